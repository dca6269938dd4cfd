"""Worker processes that die with the process that started them.

A pool's workers outlive a parent killed with SIGKILL (no cleanup runs in it): they would go on
computing episodes nobody collects. `die_with_parent`, a pool's ``initializer``, makes a
worker follow its parent: on Linux the kernel sends it SIGKILL when the parent dies
(``PR_SET_PDEATHSIG``), and everywhere a watcher thread ends it within a second of its parent's
disappearance.
"""

from __future__ import annotations

import ctypes
import os
import signal
import threading
import time
from concurrent.futures import ProcessPoolExecutor

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


def worker_pool(workers: int) -> ProcessPoolExecutor:
    """A process pool of ``workers`` processes that die with this process."""
    return ProcessPoolExecutor(
        max_workers=workers, initializer=die_with_parent, initargs=(os.getpid(),)
    )
