"""Worker processes die with the process that started them, even when it is killed with
SIGKILL (no cleanup runs in it), and a pool never starts more workers than tasks."""

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from hptrack.experiments.workers import process_alive

PARENT = textwrap.dedent(
    """
    import os, sys, time
    from hptrack.experiments.workers import worker_pool

    pool = worker_pool(2)
    futures = [pool.submit(time.sleep, 600) for _ in range(2)]
    while len(pool._processes) < 2:
        time.sleep(0.05)
    print(" ".join(str(pid) for pid in pool._processes), flush=True)
    time.sleep(600)
    """
)


@pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL")
def test_workers_die_when_their_parent_is_killed():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    parent = subprocess.Popen(
        [sys.executable, "-c", PARENT], stdout=subprocess.PIPE, text=True, env=env
    )
    try:
        workers = [int(pid) for pid in parent.stdout.readline().split()]
        assert len(workers) == 2 and all(process_alive(pid) for pid in workers)
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=30)
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline and any(process_alive(pid) for pid in workers):
            time.sleep(0.1)
        assert not any(process_alive(pid) for pid in workers)
    finally:
        parent.kill()
        parent.wait()
        parent.stdout.close()
