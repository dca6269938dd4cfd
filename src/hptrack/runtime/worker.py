"""Where the planner runs: a worker thread (real time), inline with a simulated compute time
(the simulated runner) or on the log's say-so (replay).

The controller hands a runner one job at a time (a call of the planner for one tick) and polls
it for the outcome at each ``setpoint``; a runner never blocks the caller of ``poll``. Only the
runner's thread touches the planner while a job runs.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from hptrack.interface import CurrentPlan


@dataclass(frozen=True)
class PlanOutcome:
    """What one planner call produced.

    Attributes:
        tick: the tick the call was made for.
        waypoint: ``(2,)`` m, or ``None`` if the call failed.
        error: the failure (``"TypeError: ..."``), or ``None``.
        compute_s: wall time the call took, s.
        plan: what the planner said it is doing after the call, or ``None`` if it failed.
    """

    tick: int
    waypoint: np.ndarray | None
    error: str | None
    compute_s: float
    plan: CurrentPlan | None


Job = Callable[[], PlanOutcome]


class PlannerRunner(Protocol):
    """Runs planner jobs one at a time for the controller."""

    def submit(self, tick: int, job: Job, now_s: float) -> None:
        """Start ``job`` (the controller submits only when the last one has been polled)."""

    def poll(self, now_s: float) -> PlanOutcome | None:
        """The outcome of the running job if it is available at mission time ``now_s``."""

    def drain(self, timeout_s: float) -> PlanOutcome | None:
        """At the mission's end: the running job's outcome, waiting at most ``timeout_s``."""

    def wait(self, timeout_s: float) -> bool:
        """Block (the caller holds no lock) until the running job's outcome is ready, at most
        ``timeout_s`` s; whether it is (it stays for the next ``poll``)."""

    def close(self) -> None:
        """Stop accepting jobs (a running job is abandoned)."""


class ThreadedRunner:
    """A daemon worker thread: the job runs while the caller keeps streaming setpoints; a job
    that never returns cannot keep the process alive."""

    def __init__(self) -> None:
        self._jobs: queue.Queue[Job | None] = queue.Queue()
        self._done: queue.Queue[PlanOutcome] = queue.Queue()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._work, name="hptrack-planner", daemon=True)
        self._thread.start()

    def _work(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            self._done.put(job())
            self._ready.set()

    def submit(self, tick: int, job: Job, now_s: float) -> None:
        self._ready.clear()
        self._jobs.put(job)

    def poll(self, now_s: float) -> PlanOutcome | None:
        try:
            return self._done.get_nowait()
        except queue.Empty:
            return None

    def drain(self, timeout_s: float) -> PlanOutcome | None:
        """Wait up to ``timeout_s`` wall seconds for the running job."""
        try:
            return self._done.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def wait(self, timeout_s: float) -> bool:
        return self._ready.wait(timeout_s)

    def close(self) -> None:
        self._jobs.put(None)


class InlineRunner:
    """Runs each job at once in the caller's thread and releases its outcome after a
    simulated compute time, ``delay(tick)`` mission seconds (0 by default)."""

    def __init__(self, delay: Callable[[int], float] | None = None) -> None:
        self._delay = delay
        self._pending: tuple[float, PlanOutcome] | None = None

    def submit(self, tick: int, job: Job, now_s: float) -> None:
        ready = now_s + (0.0 if self._delay is None else float(self._delay(tick)))
        self._pending = (ready, job())

    def poll(self, now_s: float) -> PlanOutcome | None:
        if self._pending is not None and now_s >= self._pending[0] - 1e-9:
            outcome, self._pending = self._pending[1], None
            return outcome
        return None

    def drain(self, timeout_s: float) -> PlanOutcome | None:
        """The pending outcome whatever its simulated compute time."""
        outcome, self._pending = (None, None) if self._pending is None else (self._pending[1], None)
        return outcome

    def wait(self, timeout_s: float) -> bool:
        """Whether a job is pending (its simulated compute time is not waited for)."""
        return self._pending is not None

    def close(self) -> None:
        self._pending = None


class ReplayRunner:
    """Runs a job only when the replayed log says its outcome was delivered (:meth:`release`),
    in the caller's thread, so that a replay makes the same decisions at the same points
    without a wall clock."""

    def __init__(self) -> None:
        self._job: tuple[int, Job] | None = None
        self._released: set[int] = set()

    def release(self, tick: int) -> None:
        """Let the outcome of the job of ``tick`` be delivered at the next poll."""
        self._released.add(int(tick))

    def submit(self, tick: int, job: Job, now_s: float) -> None:
        self._job = (int(tick), job)

    def poll(self, now_s: float) -> PlanOutcome | None:
        if self._job is not None and self._job[0] in self._released:
            tick, job = self._job
            self._job = None
            self._released.discard(tick)
            return job()
        return None

    def drain(self, timeout_s: float) -> PlanOutcome | None:
        """The job's outcome if the log released it, else ``None`` (it never arrived)."""
        return self.poll(math.inf)

    def wait(self, timeout_s: float) -> bool:
        """Whether the log released the running job."""
        return self._job is not None and self._job[0] in self._released

    def close(self) -> None:
        self._job = None


def timed(call: Callable[[], np.ndarray]) -> tuple[np.ndarray | None, str | None, float]:
    """Run ``call``; return its result or the error it raised, and the wall time it took."""
    start = time.perf_counter()
    try:
        result = call()
        return np.array(result, dtype=float), None, time.perf_counter() - start
    except Exception as err:  # noqa: BLE001 - a planner failure is reported, not raised
        return None, f"{type(err).__name__}: {err}", time.perf_counter() - start
