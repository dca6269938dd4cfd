"""The planner's side of the controller: `PlannerWorker` hands the planner one
observation at a time, tells when a call is late and delivers its outcome; `Fallback` is
the cheap decision flown while a call is late. Where the planner runs: a worker thread (real
time), inline with a simulated compute time (the simulated runner) or on the log's say-so
(replay).

The worker hands a runner one job at a time (a call of the planner for one tick) and polls it
for the outcome at each ``setpoint``; a runner never blocks the caller of ``poll``. Only the
runner's thread touches the planner while a job runs.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import CurrentPlan, MissionSpec, Observation, Planner


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
    """Runs a job only when the replayed log says its outcome was delivered (`release`),
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


def observation(
    step: int,
    time_s: float,
    budget: float,
    agent: np.ndarray,
    means: np.ndarray,
    covariances: np.ndarray,
    detected: np.ndarray,
) -> Observation:
    """A planner's read-only observation of step ``step`` at ``time_s`` s (arrays copied where
    the caller keeps them)."""
    arrays = [np.array(agent, dtype=float), means, covariances, detected]
    for a in arrays:
        a.flags.writeable = False
    return Observation(step, time_s, budget - time_s, *arrays)


@dataclass(frozen=True)
class Poll:
    """What a poll of the worker found.

    Attributes:
        outcome: the call's outcome if it arrived, else ``None``.
        late: the call is (or was, when it arrived) past its deadline.
        newly_late: this poll is the first to find it past its deadline.
        tick: the call's tick.
        waited_s: mission time since the call was made, s.
    """

    outcome: PlanOutcome | None
    late: bool
    newly_late: bool
    tick: int
    waited_s: float


class PlannerWorker:
    """One planner call at a time with a deadline.

    Args:
        planner: a fresh planner (``reset`` at its first call, again after a failed first
            call).
        mission: the mission's facts.
        rng: the planner's generator.
        runner: where the calls run.
        deadline_s: a call not back within this is late, mission s.
        n_vehicles: ``m``; a call returns ``(2,)`` for one vehicle, ``(m, 2)`` for a team.
    """

    def __init__(
        self,
        planner: Planner,
        mission: MissionSpec,
        rng: np.random.Generator,
        runner: PlannerRunner,
        deadline_s: float,
        n_vehicles: int = 1,
    ) -> None:
        self.planner, self.mission, self._rng = planner, mission, rng
        self.shape = (2,) if n_vehicles == 1 else (n_vehicles, 2)
        """The shape of a waypoint, m."""
        self.runner, self.deadline_s = runner, deadline_s
        self.in_flight: tuple[int, float] | None = None
        """Tick and mission time of the running call."""
        self.started = False
        self._late_seen = False
        self._first = False

    def submit(self, obs: Observation, now_s: float) -> None:
        """Call the planner on ``obs`` (the first call resets it) at mission time ``now_s``."""
        first = not self.started
        self.started = True
        planner, mission, rng, shape = self.planner, self.mission, self._rng, self.shape

        def call() -> np.ndarray:
            if first:
                planner.reset(mission, obs, rng)
            return planner.act(obs)

        def job() -> PlanOutcome:
            waypoint, error, elapsed = timed(call)
            if shape == (2,) and waypoint is not None and np.shape(waypoint) == (1, 2):
                waypoint = np.asarray(waypoint)[0]  # the one vehicle's, as (m, 2)
            if waypoint is not None and (
                waypoint.shape != shape or not np.all(np.isfinite(waypoint))
            ):
                error, waypoint = f"invalid waypoint {waypoint.tolist()}", None
            return PlanOutcome(
                obs.step, waypoint, error, elapsed, None if error else planner.current_plan()
            )

        self.in_flight = (obs.step, now_s)
        self._late_seen = False
        self._first = first
        self.runner.submit(obs.step, job, now_s)

    def poll(self, t: float) -> Poll | None:
        """The running call's state at mission time ``t`` s (``None`` if none runs)."""
        if self.in_flight is None:
            return None
        tick, since = self.in_flight
        outcome = self.runner.poll(t)
        waited = t - since
        if outcome is None:
            newly = not self._late_seen and waited > self.deadline_s
            self._late_seen = self._late_seen or newly
            return Poll(None, self._late_seen, newly, tick, waited)
        self._delivered(outcome)
        return Poll(outcome, waited > self.deadline_s + 1e-9, False, tick, waited)

    def drain(self) -> PlanOutcome | None:
        """At the mission's end: the running call's outcome, waiting at most the deadline."""
        if self.in_flight is None:
            return None
        outcome = self.runner.drain(self.deadline_s)
        if outcome is not None:
            self._delivered(outcome)
        return outcome

    def _delivered(self, outcome: PlanOutcome) -> None:
        self.in_flight = None
        if outcome.error and self._first:
            self.started = False  # the next call resets the planner again

    def wait(self, timeout_s: float) -> bool:
        """Block up to ``timeout_s`` s until the running call's outcome is ready."""
        return self.in_flight is not None and self.runner.wait(timeout_s)

    def info(self) -> dict:
        """The planner's own record of the mission (``unavailable`` while a call runs)."""
        if self.in_flight is not None:
            return {"unavailable": f"the planner was still running tick {self.in_flight[0]}"}
        return self.planner.episode_info() if self.started else {}

    def close(self) -> None:
        self.runner.close()


class Fallback:
    """The decision flown while the planner is late: the ``greedy`` planner on the current
    beliefs (deterministic, milliseconds), reset at the start of each late spell.

    Args:
        mission: the mission's facts.
        seed: the generator handed to ``greedy``'s reset (it draws nothing).
        planner: the planner that decides instead of ``greedy`` (a team's ``team-greedy``).
    """

    def __init__(self, mission: MissionSpec, seed: int, planner: Any = None) -> None:
        self.mission, self.seed = mission, seed
        self.planner: Any = GreedyPlanner() if planner is None else planner
        self.active = False

    def decide(self, obs: Observation) -> np.ndarray:
        """A waypoint ``(2,)`` m for ``obs``; the fallback is active until `stop`."""
        if not self.active:
            self.planner.reset(self.mission, obs, np.random.default_rng(self.seed))
        self.active = True
        return np.asarray(self.planner.act(obs), dtype=float)

    def stop(self) -> None:
        """The planner flies again."""
        self.active = False
