"""The simulated world drives the controller on a simulated clock (fast, not wall time), with
the faults a real flight has: odometry rate, outages and drops, detection rate, latency,
jitter and drops, planner compute times beyond the deadline, and malformed or hostile inputs.

The world is the simulator's (`hptrack.sim.step`): true initial states from
`initial_true_states`, one step of true motion per ``tau`` from the
scenario's motion model (linearly interpolated between steps for sensing at other rates), the
sensor's footprint and noise (without identity, ``sensor.labelled: false``: the simulator's
detector, `hptrack.runtime.world.synthetic_detector`, whose reports carry no id), and the agent
moving straight towards the controller's setpoint at
``v_a`` (`move_towards`). The clock advances in physics steps of
``1 / setpoint_rate_hz``; at each step the world senses, due events are delivered in delivery
order, then ``setpoint`` is called and the agent moves.

Randomness: ``SeedSequence(seed)`` spawns the simulator's four streams (truth, motion, sensor,
planner: the same missions as `run_episode`) and a fifth for the
faults. Without faults, with detections every ``tau`` and no planner delay, the controller sees
what the simulator's planner sees, step for step.
"""

from __future__ import annotations

import heapq
import math
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from hptrack.interface import InputError, Planner
from hptrack.models.vehicle import move_towards
from hptrack.runtime.controller import MissionController
from hptrack.runtime.inputs import ControllerSettings
from hptrack.runtime.log import MissionLog
from hptrack.runtime.team import DEFAULT_SEPARATION_M, TeamController
from hptrack.runtime.worker import InlineRunner
from hptrack.runtime.world import TrueTargets, synthetic_detector
from hptrack.scenario.model import Scenario
from hptrack.sim.record import EpisodeRecord

Probability = Annotated[float, Field(ge=0.0, le=1.0)]
Seconds = Annotated[float, Field(ge=0.0, le=3600.0)]


class SimulatedFaults(BaseModel):
    """Rates and faults of a simulated run (Hz, s, probabilities per event).

    Attributes:
        setpoint_rate_hz: setpoint calls per second (the physics step); ``tau`` must be a
            whole number of steps.
        odometry_rate_hz: odometry per second.
        odometry_drop_probability: chance that one odometry is lost.
        odometry_outages: ``(start_s, duration_s)`` windows without odometry.
        detection_rate_hz: sensing per second; default one per ``tau`` (as the simulator).
        detection_latency_s: delay from measurement to delivery.
        detection_jitter_s: extra delivery delay, uniform in ``[0, jitter]`` (reorders).
        detection_drop_probability: chance that one detection is lost.
        planner_delay_s: simulated compute time of every planner call.
        planner_slow_probability: chance that a call takes ``planner_slow_delay_s`` more.
        planner_slow_delay_s: the extra compute time of a slow call.
        bad_input_rate_hz: hostile inputs per second (NaN, unknown ids, duplicates, jumps,
            stale or future stamps, a bad covariance), each refused by the controller.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    setpoint_rate_hz: Annotated[float, Field(gt=0.0, le=1000.0)] = 20.0
    odometry_rate_hz: Annotated[float, Field(gt=0.0, le=1000.0)] = 10.0
    odometry_drop_probability: Probability = 0.0
    odometry_outages: tuple[tuple[Seconds, Seconds], ...] = ()
    detection_rate_hz: Annotated[float | None, Field(gt=0.0, le=1000.0)] = None
    detection_latency_s: Seconds = 0.0
    detection_jitter_s: Seconds = 0.0
    detection_drop_probability: Probability = 0.0
    planner_delay_s: Seconds = 0.0
    planner_slow_probability: Probability = 0.0
    planner_slow_delay_s: Seconds = 0.0
    bad_input_rate_hz: Annotated[float, Field(ge=0.0, le=1000.0)] = 0.0


@dataclass
class SimulatedRun:
    """A finished simulated mission.

    Attributes:
        controller: the controller that flew it (its log, counts, history).
        record: the mission with the true target states.
        fed: inputs handed to the controller by kind (``odometry``, ``detection``,
            ``bad``).
        wall_s: wall time of the run, s.
    """

    controller: MissionController
    record: EpisodeRecord
    fed: Counter
    wall_s: float

    @property
    def uncertainty(self) -> float:
        """``U`` at the mission's end."""
        return self.record.uncertainty


class _Clock:
    """Physics time ``j`` steps in, exact at whole ``tau``."""

    def __init__(self, tau: float, per_tau: int) -> None:
        self.tau, self.per_tau = tau, per_tau

    def __call__(self, j: int) -> float:
        k, m = divmod(j, self.per_tau)
        return k * self.tau + m * (self.tau / self.per_tau)


def _due(j: int, rate_hz: float, clock: _Clock) -> bool:
    """Whether an event of ``rate_hz`` falls in physics step ``j`` (always at ``j = 0``)."""
    if j == 0:
        return True
    return math.floor(clock(j) * rate_hz + 1e-9) > math.floor(clock(j - 1) * rate_hz + 1e-9)


def run_simulated(
    scenario: Scenario,
    planner: Planner,
    seed: int | None = None,
    faults: SimulatedFaults | None = None,
    settings: ControllerSettings | None = None,
    log: MissionLog | None = None,
    on_step: Callable[[float], None] | None = None,
    separation_m: float = DEFAULT_SEPARATION_M,
) -> SimulatedRun:
    """Fly ``planner`` through ``scenario`` with a `MissionController` on a simulated
    clock (module docstring); a team (``agents:``) with a
    `hptrack.runtime.team.TeamController` keeping ``separation_m`` (m), each vehicle moving
    towards its reference (so that the separation rule is what it flies).

    Raises:
        InputError: ``tau`` is not a whole number of physics steps.
    """
    faults = faults or SimulatedFaults()
    seed = scenario.seed if seed is None else int(seed)
    mission = scenario.mission_spec()
    tau = mission.time_step
    per_tau = round(tau * faults.setpoint_rate_hz)
    if per_tau < 1 or abs(per_tau - tau * faults.setpoint_rate_hz) > 1e-9:
        raise InputError(
            f"setpoint_rate_hz {faults.setpoint_rate_hz:g}: time_step {tau:g} s "
            "is not a whole number of setpoint periods"
        )
    clock = _Clock(tau, per_tau)
    dt = tau / per_tau
    truth_seq, motion_seq, sensor_seq, _, fault_seq = np.random.SeedSequence(seed).spawn(5)
    motion_rng = np.random.default_rng(motion_seq)
    sensor_rng = np.random.default_rng(sensor_seq)
    fault_rng = np.random.default_rng(fault_seq)

    def planner_delay(_tick: int) -> float:
        delay = faults.planner_delay_s
        if (
            faults.planner_slow_probability > 0
            and fault_rng.random() < faults.planner_slow_probability
        ):
            delay += faults.planner_slow_delay_s
        return delay

    log = log if log is not None else MissionLog()
    team = scenario.n_vehicles > 1
    controller = (TeamController if team else MissionController)(
        scenario,
        planner,
        seed=seed,
        settings=settings,
        log=log,
        runner=InlineRunner(planner_delay),
        header={"source": "simulated", "faults": faults.model_dump(mode="json")},
        **({"separation_m": separation_m} if team else {}),
    )
    vehicles = [mission.vehicle_mission(j) for j in range(scenario.n_vehicles)]
    unlabelled = not scenario.sensor_spec().labelled
    detector = synthetic_detector(scenario, seed) if unlabelled else None
    targets = TrueTargets(scenario, np.random.default_rng(truth_seq), motion_rng)
    agents = scenario.starts()
    detection_rate = faults.detection_rate_hz or 1.0 / tau
    events: list[tuple[float, int, str, tuple]] = []
    fed: Counter = Counter()
    order = 0

    def schedule(at: float, kind: str, args: tuple) -> None:
        nonlocal order
        order += 1
        heapq.heappush(events, (at, order, kind, args))

    def in_outage(t: float) -> bool:
        return any(start <= t < start + length for start, length in faults.odometry_outages)

    last_detection: tuple | None = None
    start = time.perf_counter()
    j = 0
    while not controller.finished:
        t = clock(j)
        k, m = divmod(j, per_tau)
        if m == 0:
            log.write({"kind": "truth", "t": t, "k": k, "states": targets.state(k)})
        positions = targets.positions(k, m / per_tau)
        if _due(j, detection_rate, clock):
            looks = []
            for agent, vehicle in zip(agents, vehicles, strict=True):
                if detector is not None:
                    measured = detector.look(agent, positions).positions
                    names: list[str | None] = [None] * len(measured)
                else:
                    sensor = vehicle.sensor
                    seen = np.flatnonzero(sensor.in_footprint(agent, positions))
                    measured = sensor.sample(positions[seen], sensor_rng)
                    names = [mission.target_ids[i] for i in seen]
                looks.extend(zip(names, measured, strict=True))
            for name, z in looks:
                if (
                    faults.detection_drop_probability > 0
                    and fault_rng.random() < faults.detection_drop_probability
                ):
                    continue
                delay = faults.detection_latency_s
                if faults.detection_jitter_s > 0:
                    delay += fault_rng.uniform(0.0, faults.detection_jitter_s)
                schedule(t + delay, "detection", (t, name, z))
        if _due(j, faults.odometry_rate_hz, clock) and not in_outage(t):
            for v, agent in enumerate(agents):
                if not (
                    faults.odometry_drop_probability > 0
                    and fault_rng.random() < faults.odometry_drop_probability
                ):
                    schedule(t, "odometry", (t, agent.copy(), v) if team else (t, agent.copy()))
        if faults.bad_input_rate_hz > 0 and fault_rng.random() < faults.bad_input_rate_hz * dt:
            schedule(t, "bad", (t, int(fault_rng.integers(9))))
        while events and events[0][0] <= t + 1e-12:
            _, _, kind, args = heapq.heappop(events)
            fed[kind] += 1
            if kind == "odometry":
                controller.odometry(*args)
            elif kind == "detection":
                controller.detection(*args)
                last_detection = args
            else:
                _feed_bad(controller, args[0], args[1], dt, agents[0], last_detection)
        if isinstance(controller, TeamController):
            for v, (setpoint, vehicle) in enumerate(
                zip(controller.setpoints(t), vehicles, strict=True)
            ):
                agents[v] = move_towards(agents[v], setpoint.reference, vehicle.agent_speed * dt)
        else:
            setpoint = controller.setpoint(t)
            agents[0] = move_towards(agents[0], setpoint.position, mission.agent_speed * dt)
        if on_step is not None:
            on_step(t)
        j += 1
    wall = time.perf_counter() - start
    last = round(controller.final["time"] / tau)
    truth_array = np.array([targets.state(k) for k in range(last + 1)])
    return SimulatedRun(controller, controller.episode_record(truth_array), fed, wall)


def _feed_bad(
    controller: MissionController,
    t: float,
    which: int,
    dt: float,
    agent: np.ndarray,
    last_detection: tuple | None,
) -> None:
    """One hostile input of kind ``which`` (0-8) at time ``t``."""
    ids = controller.mission.target_ids
    stale = controller.newest_detection_s - controller.settings.reorder_tolerance_s - 1.0
    last = controller.last_odometry
    if which == 0:
        controller.odometry(t, [math.nan, agent[1]])
    elif which == 1:
        controller.odometry(t + 0.5 * dt, agent + 1e4)
    elif which == 2 and last is not None:
        controller.odometry(last[0] - 0.5 * dt, last[1])
    elif which == 2:
        controller.odometry(t, agent[:1])
    elif which == 3:
        controller.detection(t, "no-such-target", agent)
    elif which == 4:
        controller.detection(t, ids[0], [math.inf, 0.0])
    elif which == 5:
        controller.detection(stale, ids[0], agent)
    elif which == 6:
        controller.detection(t, ids[0], agent, [[1.0, 2.0], [2.0, 1.0]])
    elif which == 7:
        controller.detection(t + controller.settings.future_tolerance_s + 1.0, ids[0], agent)
    elif last_detection is not None:
        controller.detection(*last_detection)
    else:
        controller.detection(t, ids[0], [agent])
