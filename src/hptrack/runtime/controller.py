"""The real-time mission controller (paper Fig. 2 on a clock): beliefs, planner and mission log
driven by timestamped events, with no vehicle or middleware inside.

Inputs, all in the planner's local frame (m; ``x`` east, ``y`` north) and mission time (s from
the mission start):

* `MissionController.odometry` -- the vehicle's position;
* `MissionController.detection` -- a position measurement of one target, with its own
  2x2 noise covariance or the scenario's ``R``; with the scenario's ``sensor.labelled: false``,
  a report without identity (no target id, optionally a confidence), which the tracker
  associates with the beliefs at its tick (below);
* `MissionController.setpoint` -- where the vehicle should fly now; it always returns at
  once.

Beliefs are predicted in closed form to each event's time whatever the gaps (`BeliefTimeline`).
With the scenario's ``sensor.negative_information``, each tick is a look from the latest
odometry: every target with no detection taken since the previous tick gets the miss update at
the tick's time (`hptrack.models.miss_update`; a team's, one from each vehicle's position in
turn; a detection of that interval that arrives later takes the misses out again). Without
identity (``sensor.labelled: false``) the beliefs are the simulator's tracker's
(`hptrack.runtime.looks.TrackedBeliefs`): each tick is one look, which associates the reports
stamped since the previous tick with the beliefs (gating, GNN or JPDA, tentative tracks and
their confirmation: `hptrack.models.tracking.Tracker`) and logs which report went to which
belief (a ``look`` record); a target is ``detected`` when a report went to its belief or a
tentative track claimed it. The planner runs on its own step clock: ticks at ``k tau``. At the
first ``setpoint`` call at or after ``k tau`` the controller builds the `Observation` of step
``k`` (beliefs at ``k tau`` from the measurements taken up to then, the latest odometry) and
hands ``act`` to the planner runner (a worker thread in flight); the waypoint it returns becomes
the setpoint when it arrives. A target is ``detected`` in an observation when a measurement of
it taken at or before ``k tau`` was accepted since the last observation the planner received (so
a find is never lost while the planner is busy, and a measurement that arrives late counts at
the next tick). While a call runs, further ticks are skipped. A call that is not back within the
deadline is logged as late and replaced at once by a fallback decision (greedy on the current
beliefs), decided again at each tick until the planner answers; the late plan is logged, not
flown. A call that fails holds the vehicle where it is until a later call succeeds. Each
decision is flown as a `Leg` from the odometry of the moment it arrives, at the planned speed,
shifted by the vehicle's lag behind the reference it was flying (``keep_lag``), so that the lag
a position loop needs to fly the planned speed is not lost at every decision. With a fence, a
reference outside its free space (the fence shrunk by the margin) is sent projected onto it
(`nearest_free`), and logged.

Bad input changes nothing; it is counted and logged with its reason: non-finite or malformed
values, an unknown target id, an event before the start or after the end of the mission, a
detection stamped ahead of the controller's clock (odometry and ``setpoint`` times are the
clock), odometry older than the last one (a newer position
supersedes it) or at the same time, a detection older than the newest by more than the
tolerance, a duplicate detection, a detection outside the mission's area or with a covariance
outside R's range, odometry that jumps faster than the vehicle can fly
(`hptrack.runtime.inputs`). Odometry older than ``stale_odometry_s`` makes ``setpoint`` hold
position and say so.

The controller is assembled from its parts, each testable alone: the input checks
(`inputs`), the clock (`clock`), the planner worker
and fallback (`worker`), the journal of records and counts
(`journal`) and the mission's history for the figure
(`record`).

Every event and decision goes to the mission log (`hptrack.runtime.log`); records made
inside a ``setpoint`` call carry its number, so that a replay makes the same calls.
"""

from __future__ import annotations

import threading
from collections import Counter
from functools import partial
from typing import Any

import numpy as np

from hptrack.interface import CurrentPlan, Planner
from hptrack.models.beliefs import position_logdet
from hptrack.models.fence import nearest_free, point_free
from hptrack.models.mission import STEP_TOLERANCE
from hptrack.models.sensor import informs_misses, look_missed
from hptrack.runtime.beliefs import BeliefTimeline
from hptrack.runtime.clock import MissionClock
from hptrack.runtime.inputs import ControllerSettings, InputChecks, raw, vector
from hptrack.runtime.journal import Journal
from hptrack.runtime.legs import Leg, Setpoint
from hptrack.runtime.log import LOG_VERSION, MissionLog, log_float
from hptrack.runtime.looks import TrackedBeliefs
from hptrack.runtime.record import MissionHistory
from hptrack.runtime.worker import (
    Fallback,
    PlannerRunner,
    PlannerWorker,
    PlanOutcome,
    ThreadedRunner,
    observation,
)
from hptrack.scenario.io import file_data
from hptrack.scenario.model import Scenario
from hptrack.sim.record import EpisodeRecord

FLYING = ("tracking", "fallback")
"""The setpoint modes that fly a leg (the others hold)."""


def plan_json(plan: CurrentPlan | None, target_ids: tuple[str, ...]) -> dict[str, Any] | None:
    """The sub-task of ``plan`` for the log (`hptrack.subtasks.Subtask.to_json`, targets
    named by id); ``None`` without a sub-task."""
    if plan is None or plan.subtask is None:
        return None
    return plan.subtask.to_json(target_ids)


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
        self.journal = Journal(log)
        self.log = self.journal.log
        self.checks = InputChecks(scenario, self.settings)
        self.clock = MissionClock(self.mission.time_step, self.mission.n_steps)
        self.worker = PlannerWorker(
            planner,
            self.mission,
            np.random.default_rng(np.random.SeedSequence(self.seed).spawn(4)[3]),
            runner if runner is not None else ThreadedRunner(),
            self.settings.planner_deadline_s,
            self.mission.n_vehicles,
        )
        self.fallback = Fallback(self.mission, self.seed)
        self.history = MissionHistory(self.mission, np.asarray(scenario.agent.position, float))
        sensor = self.mission.record.sensor
        self._informs = bool(informs_misses(sensor))
        self._beliefs = BeliefTimeline(
            scenario.means(),
            scenario.covariances(),
            self.mission.process_noise,
            self.mission.motion,
            self.settings.reorder_tolerance_s,
            missed=partial(look_missed, sensor) if self._informs else None,
            look_s=self.mission.time_step,
        )
        self._tracked = (
            None if scenario.sensor_spec().labelled else TrackedBeliefs(scenario, self.seed)
        )
        """The tracker's beliefs without identity (``None``: named detections)."""
        self._unseen = np.zeros(self.mission.n_targets, dtype=bool)
        self._seen_for_planner = self._unseen.copy()
        self._seen_for_record = self._unseen.copy()
        self.tracking: Counter[str] = Counter()
        """Without identity: looks, reports looked at, reports a belief took, claims by
        tentative tracks, superseded reports."""
        self._lock = threading.RLock()
        self._odom: tuple[float, np.ndarray] | None = None
        self._waypoint: np.ndarray | None = None
        self._leg: Leg | None = None
        self._planner_error: str | None = None
        self._for_planner: list[tuple[float, int]] = []
        self._for_record: list[tuple[float, int]] = []
        self._det_seq = 0
        self._mode: str | None = None
        self._hold_at = np.asarray(scenario.agent.position, dtype=float)
        self._fence = None if scenario.fence is None else scenario.fence.spec().compiled()
        self.fence_projections = 0
        """Setpoints projected into the fence's free space (`_inside`)."""
        self._last_tick: dict | None = None
        self.plan: CurrentPlan | None = None
        """What the planner said it is doing after its last flown call."""
        self.last_detection: dict[str, Any] | None = None
        self.finished = False
        self.end: dict | None = None
        self.first_plan_s: float | None = None
        """Compute time of tick 0's plan (s) once it is flown."""
        self.journal.write(
            {
                "kind": "header",
                "version": LOG_VERSION,
                "scenario": file_data(scenario),
                "planner": planner.name,
                "planner_settings": planner.settings.as_json(),
                "seed": self.seed,
                "controller": self.settings.model_dump(),
                **(header or {}),
            }
        )

    @property
    def accepted(self) -> Counter[str]:
        """Accepted inputs by kind."""
        return self.journal.accepted

    @property
    def rejected(self) -> Counter[str]:
        """Refused inputs by ``"kind: reason"``."""
        return self.journal.rejected

    @property
    def final(self) -> dict | None:
        """The beliefs, agent and detections at the end (after `finish`)."""
        return self.history.final

    def _ended(self) -> str | None:
        return self.end["reason"] if self.finished else None

    def bad_input(self, kind: str, reason: str, detail: str, raw_input: Any = None) -> None:
        """Count and log an input an adapter could not even parse (e.g. a malformed JSON
        line); it changes nothing."""
        with self._lock:
            record = {"kind": kind, "t": None, "raw": raw(raw_input)}
            self.journal.refuse(kind, record, reason, detail)

    # --- events -------------------------------------------------------------------------
    def odometry(self, t: float, position: Any) -> bool:
        """The vehicle was at ``position`` (2,) m at mission time ``t`` s; ``False`` (logged
        with the reason) if refused."""
        with self._lock:
            t = log_float(t)
            p = vector(position, (2,))
            record = {
                "kind": "odometry",
                "t": t,
                "position": p if p is not None else raw(position),
            }
            problem = self.checks.odometry(t, p, self._odom, self._ended())
            if problem is not None:
                return self.journal.refuse("odometry", record, *problem)
            self._odom = (t, p)
            self.clock.observe(t)
            return self.journal.accept("odometry", record)

    def detection(
        self,
        t: float,
        target_id: Any,
        position: Any,
        covariance: Any = None,
        confidence: Any = None,
        vehicle: Any = None,
    ) -> bool:
        """Target ``target_id`` was measured at ``position`` (2,) m at mission time ``t`` s,
        with noise ``covariance`` (2, 2) m^2 (default the scenario's ``R``); ``False``
        (logged with the reason) if refused. Without identity ``target_id`` is ``None`` and
        the report waits for its tick's look (numbered ``report`` in its record; a
        ``confidence`` in ``[0, 1]`` is logged, not used by the association); a team's report
        names the ``vehicle`` whose camera took it (its look is that vehicle's). A named
        detection's ``vehicle`` is logged."""
        with self._lock:
            t = log_float(t)
            z = vector(position, (2,))
            record = {
                "kind": "detection",
                "t": t,
                "target": raw(target_id),
                "position": z if z is not None else raw(position),
            }
            if covariance is not None:
                record["covariance"] = raw(covariance)
            if confidence is not None:
                record["confidence"] = raw(confidence)
            if vehicle is not None:
                record["vehicle"] = raw(vehicle)
            problem = self._vehicle_problem(vehicle)
            if problem is not None:
                return self.journal.refuse("detection", record, *problem)
            check = self.checks.detection(
                t, target_id, z, covariance, self.clock.ahead(t), self._ended(),
                self._belief_source(), confidence,
            )  # fmt: skip
            if check.problem is not None:
                return self.journal.refuse("detection", record, *check.problem)
            self._det_seq += 1
            if self._tracked is not None:
                self._tracked.add(t, z, self._det_seq, 0 if vehicle is None else vehicle)
                self.clock.observe(t)
                self.last_detection = {"target": None, "t": t, "position": z.tolist()}
                return self.journal.accept("detection", {**record, "report": self._det_seq})
            self._beliefs.add(check.index, t, z, check.noise, self._det_seq)
            self.clock.observe(t)
            self._for_planner.append((t, check.index))
            self._for_record.append((t, check.index))
            self.last_detection = {"target": target_id, "t": t, "position": z.tolist()}
            return self.journal.accept("detection", record)

    # --- setpoints ----------------------------------------------------------------------
    def setpoint(self, t: float) -> Setpoint:
        """Where the vehicle should be at mission time ``t`` s. Never waits for the planner:
        processes a due tick (hands the planner its observation), takes a plan that has
        arrived, and returns the latest decision's reference or a hold."""
        with self._lock, self.journal.call():
            asked = log_float(t)
            t, problem = self.clock.call(asked)
            if problem is not None:
                record = {"kind": "setpoint", "t": asked}
                self.journal.refuse("setpoint", record, "bad time", problem)
            if not self.finished:
                self._process_tick(t)
            if not self.finished:
                self._poll(t)
            return self._output(t)

    def _process_tick(self, t: float) -> None:
        due = self.clock.due(t)
        if due is None:
            return
        k, missed = due
        if self._tracked is not None:
            self._look(t, k, missed)
        if k == self.mission.n_steps:
            self._finish(t, "budget", self.mission.n_steps * self.mission.time_step)
            return
        time_k = k * self.mission.time_step
        recorded = self._recorded(time_k)
        if self._informs and self._odom is not None and time_k >= self._beliefs.horizon_s:
            for i in np.flatnonzero(~recorded):
                for agent in np.atleast_2d(self._odom[1]):  # a team's vehicles in turn
                    self._beliefs.add_miss(int(i), time_k, agent)
        means, covs = self._belief_source().at(time_k)
        agent = None if self._odom is None else self._odom[1]
        record: dict[str, Any] = {
            "kind": "tick",
            "t": t,
            "k": k,
            "time": time_k,
            "agent": agent,
            "logdet": position_logdet(covs),
            "means": means,
        }
        if missed:
            record["missed"] = missed
        record.update(self._tick_fields(agent))
        fall_back = False
        if self._odom is None:
            record.update(submitted=False, reason="no odometry yet")
        elif self.worker.in_flight is not None:
            busy = self.worker.in_flight[0]
            record.update(submitted=False, reason=f"planner busy with tick {busy}")
            fall_back = self.fallback.active
        else:
            detected = self._detected(time_k)
            record.update(
                submitted=True,
                detected=[self.mission.target_ids[i] for i in np.flatnonzero(detected)],
            )
            obs = observation(k, time_k, self.mission.budget, self._odom[1], means, covs, detected)
            self.worker.submit(obs, t)
        self._last_tick = record
        self.history.tick(k, agent, means, covs, recorded)
        self.journal.write(record)
        if fall_back:
            self._fall_back(t, f"planner late with tick {self.worker.in_flight[0]}")

    def _tick_fields(self, agent: np.ndarray | None) -> dict[str, Any]:
        """Fields a tick record adds for the vehicles at ``agent`` (none for one UAV; a team's
        controller adds its separation)."""
        return {}

    def _end_fields(self) -> dict[str, Any]:
        """Fields the ``end`` record adds (none for one UAV; a team's separation)."""
        return {}

    def _vehicle_problem(self, vehicle: Any) -> tuple[str, str] | None:
        """Why a detection's ``vehicle`` is refused (``(reason, detail)``), or ``None``: one
        UAV takes none or 0; a team's report without identity must name one of its vehicles,
        and a team's named detection may."""
        m = self.mission.n_vehicles
        if vehicle is None:
            if self._tracked is not None and m > 1:
                return "no vehicle", (
                    "a report without id on a team names the vehicle whose camera took it "
                    f"(its vehicle field, 0..{m - 1})"
                )
            return None
        if isinstance(vehicle, bool) or not isinstance(vehicle, int) or not 0 <= vehicle < m:
            return "unknown vehicle", f"vehicle {raw(vehicle)!r} is not one of 0..{m - 1}"
        return None

    def _belief_source(self) -> BeliefTimeline | TrackedBeliefs:
        """Where the beliefs at a time come from: the tracker's without identity."""
        return self._beliefs if self._tracked is None else self._tracked

    def _look(self, t: float, k: int, missed: int) -> None:
        """The tracker's looks of ticks ``k - missed .. k`` (one each; a team's, one per
        vehicle in turn, each from its own) from the latest odometry (the start before any),
        logged as ``look`` records (with the ``vehicle`` of a team)."""
        assert self._tracked is not None
        agents = np.atleast_2d(self._hold_at if self._odom is None else self._odom[1])
        team = len(agents) > 1
        for j in range(k - missed, k + 1):
            for vehicle, agent in enumerate(agents):
                look = self._tracked.look(j, agent, vehicle)
                self._seen_for_planner |= look.seen
                self._seen_for_record |= look.seen
                record = look.record
                self.tracking["looks"] += 1
                self.tracking["reports"] += len(record["reports"])
                self.tracking["taken by a belief"] += sum(b is not None for b in record["belief"])
                self.tracking["claims"] += len(record["claims"])
                self.tracking["superseded"] += len(record.get("superseded", ()))
                self.journal.write({**record, "t": t, **({"vehicle": vehicle} if team else {})})

    def _detected(self, time_s: float) -> np.ndarray:
        """The targets detected since the planner's last observation, up to ``time_s``."""
        if self._tracked is None:
            return self._take(self._for_planner, time_s)
        flags, self._seen_for_planner = self._seen_for_planner, self._unseen.copy()
        return flags

    def _recorded(self, time_s: float) -> np.ndarray:
        """The targets detected since the history's last row, up to ``time_s``."""
        if self._tracked is None:
            return self._take(self._for_record, time_s)
        flags, self._seen_for_record = self._seen_for_record, self._unseen.copy()
        return flags

    def _take(self, pending: list[tuple[float, int]], time_s: float) -> np.ndarray:
        """Flags of the targets measured at or before ``time_s`` in ``pending`` (removed)."""
        flags = np.zeros(self.mission.n_targets, dtype=bool)
        keep = []
        for t, i in pending:
            if t <= time_s + STEP_TOLERANCE:
                flags[i] = True
            else:
                keep.append((t, i))
        pending[:] = keep
        return flags

    def _poll(self, t: float) -> None:
        poll = self.worker.poll(t)
        if poll is None:
            return
        if poll.outcome is None:
            if poll.newly_late:
                self.journal.rejected["plan: late"] += 1
                self.journal.write(
                    {
                        "kind": "late",
                        "t": t,
                        "k": poll.tick,
                        "waited_s": poll.waited_s,
                        "detail": "flying the fallback decision meanwhile",
                    }
                )
                self._fall_back(t, f"planner late with tick {poll.tick}")
            return
        self._apply(poll.outcome, t, late=poll.late)

    def _apply(self, outcome: PlanOutcome, t: float, late: bool, after_end: bool = False) -> None:
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
            self.journal.rejected["plan: error"] += 1
            self._planner_error = outcome.error
        elif late and self.fallback.active:
            record["detail"] = "not flown: the fallback flies until the next tick's plan"
            self.plan = outcome.plan
        elif not after_end:
            self.fallback.stop()
            self._fly(outcome.waypoint, t)
            self._planner_error = None
            self.plan = outcome.plan
            if outcome.tick == 0 and self.first_plan_s is None:
                self.first_plan_s = outcome.compute_s
        if after_end:
            record["after_end"] = True
        self.journal.write(record)

    def _output(self, t: float) -> Setpoint:
        mode, detail, hold = self._update_mode(t)
        if hold:
            reference, velocity = self._inside(t, self._hold_at.copy(), np.zeros(2))
            return Setpoint(self._hold_at.copy(), True, mode, detail, reference, velocity)
        reference, velocity = self._inside(t, *self._leg.at(t))
        return Setpoint(self._waypoint.copy(), False, mode, detail, reference, velocity)

    def _update_mode(self, t: float) -> tuple[str, str, bool]:
        """The setpoint mode at ``t`` s, its detail and whether it holds; a change of mode is
        logged (a ``mode`` record) and a hold starts where the vehicle is."""
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
        elif self.fallback.active:
            mode, detail = "fallback", "the planner is late: flying a greedy decision"
        else:
            mode, detail = "tracking", "flying the planner's waypoint"
        hold = mode not in FLYING
        if mode != self._mode:
            if self._odom is not None:
                self._hold_at = self._odom[1].copy()
            self._mode = mode
            position = self._hold_at if hold else self._waypoint
            self.journal.write(
                {
                    "kind": "mode",
                    "t": t,
                    "mode": mode,
                    "hold": hold,
                    "position": position,
                    "detail": detail,
                }
            )
        return mode, detail, hold

    def _inside(
        self, t: float, reference: np.ndarray, velocity: np.ndarray, vehicle: int | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The reference (m) and feed-forward (m/s) to send at ``t`` s: as they are where the
        fence's free space (shrunk by its margin) holds the reference, else the reference
        projected onto the free space (`nearest_free`) with no feed-forward, logged as a
        ``fence`` record (with the ``vehicle`` of a team)."""
        if self._fence is None or point_free(self._fence, reference[0], reference[1]):
            return reference, velocity
        projected = np.array(nearest_free(self._fence, reference[0], reference[1]))
        self.fence_projections += 1
        record = {"kind": "fence", "t": t, "reference": reference, "projected": projected}
        if vehicle is not None:
            record["vehicle"] = vehicle
        self.journal.write(record)
        return projected, np.zeros(2)

    def _fly(self, waypoint: np.ndarray, t: float) -> None:
        """Make ``waypoint`` the decision flown from the latest odometry at time ``t``: a leg
        shifted by the vehicle's lag behind the reference it was flying (`Leg.lag`), unless the
        settings say otherwise or the vehicle was holding."""
        self._waypoint = waypoint
        start = self._hold_at if self._odom is None else self._odom[1]
        lag = np.zeros(2)
        if self.settings.keep_lag and self._leg is not None and self._mode in FLYING:
            lag = self._leg.lag(t, start, self.mission.step_length)
        self._leg = Leg(start + lag, t, waypoint + lag, self.mission.agent_speed)

    def _fall_back(self, t: float, why: str) -> None:
        """The fallback's decision on the beliefs at ``t`` from the latest odometry, flown at
        once while the planner is late (logged as ``fallback``)."""
        means, covs = self._belief_source().at(t)
        no_detections = np.zeros(self.mission.n_targets, dtype=bool)
        step = max(self.clock.tick, 0)
        obs = observation(step, t, self.mission.budget, self._odom[1], means, covs, no_detections)
        waypoint = self.fallback.decide(obs)
        self._fly(waypoint, t)
        self.journal.accepted["fallback"] += 1
        self.journal.write(
            {
                "kind": "fallback",
                "t": t,
                "k": self.clock.tick,
                "waypoint": waypoint,
                "planner": self.fallback.planner.name,
                "reason": why,
            }
        )

    # --- before the mission ---------------------------------------------------------------
    def prepare(self, position: Any) -> None:
        """Before the mission starts (during take-off): the vehicle will start at
        ``position`` (2,) m; hands tick 0 to the planner (its kernels compile or load in that
        first call). Follow with `first_plan`."""
        self.odometry(0.0, position)
        self.setpoint(0.0)

    def first_plan(self, timeout_s: float) -> float | None:
        """Wait up to ``timeout_s`` s (without holding the controller) for tick 0's plan and
        take it; returns its compute time, s, or ``None`` if it did not come."""
        if self.worker.wait(timeout_s):
            self.setpoint(0.0)
        return self.first_plan_s

    # --- the end --------------------------------------------------------------------------
    def finish(self, t: float, reason: str) -> dict:
        """End the mission at time ``t`` s for ``reason`` (idempotent); returns the ``end``
        record (``U`` of the beliefs at ``min(t, budget)``)."""
        with self._lock:
            if not self.finished:
                t = log_float(t)
                t = self.clock.last_call if not np.isfinite(t) else t
                self._finish(t, reason, min(max(t, 0.0), self.mission.budget))
            return self.end

    def _finish(self, t: float, reason: str, time_s: float) -> None:
        outcome = self.worker.drain()
        if outcome is not None:
            self._apply(outcome, t, late=False, after_end=True)
        info = self.worker.info()
        self.finished = True
        means, covs = self._belief_source().at(time_s)
        logdet = position_logdet(covs)
        agent = None if self._odom is None else self._odom[1].copy()
        self.history.end(time_s, agent, means, covs, self._recorded(time_s))
        end = {
            "kind": "end",
            "t": t,
            "time": time_s,
            "reason": reason,
            "U": float(logdet.sum()),
            "per_target_logdet": dict(zip(self.mission.target_ids, logdet.tolist(), strict=True)),
            "accepted": dict(self.accepted),
            "rejected": dict(self.rejected),
            "planner_info": info,
        }
        if self._tracked is not None:
            end["tracking"] = dict(self.tracking)
        end.update(self._end_fields())
        self.end = self.journal.write(end)
        self.worker.close()

    def close(self) -> None:
        """Stop the planner runner (the log stays open: its owner closes it)."""
        self.worker.close()

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
        return self._belief_source().newest_s

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
                "t": self.clock.last_call,
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
                "tracking": None if self._tracked is None else self._tracking_status(),
                "fence": None
                if self._fence is None
                else {
                    "margin_m": self.scenario.fence.margin,
                    "vehicle_free": None
                    if self._odom is None
                    else all(point_free(self._fence, *p) for p in np.atleast_2d(self._odom[1])),
                    "projections": self.fence_projections,
                },
            }

    def _tracking_status(self) -> dict[str, Any]:
        """Without identity, for a live view: the last look's associations (each report's
        position, the belief it went to, its weight), the claims, the tentative tracks and the
        counts so far."""
        assert self._tracked is not None
        look = self._tracked.last_look
        return {
            "counts": dict(self.tracking),
            "look": None if look is None else {
                "k": look["k"],
                "time": look["time"],
                "belief": look["belief"],
                "weight": np.asarray(look["weight"]).tolist(),
                "claims": look["claims"],
            },
            "tentative": [] if look is None else look["tentative"],
            "waiting": len(self._tracked.pending),
        }  # fmt: skip

    def episode_record(self, truth: np.ndarray | None = None) -> EpisodeRecord:
        """The mission as an `EpisodeRecord` (for the mission
        figure; `episode_record`); ``truth``
        ``(K+1, n, 4)`` if known, else NaN. Call after `finish`."""
        if not self.finished:
            raise RuntimeError("episode_record() needs a finished mission")
        info = dict(self.end.get("planner_info") or {})
        return self.history.episode_record(self.worker.planner.name, self.seed, info, truth)
