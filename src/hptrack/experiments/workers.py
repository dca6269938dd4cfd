"""Worker processes that die with the process that started them.

A pool's workers outlive a parent killed with SIGKILL (no cleanup runs in it): they would go on
computing episodes nobody collects. `die_with_parent`, a pool's ``initializer``, makes a
worker follow its parent: on Linux the kernel sends it SIGKILL when the parent dies
(``PR_SET_PDEATHSIG``), and everywhere a watcher thread ends it within a second of its parent's
disappearance. Workers ignore Ctrl-C (SIGINT): the parent decides, and on an interrupt ends them
at once with `stop_workers` instead of waiting for their episodes.
"""

from __future__ import annotations

import ctypes
import os
import signal
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

PR_SET_PDEATHSIG = 1
"""``prctl`` option: the signal this process receives when its parent dies (Linux)."""
WATCH_INTERVAL_S = 1.0
"""How often a worker checks that its parent still lives, s."""


def process_alive(pid: int) -> bool:
    """Whether a process of this id exists (one of another user counts)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def runs_with_file_open(pid: int, path: Path) -> bool | None:
    """Whether process ``pid`` has the file ``path`` open (Linux's ``/proc``); ``False`` also
    for a process that cannot be a run of it (not Python, when its files cannot be listed),
    ``None`` where this cannot be told."""
    proc = Path(f"/proc/{pid}")
    try:
        wanted = path.stat()
        names = os.listdir(proc / "fd")
    except PermissionError:  # another user's process: at least it must be Python
        try:
            command = (proc / "cmdline").read_bytes().lower()
        except OSError:
            return None
        return None if b"python" in command or b"hptrack" in command else False
    except OSError:
        return None
    for name in names:
        try:
            held = os.stat(proc / "fd" / name)
        except OSError:
            continue
        if (held.st_dev, held.st_ino) == (wanted.st_dev, wanted.st_ino):
            return True
    return False


def die_with_parent(parent: int | None = None) -> None:
    """Make this (worker) process end when process ``parent`` (default: its parent) ends."""
    parent = os.getppid() if parent is None else parent
    if os.getppid() == parent:
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # not Linux: the watcher below does it
            pass
        if os.getppid() != parent:  # the parent died before the prctl call
            os._exit(1)

    def watch() -> None:
        while process_alive(parent) and os.getppid() == parent:
            time.sleep(WATCH_INTERVAL_S)
        os._exit(1)

    threading.Thread(target=watch, name="die-with-parent", daemon=True).start()


def _start_worker(parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent)


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A process pool of ``workers`` processes that die with this process and ignore Ctrl-C."""
    return ProcessPoolExecutor(
        max_workers=workers, initializer=_start_worker, initargs=(os.getpid(),)
    )


def stop_workers(pool: ProcessPoolExecutor) -> None:
    """End ``pool`` now: its queued tasks are cancelled and its running ones killed."""
    processes = list((getattr(pool, "_processes", None) or {}).values())  # public in 3.14
    # shutdown(wait=False) forgets the pool's manager thread, so a later shutdown(wait=True)
    # would not wait for it; joined here, it has closed its wake-up pipe before the interpreter's
    # exit hook writes to it (a race in Python 3.11 that printed a traceback after Ctrl-C)
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.kill()
    if manager is not None:
        manager.join()
