"""The real-time mission controller (paper Fig. 2 on a clock): beliefs, planner and mission log
driven by timestamped events, with no vehicle or middleware inside.

Inputs, all in the planner's local frame (m; ``x`` east, ``y`` north) and mission time (s from
the mission start):

* :meth:`MissionController.odometry` -- the vehicle's position;
* :meth:`MissionController.detection` -- a position measurement of one target, with its own
  2x2 noise covariance or the scenario's ``R``;
* :meth:`MissionController.setpoint` -- where the vehicle should fly now; it always returns at
  once.

Beliefs are predicted in closed form to each event's time whatever the gaps
(:class:`~hptrack.runtime.beliefs.BeliefTimeline`). The planner runs on its own step clock:
ticks at ``k tau``. At the first ``setpoint`` call at or after ``k tau`` the controller builds the
:class:`~hptrack.interface.Observation` of step ``k`` (beliefs at ``k tau`` from the
measurements taken up to then, the latest odometry) and hands ``act`` to the planner runner (a
worker thread in flight); the waypoint it returns becomes the setpoint when it arrives. A
target is ``detected`` in an observation when a measurement of it taken at or before ``k tau``
was accepted since the last observation the planner received (so a find is never lost while
the planner is busy, and a measurement that arrives late counts at the next tick). While a call
runs, further ticks are skipped. A call that is not back within the deadline keeps the current
waypoint (the current sub-task) and is logged as late; its waypoint is used when it arrives. A
call that fails holds the vehicle where it is until a later call succeeds.

Bad input changes nothing; it is counted and logged with its reason: non-finite or malformed
values, an unknown target id, an event before the start or after the end of the mission, a
detection stamped ahead of the controller's clock (odometry and ``setpoint`` times are the
clock), odometry older than the last one (a newer position
supersedes it) or at the same time, a detection older than the newest by more than the
tolerance, a duplicate detection, odometry that jumps faster than the vehicle can fly. Odometry
older than ``stale_odometry_s`` makes ``setpoint`` hold position and say so.

Every event and decision goes to the mission log (:mod:`hptrack.runtime.log`); records made
inside a ``setpoint`` call carry its number, so that a replay makes the same calls.
"""

from __future__ import annotations

import math
import threading
from collections import Counter
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import CurrentPlan, Observation, Planner
from hptrack.models.beliefs import position_logdet
from hptrack.models.measurement import check_noise_covariance
from hptrack.runtime.beliefs import BeliefTimeline
from hptrack.runtime.log import LOG_VERSION, MissionLog, log_float
from hptrack.runtime.worker import PlannerRunner, PlanOutcome, ThreadedRunner, timed
from hptrack.scenario.model import Scenario
from hptrack.sim.record import EpisodeRecord

_STEP_EPS = 1e-9


class ControllerSettings(BaseModel):
    """How the controller treats time and bad input (s, m).

    Attributes:
        reorder_tolerance_s: a detection up to this much older than the newest one is filtered
            in its time order; an older one is refused.
        future_tolerance_s: a detection stamped more than this ahead of the controller's
            clock (the newest odometry, setpoint or detection time) is refused.
        stale_odometry_s: without odometry for longer than this, ``setpoint`` holds.
        planner_deadline_s: a planner call not back within this is late (logged; the current
            waypoint is kept meanwhile).
        max_speed_factor: odometry implying a speed above this times the agent's speed is a
            jump and is refused.
        jump_slack_m: distance allowed on top of that speed (position noise), m.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    reorder_tolerance_s: Annotated[float, Field(ge=0.0, le=60.0)] = 2.0
    future_tolerance_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.5
    stale_odometry_s: Annotated[float, Field(gt=0.0, le=600.0)] = 1.0
    planner_deadline_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 1.0
    max_speed_factor: Annotated[float, Field(ge=1.0, le=100.0)] = 2.0
    jump_slack_m: Annotated[float, Field(ge=0.0, le=1e4)] = 3.0


NOISE_RANGE_M2 = (1e-12, 1e8)
"""A detection's noise covariance must have its eigenvalues in ``(low, high]`` m^2 (the range
a scenario's ``R`` may take: beyond it the Kalman update loses its precision)."""


def mission_area(scenario: Scenario) -> tuple[np.ndarray, float]:
    """Centre (the agent's start, m) and radius (m) of the area where a detection can be: the
    vehicle flies at most ``v_a B`` from its start and measures only within ``w/2`` of itself,
    with an error under 10 standard deviations of ``R``."""
    mission = scenario.mission_spec()
    sigma = math.sqrt(float(np.max(np.linalg.eigvalsh(mission.measurement_noise))))
    radius = mission.agent_speed * mission.budget + mission.sensor_radius + 10.0 * sigma
    return np.asarray(scenario.agent.position, dtype=float), radius


@dataclass(frozen=True)
class Setpoint:
    """Where the vehicle should be now.

    Attributes:
        position: ``(2,)`` m (``x`` east, ``y`` north): the decision's waypoint, or the hold.
        hold: the position is a hold, not the planner's waypoint.
        reason: ``"tracking"``, ``"no odometry yet"``, ``"waiting for the first plan"``,
            ``"odometry stale"``, ``"planner error"`` or ``"mission over"``.
        detail: one line with the figures behind ``reason``.
        reference: ``(2,)`` m, where the vehicle should be now on its way to ``position``: it
            leaves the odometry of the moment the decision arrived at the planned speed.
        velocity: ``(2,)`` m/s, the planned velocity at ``reference`` (0 once it reaches
            ``position``, and in a hold): the feed-forward of a position controller.
    """

    position: np.ndarray
    hold: bool
    reason: str
    detail: str
    reference: np.ndarray
    velocity: np.ndarray


@dataclass(frozen=True)
class Leg:
    """The straight flight to a decision's waypoint: from ``start`` (m) at ``start_s`` (mission
    s) at ``speed`` m/s towards ``end`` (m)."""

    start: np.ndarray
    start_s: float
    end: np.ndarray
    speed: float

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Reference position (m) and velocity (m/s) at mission time ``t`` s."""
        step = self.end - self.start
        length = float(np.hypot(*step))
        along = self.speed * max(t - self.start_s, 0.0)
        if length <= 0.0 or along >= length:
            return self.end.copy(), np.zeros(2)
        unit = step / length
        return self.start + along * unit, self.speed * unit


def _vector(value: Any, shape: tuple[int, ...]) -> np.ndarray | None:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        return None
    return array if array.shape == shape else None


def _raw(value: Any) -> Any:
    """A raw input as log data (an array as a list, anything odd as its repr)."""
    if value is None or isinstance(value, str | bool | int | float):
        return value
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError):
        return repr(value)[:200]


def plan_json(plan: CurrentPlan | None, target_ids: tuple[str, ...]) -> dict[str, Any] | None:
    """The sub-task of ``plan`` for the log, with target names: ``{"target": id, "since_step":
    k, "p_find": p}`` (a pursuit), ``{"follow": id, ...}`` or ``{"dwell": id, ...}``; ``None``
    without a sub-task."""
    if plan is None or plan.subtask is None:
        return None
    sub = plan.subtask
    key = {"pursue": "target", "follow": "follow", "dwell": "dwell"}[sub.kind]
    out: dict[str, Any] = {key: target_ids[sub.target], "since_step": sub.since_step}
    if sub.p_find is not None:
        out["p_find"] = sub.p_find
    return out


class MissionController:
    """Beliefs, planner worker and mission log of one mission (module docstring).

    Args:
        scenario: the mission (time step, budget, speed, priors, ``R``).
        planner: a fresh registered planner (``reset`` is called at the first tick).
        seed: drives the planner's generator (the fourth stream of ``SeedSequence(seed)``,
            as in the simulator); default ``scenario.seed``.
        settings: time tolerances and checks.
        log: where records go (default: memory only).
        runner: where the planner runs (default: a worker thread).
        header: extra fields for the log's header record (the adapter's options).
    """

    def __init__(
        self,
        scenario: Scenario,
        planner: Planner,
        *,
        seed: int | None = None,
        settings: ControllerSettings | None = None,
        log: MissionLog | None = None,
        runner: PlannerRunner | None = None,
        header: dict | None = None,
    ) -> None:
        self.scenario = scenario
        self.mission = scenario.mission_spec()
        self.settings = settings or ControllerSettings()
        self.seed = scenario.seed if seed is None else int(seed)
        self.log = log if log is not None else MissionLog()
        self._planner = planner
        self._rng = np.random.default_rng(np.random.SeedSequence(self.seed).spawn(4)[3])
        self._runner = runner if runner is not None else ThreadedRunner()
        self._ids = {tid: i for i, tid in enumerate(self.mission.target_ids)}
        self._beliefs = BeliefTimeline(
            scenario.means(),
            scenario.covariances(),
            self.mission.process_noise,
            self.mission.motion,
            self.settings.reorder_tolerance_s,
        )
        self._lock = threading.RLock()
        self._clock = 0.0
        self._odom: tuple[float, np.ndarray] | None = None
        self._last_call = 0.0
        self._calls = 0
        self._call: int | None = None
        self._tick = -1
        self._in_flight: tuple[int, float] | None = None
        self._late_logged = False
        self._planner_started = False
        self._first_in_flight = False
        self._waypoint: np.ndarray | None = None
        self._leg: Leg | None = None
        self._fallback = GreedyPlanner()
        self._fallback_active = False
        self._area = mission_area(scenario)
        self._planner_error: str | None = None
        self._for_planner: list[tuple[float, int]] = []
        self._for_record: list[tuple[float, int]] = []
        self._det_seq = 0
        self._mode: str | None = None
        self._hold_at = np.asarray(scenario.agent.position, dtype=float)
        self._last_tick: dict | None = None
        self.history: list[dict] = []
        """Per processed tick: ``k``, ``agent`` (or ``None``), ``means``, ``covariances``,
        ``detected``."""
        self.plan: CurrentPlan | None = None
        """What the planner said it is doing after its last flown call."""
        self.last_detection: dict[str, Any] | None = None
        self.accepted: Counter[str] = Counter()
        self.rejected: Counter[str] = Counter()
        """Refused inputs by ``"kind: reason"``."""
        self.finished = False
        self.end: dict | None = None
        self.first_plan_s: float | None = None
        """Compute time of tick 0's plan (s) once it is flown."""
        self._write(
            {
                "kind": "header",
                "version": LOG_VERSION,
                "scenario": scenario.model_dump(mode="json"),
                "planner": planner.name,
                "planner_settings": planner.settings.as_json(),
                "seed": self.seed,
                "controller": self.settings.model_dump(),
                **(header or {}),
            }
        )

    # --- log ----------------------------------------------------------------------------
    def _write(self, record: dict) -> dict:
        if self._call is not None:
            record = {**record, "call": self._call}
        return self.log.write(record)

    def _refuse(self, kind: str, record: dict, reason: str, detail: str) -> bool:
        self.rejected[f"{kind}: {reason}"] += 1
        self._write({**record, "accepted": False, "reason": reason, "detail": detail})
        return False

    def bad_input(self, kind: str, reason: str, detail: str, raw: Any = None) -> None:
        """Count and log an input an adapter could not even parse (e.g. a malformed JSON
        line); it changes nothing."""
        with self._lock:
            self._refuse(kind, {"kind": kind, "t": None, "raw": _raw(raw)}, reason, detail)

    def _check_time(self, t: float, clock_source: bool) -> tuple[str, str] | None:
        """Refuse a non-finite time, one outside the mission, or (for an event that is not
        a source of the clock) one stamped ahead of the clock."""
        if not math.isfinite(t):
            return "non-finite", f"time {t}"
        if self.finished:
            return "after the end", f"the mission ended ({self.end['reason']})"
        if t < -_STEP_EPS:
            return "before the start", f"time {t:.3f} s is before the mission's start"
        if clock_source:
            return None
        ahead = t - self._clock
        if ahead > self.settings.future_tolerance_s:
            return "in the future", (
                f"stamped {ahead:.3f} s ahead of the controller's clock "
                f"(tolerance {self.settings.future_tolerance_s:g} s)"
            )
        return None

    # --- events -------------------------------------------------------------------------
    def odometry(self, t: float, position: Any) -> bool:
        """The vehicle was at ``position`` (2,) m at mission time ``t`` s; ``False`` (logged
        with the reason) if refused."""
        with self._lock:
            t = log_float(t)
            p = _vector(position, (2,))
            record = {
                "kind": "odometry",
                "t": t,
                "position": p if p is not None else _raw(position),
            }
            problem = self._check_odometry(t, p)
            if problem is not None:
                return self._refuse("odometry", record, *problem)
            self._odom = (t, p)
            self._clock = max(self._clock, t)
            self.accepted["odometry"] += 1
            self._write({**record, "accepted": True})
            return True

    def _check_odometry(self, t: float, p: np.ndarray | None) -> tuple[str, str] | None:
        if p is None:
            return "malformed", "position is not two numbers"
        if not np.all(np.isfinite(p)):
            return "non-finite", f"position {p.tolist()}"
        problem = self._check_time(t, clock_source=True)
        if problem is not None or self._odom is None:
            return problem
        last_t, last_p = self._odom
        if t < last_t:
            return "out of order", f"{last_t - t:.3f} s older than the last odometry"
        if t == last_t:
            return "duplicate", f"a second odometry at {t:.3f} s"
        distance = float(np.hypot(*(p - last_p)))
        speed = self.settings.max_speed_factor * self.mission.agent_speed
        if distance > speed * (t - last_t) + self.settings.jump_slack_m:
            return "jump", (
                f"{distance:.1f} m in {t - last_t:.3f} s (more than {speed:g} m/s "
                f"+ {self.settings.jump_slack_m:g} m)"
            )
        return None

    def detection(self, t: float, target_id: Any, position: Any, covariance: Any = None) -> bool:
        """Target ``target_id`` was measured at ``position`` (2,) m at mission time ``t`` s,
        with noise ``covariance`` (2, 2) m^2 (default the scenario's ``R``); ``False``
        (logged with the reason) if refused."""
        with self._lock:
            t = log_float(t)
            z = _vector(position, (2,))
            record = {
                "kind": "detection",
                "t": t,
                "target": _raw(target_id),
                "position": z if z is not None else _raw(position),
            }
            if covariance is not None:
                record["covariance"] = _raw(covariance)
            problem, index, noise = self._check_detection(t, target_id, z, covariance)
            if problem is not None:
                return self._refuse("detection", record, *problem)
            self._det_seq += 1
            self._beliefs.add(index, t, z, noise, self._det_seq)
            self._clock = max(self._clock, t)
            self._for_planner.append((t, index))
            self._for_record.append((t, index))
            self.last_detection = {"target": target_id, "t": t, "position": z.tolist()}
            self.accepted["detection"] += 1
            self._write({**record, "accepted": True})
            return True

    def _check_detection(
        self, t: float, target_id: Any, z: np.ndarray | None, covariance: Any
    ) -> tuple[tuple[str, str] | None, int, np.ndarray]:
        noise = self.mission.measurement_noise
        if not isinstance(target_id, str) or target_id not in self._ids:
            return (
                (
                    "unknown target",
                    f"target id {_raw(target_id)!r} is not in the mission "
                    f"({', '.join(self.mission.target_ids)})",
                ),
                -1,
                noise,
            )
        if z is None:
            return ("malformed", "position is not two numbers"), -1, noise
        if not np.all(np.isfinite(z)):
            return ("non-finite", f"position {z.tolist()}"), -1, noise
        centre, radius = self._area
        distance = float(np.hypot(*(z - centre)))
        if not distance <= radius:
            return (
                (
                    "outside the area",
                    f"{distance:.3g} m from the start, beyond the mission's {radius:.0f} m",
                ),
                -1,
                noise,
            )
        if covariance is not None:
            r = _vector(covariance, (2, 2))
            if r is None:
                return ("malformed", "covariance is not a 2x2 matrix"), -1, noise
            try:
                noise = check_noise_covariance(r)
            except ValueError as err:
                return ("bad covariance", str(err)), -1, noise
            low, high = NOISE_RANGE_M2
            eig = np.linalg.eigvalsh(noise)
            if not (eig[0] > low and eig[1] <= high):
                return (
                    (
                        "bad covariance",
                        f"eigenvalues {eig[0]:.3g}, {eig[1]:.3g} m^2 outside ({low:g}, {high:g}]",
                    ),
                    -1,
                    noise,
                )
        problem = self._check_time(t, clock_source=False)
        if problem is not None:
            return problem, -1, noise
        index = self._ids[target_id]
        behind = self._beliefs.newest_s - t
        if behind > self.settings.reorder_tolerance_s:
            return (
                (
                    "out of order",
                    f"{behind:.3f} s older than the newest detection "
                    f"(tolerance {self.settings.reorder_tolerance_s:g} s)",
                ),
                index,
                noise,
            )
        if self._beliefs.is_duplicate(index, t, z):
            return ("duplicate", f"the same measurement of {target_id} at {t:.3f} s"), index, noise
        return None, index, noise

    # --- setpoints ----------------------------------------------------------------------
    def setpoint(self, t: float) -> Setpoint:
        """Where the vehicle should be at mission time ``t`` s. Never waits for the planner:
        processes a due tick (hands the planner its observation), takes a plan that has
        arrived, and returns the latest waypoint or a hold."""
        with self._lock:
            self._calls += 1
            self._call = self._calls
            try:
                t = log_float(t)
                if not math.isfinite(t) or t < self._last_call:
                    self._refuse(
                        "setpoint",
                        {"kind": "setpoint", "t": t},
                        "bad time",
                        f"time {t} is not finite or before the last call ({self._last_call:.3f} s)",
                    )
                    t = self._last_call
                self._last_call = t
                self._clock = max(self._clock, t)
                if not self.finished:
                    self._process_tick(t)
                if not self.finished:
                    self._poll(t)
                return self._output(t)
            finally:
                self._call = None

    def _process_tick(self, t: float) -> None:
        tau, n_steps = self.mission.time_step, self.mission.n_steps
        k = min(math.floor(t / tau + _STEP_EPS), n_steps)
        if k <= self._tick:
            return
        missed = k - self._tick - 1
        self._tick = k
        if k == n_steps:
            self._finish(t, "budget", n_steps * tau)
            return
        time_k = k * tau
        means, covs = self._beliefs.at(time_k)
        recorded = self._take(self._for_record, time_k)
        record: dict[str, Any] = {
            "kind": "tick",
            "t": t,
            "k": k,
            "time": time_k,
            "agent": None if self._odom is None else self._odom[1],
            "logdet": position_logdet(covs),
            "means": means,
        }
        if missed:
            record["missed"] = missed
        fall_back = False
        if self._odom is None:
            record.update(submitted=False, reason="no odometry yet")
        elif self._in_flight is not None:
            record.update(submitted=False, reason=f"planner busy with tick {self._in_flight[0]}")
            fall_back = self._fallback_active
        else:
            detected = self._take(self._for_planner, time_k)
            record.update(
                submitted=True,
                detected=[self.mission.target_ids[i] for i in np.flatnonzero(detected)],
            )
            self._submit(k, time_k, self._odom[1], means, covs, detected, t)
        self._last_tick = record
        self.history.append(
            {
                "k": k,
                "agent": None if self._odom is None else self._odom[1],
                "means": means,
                "covariances": covs,
                "detected": recorded,
            }
        )
        self._write(record)
        if fall_back:
            self._fall_back(t, f"planner late with tick {self._in_flight[0]}")

    def _take(self, pending: list[tuple[float, int]], time_s: float) -> np.ndarray:
        """Flags of the targets measured at or before ``time_s`` in ``pending`` (removed)."""
        flags = np.zeros(self.mission.n_targets, dtype=bool)
        keep = []
        for t, i in pending:
            if t <= time_s + _STEP_EPS:
                flags[i] = True
            else:
                keep.append((t, i))
        pending[:] = keep
        return flags

    def _submit(
        self,
        k: int,
        time_k: float,
        agent: np.ndarray,
        means: np.ndarray,
        covs: np.ndarray,
        detected: np.ndarray,
        now: float,
    ) -> None:
        arrays = [agent.copy(), means, covs, detected]
        for a in arrays:
            a.flags.writeable = False
        obs = Observation(k, time_k, self.mission.budget - time_k, *arrays)
        first = not self._planner_started
        self._planner_started = True
        planner, mission, rng = self._planner, self.mission, self._rng

        def call() -> np.ndarray:
            if first:
                planner.reset(mission, obs, rng)
            return planner.act(obs)

        def job() -> PlanOutcome:
            waypoint, error, elapsed = timed(call)
            if waypoint is not None and (
                waypoint.shape != (2,) or not np.all(np.isfinite(waypoint))
            ):
                error, waypoint = f"invalid waypoint {waypoint.tolist()}", None
            return PlanOutcome(
                k, waypoint, error, elapsed, None if error else planner.current_plan()
            )

        self._in_flight = (k, now)
        self._late_logged = False
        self._first_in_flight = first
        self._runner.submit(k, job, now)

    def _poll(self, t: float) -> None:
        if self._in_flight is None:
            return
        tick, since = self._in_flight
        outcome = self._runner.poll(t)
        if outcome is None:
            if not self._late_logged and t - since > self.settings.planner_deadline_s:
                self._late_logged = True
                self.rejected["plan: late"] += 1
                self._write(
                    {
                        "kind": "late",
                        "t": t,
                        "k": tick,
                        "waited_s": t - since,
                        "detail": "flying the fallback decision meanwhile",
                    }
                )
                self._fall_back(t, f"planner late with tick {tick}")
            return
        self._apply(outcome, t, late=t - since > self.settings.planner_deadline_s + _STEP_EPS)

    def _apply(self, outcome: PlanOutcome, t: float, late: bool, after_end: bool = False) -> None:
        self._in_flight = None
        status = "error" if outcome.error else ("late" if late else "ok")
        record: dict[str, Any] = {
            "kind": "plan",
            "t": t,
            "k": outcome.tick,
            "status": status,
            "waypoint": outcome.waypoint,
            "compute_s": outcome.compute_s,
            "subtask": plan_json(outcome.plan, self.mission.target_ids),
            "speed_m_s": self.mission.agent_speed,
        }
        if outcome.error:
            record["error"] = outcome.error
            self.rejected["plan: error"] += 1
            self._planner_error = outcome.error
            if self._first_in_flight:
                self._planner_started = False
        elif late and self._fallback_active:
            record["detail"] = "not flown: the fallback flies until the next tick's plan"
            self.plan = outcome.plan
        elif not after_end:
            self._fallback_active = False
            self._fly(outcome.waypoint, t)
            self._planner_error = None
            self.plan = outcome.plan
            if outcome.tick == 0 and self.first_plan_s is None:
                self.first_plan_s = outcome.compute_s
        if after_end:
            record["after_end"] = True
        self._write(record)

    def _output(self, t: float) -> Setpoint:
        if self.finished:
            mode, detail = "mission over", f"the mission ended ({self.end['reason']})"
        elif self._odom is None:
            mode, detail = "no odometry yet", "holding at the scenario's start position"
        elif t - self._odom[0] > self.settings.stale_odometry_s:
            mode = "odometry stale"
            detail = (
                f"no odometry for {t - self._odom[0]:.2f} s "
                f"(limit {self.settings.stale_odometry_s:g} s)"
            )
        elif self._planner_error is not None:
            mode, detail = "planner error", self._planner_error
        elif self._waypoint is None:
            mode, detail = "waiting for the first plan", "holding until the planner answers"
        elif self._fallback_active:
            mode, detail = "fallback", "the planner is late: flying a greedy decision"
        else:
            mode, detail = "tracking", "flying the planner's waypoint"
        hold = mode not in ("tracking", "fallback")
        if mode != self._mode:
            if self._odom is not None:
                self._hold_at = self._odom[1].copy()
            self._mode = mode
            position = self._hold_at if hold else self._waypoint
            self._write(
                {
                    "kind": "mode",
                    "t": t,
                    "mode": mode,
                    "hold": hold,
                    "position": position,
                    "detail": detail,
                }
            )
        if hold:
            return Setpoint(
                self._hold_at.copy(), True, mode, detail, self._hold_at.copy(), np.zeros(2)
            )
        reference, velocity = self._leg.at(t)
        return Setpoint(self._waypoint.copy(), False, mode, detail, reference, velocity)

    def _fly(self, waypoint: np.ndarray, t: float) -> None:
        """Make ``waypoint`` the decision flown from the latest odometry at time ``t``."""
        self._waypoint = waypoint
        start = self._hold_at if self._odom is None else self._odom[1]
        self._leg = Leg(start.copy(), t, waypoint.copy(), self.mission.agent_speed)

    def _fall_back(self, t: float, why: str) -> None:
        """A greedy decision on the beliefs at ``t`` from the latest odometry, flown at once
        while the planner is late (logged as ``fallback``)."""
        means, covs = self._beliefs.at(t)
        agent = self._odom[1].copy()
        arrays = [agent, means, covs, np.zeros(self.mission.n_targets, dtype=bool)]
        for a in arrays:
            a.flags.writeable = False
        obs = Observation(max(self._tick, 0), t, self.mission.budget - t, *arrays)
        if not self._fallback_active:
            self._fallback.reset(self.mission, obs, np.random.default_rng(self.seed))
        waypoint = np.asarray(self._fallback.act(obs), dtype=float)
        self._fallback_active = True
        self._fly(waypoint, t)
        self.accepted["fallback"] += 1
        self._write(
            {
                "kind": "fallback",
                "t": t,
                "k": self._tick,
                "waypoint": waypoint,
                "planner": self._fallback.name,
                "reason": why,
            }
        )

    # --- before the mission ---------------------------------------------------------------
    def prepare(self, position: Any) -> None:
        """Before the mission starts (during take-off): the vehicle will start at
        ``position`` (2,) m; hands tick 0 to the planner (its kernels compile or load in that
        first call). Follow with :meth:`first_plan`."""
        self.odometry(0.0, position)
        self.setpoint(0.0)

    def first_plan(self, timeout_s: float) -> float | None:
        """Wait up to ``timeout_s`` s (without holding the controller) for tick 0's plan and
        take it; returns its compute time, s, or ``None`` if it did not come."""
        if self._in_flight is None or not self._runner.wait(timeout_s):
            return self.first_plan_s
        self.setpoint(0.0)
        return self.first_plan_s

    # --- the end --------------------------------------------------------------------------
    def finish(self, t: float, reason: str) -> dict:
        """End the mission at time ``t`` s for ``reason`` (idempotent); returns the ``end``
        record (``U`` of the beliefs at ``min(t, budget)``)."""
        with self._lock:
            if not self.finished:
                t = log_float(t)
                t = self._last_call if not math.isfinite(t) else t
                self._finish(t, reason, min(max(t, 0.0), self.mission.budget))
            return self.end

    def _finish(self, t: float, reason: str, time_s: float) -> None:
        if self._in_flight is not None:
            outcome = self._runner.drain(self.settings.planner_deadline_s)
            if outcome is not None:
                self._apply(outcome, t, late=False, after_end=True)
        if self._in_flight is None:
            info = self._planner.episode_info() if self._planner_started else {}
        else:
            info = {"unavailable": f"the planner was still running tick {self._in_flight[0]}"}
        self.finished = True
        means, covs = self._beliefs.at(time_s)
        logdet = position_logdet(covs)
        self.final = {
            "time": time_s,
            "means": means,
            "covariances": covs,
            "agent": None if self._odom is None else self._odom[1].copy(),
            "detected": self._take(self._for_record, time_s),
        }
        self.end = self._write(
            {
                "kind": "end",
                "t": t,
                "time": time_s,
                "reason": reason,
                "U": float(logdet.sum()),
                "per_target_logdet": dict(
                    zip(self.mission.target_ids, logdet.tolist(), strict=True)
                ),
                "accepted": dict(self.accepted),
                "rejected": dict(self.rejected),
                "planner_info": info,
            }
        )
        self._runner.close()

    def close(self) -> None:
        """Stop the planner runner (the log stays open: its owner closes it)."""
        self._runner.close()

    # --- views ----------------------------------------------------------------------------
    @property
    def last_odometry(self) -> tuple[float, np.ndarray] | None:
        """Time (s) and position (m) of the last accepted odometry."""
        return self._odom

    @property
    def planner_error(self) -> str | None:
        """The planner's last failure while no later call succeeded, or ``None``."""
        return self._planner_error

    @property
    def newest_detection_s(self) -> float:
        """Time of the newest accepted detection (0 before any), s."""
        return self._beliefs.newest_s

    def status(self) -> dict[str, Any]:
        """A snapshot for a live view: time, mode, sub-task, each target's log det at the last
        tick, the last detection and the refused inputs."""
        with self._lock:
            tick = self._last_tick
            logdet = (
                None
                if tick is None
                else dict(
                    zip(self.mission.target_ids, np.asarray(tick["logdet"]).tolist(), strict=True)
                )
            )
            return {
                "t": self._last_call,
                "budget": self.mission.budget,
                "mode": self._mode,
                "plan": self.plan,
                "target_ids": self.mission.target_ids,
                "logdet": logdet,
                "last_detection": self.last_detection,
                "accepted": dict(self.accepted),
                "rejected": dict(self.rejected),
                "finished": self.finished,
                "end": self.end,
            }

    def episode_record(self, truth: np.ndarray | None = None) -> EpisodeRecord:
        """The mission as an :class:`~hptrack.sim.record.EpisodeRecord` (for the mission
        figure): the agent at each tick (held between processed ticks), the beliefs at each
        processed tick and at the end, the detections per tick; ``truth`` ``(K+1, n, 4)`` if
        known, else NaN. Call after :meth:`finish`."""
        if not self.finished:
            raise RuntimeError("episode_record() needs a finished mission")
        tau, n = self.mission.time_step, self.mission.n_targets
        last = math.floor(self.final["time"] / tau + _STEP_EPS)
        agent_path = np.empty((last + 1, 2))
        detections = np.zeros((last + 1, n), dtype=bool)
        position = np.asarray(self.scenario.agent.position, dtype=float)
        rows = {row["k"]: row for row in self.history if row["k"] <= last}
        final = {"agent": self.final["agent"], "detected": self.final["detected"]}
        for k in range(last + 1):
            for row in (rows.get(k), final if k == last else None):
                if row is not None:
                    if row["agent"] is not None:
                        position = row["agent"]
                    detections[k] |= row["detected"]
            agent_path[k] = position
        stored = [row for row in rows.values() if row["k"] < last]
        steps = [row["k"] for row in stored] + [last]
        means = np.array([row["means"] for row in stored] + [self.final["means"]])
        covs = np.array([row["covariances"] for row in stored] + [self.final["covariances"]])
        if truth is None:
            truth = np.full((last + 1, n, 4), np.nan)
        return EpisodeRecord(
            planner=self._planner.name,
            seed=self.seed,
            target_ids=self.mission.target_ids,
            time_step=tau,
            sensor_diameter=self.mission.sensor_diameter,
            agent_path=agent_path,
            true_states=np.asarray(truth)[: last + 1],
            belief_steps=np.asarray(steps),
            belief_means=means,
            belief_covariances=covs,
            detections=detections,
            per_target_logdet=position_logdet(self.final["covariances"]),
            info=dict(self.end.get("planner_info") or {}),
        )
