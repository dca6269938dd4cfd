"""The mission controller of a team (``agents:``): one planner for the team, one leg per
vehicle, and a minimum horizontal distance between the vehicles kept by the legs.

`TeamController` is the `MissionController` with a vehicle index on every odometry: each
vehicle's odometry is checked against its own last one (its own speed), the planner's
observation has every vehicle's position (``(m, 2)`` m) once each has reported, the team
planner's ``(m, 2)`` waypoints become one `Leg` per vehicle (each from its own odometry at its
own speed, with its own lag kept), and a late planner is replaced by ``team-greedy`` on the
current beliefs. The setpoint mode is the team's: every vehicle holds when any vehicle's
odometry is stale, before the first plan, or after a planner error.

Separation (`separate`): at every ``setpoint`` call the vehicles' references are kept at least
``separation_m`` apart by a fixed rule, the lower index first: vehicle ``j`` yields when its
straight way from its odometry to its reference comes within ``separation_m`` of the final
reference of a vehicle ``i < j``; its reference becomes the point ``separation_m`` from ``i``'s
on ``j``'s own side, with no feed-forward (it holds there, or is pushed back). The first vehicle
never yields. A vehicle that starts or stops yielding is logged (a ``yield`` record); every tick
records the smallest pairwise distance between the vehicles' latest odometry
(``separation_m``), and the ``end`` record the smallest over the ticks, the smallest between
the references of any ``setpoint`` call and the yields, which a replay derives again and
checks.

Fence: every vehicle's reference, once kept apart, is kept inside the fence's free space (the
fence shrunk by its margin) as one vehicle's is (`MissionController._inside`: projected onto it
and logged, with the vehicle's index); the separation is not checked again after a projection,
and the smallest distance between the references sent says what it left.

Negative information: a tick's look is every vehicle's, one after the other from its latest
odometry (the simulator's order); a target that no vehicle detected in the tick's interval gets
each vehicle's miss update, and one that any vehicle detected gets none (a named detection does
not say which camera took it, so the simulator's miss by one vehicle before another's detection
in the same step is not made in flight).

Without identity (``sensor.labelled: false``) each report names the vehicle whose camera took it
(``vehicle``), and a tick's look is every vehicle's in turn, each of its own reports from its
own odometry, as the simulator's tracker looks (`hptrack.runtime.looks.TrackedBeliefs`).

A team flies with one measurement noise on every vehicle, and with ``negative_information`` one
footprint (`team_flight_problem`; without identity the scenario itself asks for both).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from hptrack.interface import InputError, Planner
from hptrack.runtime.controller import FLYING, MissionController
from hptrack.runtime.inputs import ControllerSettings, raw, vector
from hptrack.runtime.legs import Leg, Setpoint
from hptrack.runtime.log import MissionLog, log_float
from hptrack.runtime.record import MissionHistory
from hptrack.runtime.worker import Fallback, PlannerRunner
from hptrack.scenario.model import Scenario
from hptrack.teams.sequential import TeamGreedyPlanner

DEFAULT_SEPARATION_M = 10.0
"""The default minimum horizontal distance between two vehicles' references, m: each vehicle
flies up to about 2.1 m behind its reference (PX4's 0.8 velocity tracking at 8 m/s,
`hptrack.runtime.legs.tracking_lag_m`) and GNSS puts each 1-3 m off, so references 10 m apart
leave the airframes (a quadrotor under 1 m across) a few metres apart in the worst case."""
MAX_SEPARATION_M = 1000.0
"""The largest separation accepted, m."""


def team_flight_problem(scenario: Scenario) -> str | None:
    """Why a team flight cannot fly ``scenario`` (one line), or ``None``."""
    sensor = scenario.sensor_spec()
    diameters = {scenario.sensor_spec(j).diameter for j in range(scenario.n_vehicles)}
    if sensor.negative_information and len(diameters) > 1:
        return (
            "a team flies sensor.negative_information with one footprint: give every UAV of "
            "agents the same sensor_diameter"
        )
    noises = {
        scenario.sensor_spec(j).noise_covariance().tobytes() for j in range(scenario.n_vehicles)
    }
    if len(noises) > 1:
        return (
            "a team flies with one measurement noise for every UAV of agents (a detection "
            "does not say which UAV's camera took it)"
        )
    return None


def synthetic_team_problem(scenario: Scenario) -> str | None:
    """Why the synthetic targets (``vehicle-sim``, ``targets-sim``) cannot look with every UAV
    of ``scenario``'s team (one line), or ``None``: a detector with misses or false alarms
    (`hptrack.runtime.world.synthetic_detector`) looks with one footprint."""
    sensor = scenario.sensor_spec()
    diameters = {scenario.sensor_spec(j).diameter for j in range(scenario.n_vehicles)}
    if len(diameters) > 1 and (
        sensor.detection_probability != 1.0 or sensor.false_alarm_density > 0.0
    ):
        return (
            "the synthetic detector with misses or false alarms looks with one footprint: give "
            "every UAV of agents the same sensor_diameter"
        )
    return None


def pairwise_minimum(positions: np.ndarray) -> float:
    """The smallest distance between two of ``positions`` ``(m, 2)``, m (``inf`` for one)."""
    p = np.asarray(positions, dtype=float)
    gaps = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
    upper = gaps[np.triu_indices(len(p), 1)]
    return float(upper.min()) if upper.size else float("inf")


def segment_distance(start: np.ndarray, end: np.ndarray, point: np.ndarray) -> float:
    """The distance from ``point`` to the segment from ``start`` to ``end`` (each (2,) m), m."""
    step = end - start
    length2 = float(step @ step)
    share = 0.0 if length2 == 0.0 else min(max(float((point - start) @ step) / length2, 0.0), 1.0)
    return float(np.hypot(*(start + share * step - point)))


def separate(
    references: np.ndarray,
    velocities: np.ndarray,
    positions: np.ndarray,
    minimum_m: float,
) -> tuple[np.ndarray, np.ndarray, list[int | None]]:
    """The references ``(m, 2)`` m and feed-forward velocities ``(m, 2)`` m/s of vehicles at
    ``positions`` ``(m, 2)`` m kept at least ``minimum_m`` apart, the lower index first, and
    for each vehicle the vehicle it yields to (``None``: none).

    Vehicle ``j`` yields to the nearest earlier vehicle ``i`` whose final reference is within
    ``minimum_m`` of the straight way from ``j``'s position to ``j``'s reference: ``j``'s
    reference becomes the point ``minimum_m`` from ``i``'s on ``j``'s own side (towards its
    position, so it never flies through the other's circle), with no feed-forward; a vehicle
    on top of another's reference is sent east. It is checked again against every earlier
    vehicle, at most ``m`` times."""
    refs = np.array(references, dtype=float)
    vels = np.array(velocities, dtype=float)
    here = np.array(positions, dtype=float)
    yields: list[int | None] = [None] * len(refs)
    for j in range(1, len(refs)):
        for _ in range(len(refs)):
            gaps = np.array([segment_distance(here[j], refs[j], refs[i]) for i in range(j)])
            i = int(np.argmin(gaps))
            if gaps[i] >= minimum_m:
                break
            side = here[j] - refs[i]
            norm = float(np.hypot(*side))
            unit = side / norm if norm > 0.0 else np.array([1.0, 0.0])
            refs[j] = refs[i] + minimum_m * unit
            here[j] = refs[j]  # the way is now the reference itself
            vels[j] = 0.0
            if yields[j] is None:
                yields[j] = i
    return refs, vels, yields


class TeamController(MissionController):
    """The mission controller of a team (module docstring).

    Args:
        scenario: the mission, a team (``agents:``).
        planner: a fresh team planner (``hptrack.registry.check_team``).
        separation_m: the minimum horizontal distance between two vehicles' references, m.
        seed, settings, log, runner, header: as `MissionController`'s.

    Raises:
        InputError: the scenario is no team or cannot be flown as one (`team_flight_problem`),
            or the separation is out of range.
    """

    def __init__(
        self,
        scenario: Scenario,
        planner: Planner,
        *,
        separation_m: float = DEFAULT_SEPARATION_M,
        seed: int | None = None,
        settings: ControllerSettings | None = None,
        log: MissionLog | None = None,
        runner: PlannerRunner | None = None,
        header: dict | None = None,
    ) -> None:
        problem = team_flight_problem(scenario)
        if problem is not None:
            raise InputError(problem)
        separation_m = log_float(separation_m)
        if not 0.0 <= separation_m <= MAX_SEPARATION_M:
            raise InputError(
                f"--separation must be a number in [0, {MAX_SEPARATION_M:g}] m, got {separation_m}"
            )
        self.n_vehicles = scenario.n_vehicles
        self.separation_m = separation_m
        super().__init__(
            scenario,
            planner,
            seed=seed,
            settings=settings,
            log=log,
            runner=runner,
            header={**(header or {}), "separation_m": separation_m},
        )
        starts = scenario.starts()
        self.history = MissionHistory(self.mission, starts)
        self._hold_at = starts.copy()
        self.fallback = Fallback(self.mission, self.seed, TeamGreedyPlanner())
        self._vehicle_checks = []
        for j in range(self.n_vehicles):
            checks = copy.copy(self.checks)
            checks.mission = self.mission.vehicle_mission(j)  # its own speed for the jumps
            self._vehicle_checks.append(checks)
        self._odoms: list[tuple[float, np.ndarray] | None] = [None] * self.n_vehicles
        self._legs: list[Leg] | None = None
        self._yielding: list[int | None] = [None] * self.n_vehicles
        self.yields = 0
        """Times a vehicle started yielding to another."""
        self.min_separation_m = float("inf")
        """The smallest ``separation_m`` of the ticks so far (the vehicles' odometry), m."""
        self.min_reference_separation_m = float("inf")
        """The smallest distance between two vehicles' references sent so far, m."""
        self.last_setpoints: list[Setpoint] = []
        """Every vehicle's setpoint of the last ``setpoint`` call."""

    # --- events -------------------------------------------------------------------------
    def odometry(self, t: float, position: Any, vehicle: int = 0) -> bool:
        """Vehicle ``vehicle`` was at ``position`` (2,) m at mission time ``t`` s; ``False``
        (logged with the reason) if refused."""
        with self._lock:
            t = log_float(t)
            p = vector(position, (2,))
            record = {
                "kind": "odometry",
                "t": t,
                "vehicle": vehicle,
                "position": p if p is not None else raw(position),
            }
            if not (isinstance(vehicle, int) and 0 <= vehicle < self.n_vehicles):
                detail = f"vehicle {vehicle!r} is not one of the team's 0..{self.n_vehicles - 1}"
                return self.journal.refuse("odometry", record, "unknown vehicle", detail)
            checks = self._vehicle_checks[vehicle]
            problem = checks.odometry(t, p, self._odoms[vehicle], self._ended())
            if problem is not None:
                return self.journal.refuse("odometry", record, *problem)
            assert p is not None  # checked
            self._odoms[vehicle] = (t, p)
            if all(o is not None for o in self._odoms):
                known = [o for o in self._odoms if o is not None]
                self._odom = (min(o[0] for o in known), np.array([o[1] for o in known]))
            self.clock.observe(t)
            return self.journal.accept("odometry", record)

    def setpoints(self, t: float) -> list[Setpoint]:
        """Every vehicle's setpoint at mission time ``t`` s (`MissionController.setpoint`),
        kept apart by the separation rule."""
        self.setpoint(t)
        return list(self.last_setpoints)

    # --- the team's parts -----------------------------------------------------------------
    def _tick_fields(self, agent: np.ndarray | None) -> dict[str, Any]:
        if agent is None:
            return {}
        distance = pairwise_minimum(agent)
        self.min_separation_m = min(self.min_separation_m, distance)
        return {"separation_m": distance}

    def _fly(self, waypoint: np.ndarray, t: float) -> None:
        """One leg per vehicle towards its row of ``waypoint`` ``(m, 2)``, each from its own
        odometry at its own speed, shifted by its own lag (`MissionController._fly`)."""
        self._waypoint = np.asarray(waypoint, dtype=float)
        starts = self._hold_at if self._odom is None else self._odom[1]
        legs = []
        for j in range(self.n_vehicles):
            mission = self.mission.vehicle_mission(j)
            lag = np.zeros(2)
            if self.settings.keep_lag and self._legs is not None and self._mode in FLYING:
                lag = self._legs[j].lag(t, starts[j], mission.step_length)
            legs.append(Leg(starts[j] + lag, t, self._waypoint[j] + lag, mission.agent_speed))
        self._legs = legs
        self._leg = legs[0]

    def _output(self, t: float) -> Setpoint:
        mode, detail, hold = self._update_mode(t)
        m = self.n_vehicles
        if hold:
            refs, vels = self._hold_at.copy(), np.zeros((m, 2))
            goals = self._hold_at.copy()
        else:
            assert self._legs is not None and self._waypoint is not None
            parts = [leg.at(t) for leg in self._legs]
            refs = np.array([p[0] for p in parts])
            vels = np.array([p[1] for p in parts])
            goals = self._waypoint.copy()
        here = refs if self._odom is None else self._odom[1]
        refs, vels, yields = separate(refs, vels, here, self.separation_m)
        for j in range(m):
            refs[j], vels[j] = self._inside(t, refs[j], vels[j], vehicle=j)
        self.min_reference_separation_m = min(
            self.min_reference_separation_m, pairwise_minimum(refs)
        )
        for j, (before, now) in enumerate(zip(self._yielding, yields, strict=True)):
            if (before is None) != (now is None):
                self.yields += now is not None
                self.journal.write(
                    {
                        "kind": "yield",
                        "t": t,
                        "vehicle": j,
                        "to": now,
                        "reference": refs[j],
                        "detail": "yields no more"
                        if now is None
                        else f"kept {self.separation_m:g} m from vehicle {now}",
                    }
                )
        self._yielding = yields
        self.last_setpoints = [
            Setpoint(goals[j].copy(), hold, mode, detail, refs[j], vels[j]) for j in range(m)
        ]
        return self.last_setpoints[0]

    def _end_fields(self) -> dict[str, Any]:
        return {
            "separation_m": self.separation_m,
            "min_separation_m": self.min_separation_m,
            "min_reference_separation_m": self.min_reference_separation_m,
            "yields": self.yields,
        }

    # --- before the mission ---------------------------------------------------------------
    def prepare(self, position: Any) -> None:
        """Before the mission starts: the vehicles will start at ``position`` ``(m, 2)`` m;
        hands tick 0 to the planner (`MissionController.prepare`)."""
        for j, p in enumerate(np.asarray(position, dtype=float)):
            self.odometry(0.0, p, vehicle=j)
        self.setpoint(0.0)

    def status(self) -> dict[str, Any]:
        """`MissionController.status` with the vehicles each vehicle yields to and the
        smallest separation of the ticks so far."""
        status = super().status()
        with self._lock:
            status["yielding"] = list(self._yielding)
            status["min_separation_m"] = self.min_separation_m
        return status
