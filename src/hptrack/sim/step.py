"""One simulator step as a compiled kernel, and `World`, the simulated mission it steps.

A step ``k -> k+1`` (``tau`` seconds) is the simulator's (`hptrack.sim.episode`): the agent
moves straight towards its waypoint by at most ``v_a tau``; every true target moves by the
scenario's truth motion (`hptrack.models.truth_motion`; by default the paper's ``F`` and ``Q``
noise); every belief is predicted one step (Eq. (1)); every target whose true position lies
within ``w/2`` of the agent is detected (always, with the paper's sensor; with probability
``Pd(d)`` with a `hptrack.models.sensor.DetectingFootprintSensor`), and a detected one is
measured, ``z = [x, y] + L e`` (``L L' = R``), and Kalman-updated. Sensing also happens at
step 0. The kernels call the model kernels of `hptrack.models` (prediction, true motion, Kalman
update, ``log det``); they re-derive none of them.

Randomness is the simulator's: ``SeedSequence(seed).spawn(4)`` gives the streams of the true
initial states, the target motion, the measurement noise and the planner. The motion stream gives
``n x d`` unit normals per step (``d`` the true state's size, 4 unless the truth motion has
accelerations) and the measurement stream ``2`` per measured target, in target
order. A sensor that detects with a probability below one (``sensor_draws``) has a fifth stream,
``SeedSequence(seed, spawn_key=(4,))`` (the fifth child of the same root, so the other four are
unchanged): one uniform per target inside the footprint per look, in target order, the target
detected when it is below ``Pd(d)`` (`hptrack.models.sensor.sensor_detects`); a sensor whose draws
hold over several looks uses the one it holds instead (`hptrack.models.sensor.held_draw`, one
record per UAV), so that the stream is read the same either way. The paper's sensor
draws nothing from it. A sensor without identity (``labelled: false``) reports through
`hptrack.models.detector.Detector` instead, every draw of its looks from a sixth stream,
``SeedSequence(seed, spawn_key=(5,))``, and the beliefs are kept by
`hptrack.models.tracking.Tracker` (the planners see its beliefs; `World.associations` and
`World.claims` say which report went to which belief). A Generator's normals do not depend
on how the draws are split, so `World` draws them in blocks (`NormalBlock`) and the kernels
consume them in the simulator's order: the same seed gives the same mission as
`hptrack.sim.episode.run_episode`.
"""

from __future__ import annotations

import numba
import numpy as np

from hptrack.interface import MissionSpec, Observation
from hptrack.models.beliefs import logdet_xy, position_logdet
from hptrack.models.detector import Detector
from hptrack.models.mission import predict_covariance_on, predict_mean_on
from hptrack.models.sensor import (
    draws_detection,
    held_draw,
    sensor_detects,
    sensor_draws,
    sensor_hold_looks,
    sensor_measures,
    sensor_missed,
    sensor_update,
)
from hptrack.models.state import position_of, positions
from hptrack.models.tracking import Tracker, new_track_covariance
from hptrack.models.truth_motion import advance_truth
from hptrack.models.vehicle import vehicle_move
from hptrack.scenario.model import ConstantAccelerationSpec, Scenario, SingerSpec

BLOCK_STEPS = 256
"""Steps of random normals drawn at a time."""


def initial_true_states(scenario: Scenario, rng: np.random.Generator) -> np.ndarray:
    """True initial states ``(n, d)``: given ones, or draws from each target's prior; a truth
    motion with accelerations (``d = 6``) then draws every target's ``[ax, ay]`` from
    ``N(0, acceleration_std^2)`` per axis (so positions and velocities do not depend on it)."""
    spec = scenario.truth_spec
    d = spec.state_size
    states = np.empty((len(scenario.targets), d))
    for i, target in enumerate(scenario.targets):
        if target.truth is not None:
            states[i, :4] = target.truth
        else:
            states[i, :4] = rng.multivariate_normal(
                target.mean, target.covariance, method="cholesky"
            )
    if isinstance(spec, SingerSpec | ConstantAccelerationSpec):
        states[:, 4:] = spec.acceleration_std * rng.standard_normal((len(scenario.targets), d - 4))
    return states


@numba.njit(cache=True)
def sense(sensor, agent, truth, means, covs, factor, e, e_pos, seen, logdets, z, u, u_pos, held):
    """Measure and update every target the ``sensor`` part detects from ``agent``
    (`hptrack.models.sensor`); a target it does not detect gets the sensor's ``missed``.

    A sensor that ``draws`` takes one uniform of ``u`` from ``u_pos`` per target inside its
    footprint (target order) and detects it by ``sensor_detects``, on that draw or, when its
    draws hold for several looks (``hold_looks``), on the one `held_draw` keeps in ``held``
    ``(n, 2)``; the paper's detects every target inside and reads no ``u``. Consumes two
    normals of ``e`` from ``e_pos`` per detected target (target order; ``factor`` the Cholesky
    factor of ``R``), writes ``seen`` and the per-target ``log det Sigma^xy`` into ``logdets``
    (``z``: a scratch ``(2,)`` for the measurement); returns the new ``e_pos``, ``U`` and the
    new ``u_pos``.
    """
    total = 0.0
    draws = sensor_draws(sensor)
    hold = sensor_hold_looks(sensor)
    for i in range(truth.shape[0]):
        x, y = position_of(truth[i])
        inside = sensor_measures(sensor, agent[0], agent[1], x, y)
        if draws:
            if inside:
                draw = held_draw(held, i, u[u_pos], hold, True)
                u_pos += 1
                inside = sensor_detects(sensor, agent[0], agent[1], x, y, draw)
            else:
                held_draw(held, i, 0.0, hold, False)
        seen[i] = inside
        if inside:
            e0 = e[e_pos]
            e1 = e[e_pos + 1]
            e_pos += 2
            z[0] = x + (e0 * factor[0, 0] + e1 * factor[0, 1])
            z[1] = y + (e0 * factor[1, 0] + e1 * factor[1, 1])
            sensor_update(sensor, means[i], covs[i], z, means[i], covs[i])
        else:
            sensor_missed(sensor, agent[0], agent[1], means[i], covs[i])
        c = covs[i]
        logdets[i] = logdet_xy(c[0, 0], c[0, 1], c[1, 1])
        total += logdets[i]
    return e_pos, total, u_pos


@numba.njit(cache=True)
def world_advance(mission, agent, waypoint, truth_motion, truth, z_motion, sqrt_q, means, covs):
    """The step before sensing, in place: move by the mission's vehicle, true motion by
    ``truth_motion`` with the unit normals ``z_motion`` ``(n, d)``, predict one step."""
    vehicle_move(mission.vehicle, agent, waypoint)
    advance_truth(truth_motion, mission, truth, z_motion, sqrt_q)
    tau = mission.time_step
    q = mission.process_noise
    steps = tau / tau
    elapsed = steps * tau
    for i in range(truth.shape[0]):
        predict_mean_on(mission, means[i], elapsed, means[i])
        predict_covariance_on(mission, covs[i], q[i], steps, covs[i])


@numba.njit(cache=True)
def world_step(
    mission,
    agent,
    waypoint,
    truth_motion,
    truth,
    z_motion,
    sqrt_q,
    means,
    covs,
    factor,
    e,
    e_pos,
    out,
    u,
    u_pos,
):
    """One simulator step in place (module docstring): `world_advance`, then sense by the
    mission's sensor (``factor``: the Cholesky factor of ``R``; ``out``: `sense`'s ``seen``,
    ``logdets``, ``z`` and ``held``; ``u``, ``u_pos``: its detection uniforms). Returns the new
    ``e_pos``, ``U`` and the new ``u_pos``."""
    world_advance(mission, agent, waypoint, truth_motion, truth, z_motion, sqrt_q, means, covs)
    seen, logdets, z, held = out
    return sense(
        mission.sensor, agent, truth, means, covs, factor, e, e_pos, seen, logdets, z, u, u_pos,
        held,
    )  # fmt: skip


@numba.njit(cache=True)
def move_vehicle(mission, agent, waypoint):
    """Move ``agent`` in place towards ``waypoint`` by the mission's vehicle (a team's UAVs
    after the first, which `world_step` moves)."""
    vehicle_move(mission.vehicle, agent, waypoint)


class NormalBlock:
    """Unit normals of one Generator, drawn ``size`` at a time and handed out in order.

    Call ``ensure(count)`` (``count <= size``), read ``values[pos:pos + count]`` and advance
    ``pos``: the values are those of drawing them one call at a time.
    """

    def __init__(self, rng: np.random.Generator, size: int) -> None:
        self.rng = rng
        self.values = self._draw(size)
        self.pos = 0

    def _draw(self, count: int) -> np.ndarray:
        return self.rng.standard_normal(count)

    def ensure(self, count: int) -> None:
        """Make at least ``count`` unused values available from ``pos``."""
        if self.pos + count > self.values.shape[0]:
            rest = self.values[self.pos :]
            self.values = np.concatenate([rest, self._draw(self.pos)])
            self.pos = 0


class UniformBlock(NormalBlock):
    """Uniforms in ``[0, 1)`` of one Generator, handed out as `NormalBlock`'s normals (a
    Generator's uniforms do not depend on how the draws are split either)."""

    def _draw(self, count: int) -> np.ndarray:
        return self.rng.random(count)


DETECTION_STREAM = 4
"""The spawn key of the detection stream, ``SeedSequence(seed, spawn_key=(4,))``: the fifth
child of the simulator's root (the first four are its other streams)."""
DETECTOR_STREAM = 5
"""The spawn key of the detector's stream (detections without identity), the sixth child."""


def unlabelled_parts(scenario: Scenario, seed: int) -> tuple[Detector, Tracker] | None:
    """The detector and tracker of a scenario whose sensor reports no identity (``None`` for a
    labelled one): the detector's Generator from `DETECTOR_STREAM` of ``seed`` (a team's UAVs
    have alike sensors, `Scenario`, and share both, looking in turn)."""
    spec = scenario.sensor_spec()
    if spec.labelled:
        return None
    mission = scenario.mission_spec()
    sensor, noise = mission.record.sensor, spec.noise_covariance()
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(DETECTOR_STREAM,)))
    detector = Detector(sensor, noise, spec.false_alarm_density, rng)
    tracker = Tracker(
        mission.motion,
        sensor,
        noise,
        spec.false_alarm_density,
        spec.association,
        spec.confirmation,
        float(np.max(mission.process_noise)),
        new_track_covariance(noise, scenario.covariances()),
    )
    return detector, tracker


class World:
    """A simulated mission of ``scenario`` (true targets, agent, beliefs), advanced by
    `step`; after construction, step 0 (the first sensing) is done.

    Args:
        scenario: the mission.
        seed: overrides ``scenario.seed`` (as `hptrack.sim.episode.run_episode`).

    Attributes (read them, do not write them):
        mission: the mission facts.
        step_index: current step ``k``.
        agents: ``(m, 2)`` the vehicles' positions, m (the scenario's `Scenario.team`; a
            team's UAVs move at once, then look in turn, each by its own sensor, the first
            drawing first).
        agent: ``(2,)`` the first vehicle's position, m (a view of ``agents``).
        truth: ``(n, d)`` true target states (``d`` the truth motion's state size).
        truth_motion: how they move (`hptrack.models.truth_motion`; random parameters such
            as turn rates drawn after the initial states, from the same stream).
        means, covariances: ``(n, d)``, ``(n, d, d)`` beliefs (``d`` the beliefs' motion's).
        seen: ``(n,)`` which targets were measured at this step.
        logdets: ``(n,)`` per-target ``log det Sigma^xy``.
        uncertainty: ``U = sum(logdets)``.
        planner_seed: the planner's stream of the seed.
        associations: ``(m, 6)`` without identity, one row a report: step, x, y (m), its
            source (target index, -1 a false alarm), the belief it went to (-1 none) and the
            weight (`hptrack.models.tracking.TrackerLook`); ``None`` with identity.
        claims: ``(c, 3)`` without identity, one row a confirmed tentative track: step, the
            belief it re-initialised, the source of the report that confirmed it.
    """

    def __init__(self, scenario: Scenario, seed: int | None = None) -> None:
        seed = scenario.seed if seed is None else seed
        self.seed = int(seed)
        truth_seq, motion_seq, sensor_seq, self.planner_seed = np.random.SeedSequence(
            self.seed
        ).spawn(4)
        mission = scenario.mission_spec()
        self.mission: MissionSpec = mission
        n = mission.n_targets
        self.n_steps = mission.n_steps
        truth_rng = np.random.default_rng(truth_seq)
        self.truth = np.ascontiguousarray(initial_true_states(scenario, truth_rng))
        self.truth_motion = scenario.truth_motion_model(truth_rng)
        self.agents = scenario.starts()
        self.agent = self.agents[0]
        self._records = [mission.vehicle_mission(j).record for j in range(mission.n_vehicles)]
        self._factors = [
            np.linalg.cholesky(np.array(r.sensor.measurement_noise, dtype=float))
            for r in self._records
        ]
        self._seen_by = np.zeros(mission.n_targets, dtype=bool)
        self._held = [np.zeros((mission.n_targets, 2)) for _ in self._records]
        self.means = np.ascontiguousarray(scenario.means())
        self.covariances = np.ascontiguousarray(scenario.covariances())
        self.q = np.ascontiguousarray(mission.process_noise, dtype=float)
        self._sqrt_q = np.sqrt(self.q)
        self._truth_size = self.truth.shape[1]
        self._motion = NormalBlock(
            np.random.default_rng(motion_seq), BLOCK_STEPS * n * self._truth_size
        )
        self._sensor = NormalBlock(np.random.default_rng(sensor_seq), BLOCK_STEPS * n * 2)
        self._detection: UniformBlock | None = None
        self._no_draws = np.zeros(0)
        if draws_detection(mission.record.sensor):
            detection_seq = np.random.SeedSequence(self.seed, spawn_key=(DETECTION_STREAM,))
            self._detection = UniformBlock(np.random.default_rng(detection_seq), BLOCK_STEPS * n)
        self._waypoint = np.empty(2)
        self._z = np.empty(2)
        self.seen = np.zeros(n, dtype=bool)
        self.logdets = np.empty(n)
        self.step_index = 0
        self._unlabelled = unlabelled_parts(scenario, self.seed)
        self._rows: list[np.ndarray] = []
        self._claims: list[tuple[int, int, int]] = []
        self._sense()

    @property
    def n_targets(self) -> int:
        return self.truth.shape[0]

    @property
    def time(self) -> float:
        """Elapsed time, s."""
        return self.step_index * self.mission.time_step

    @property
    def remaining_budget(self) -> float:
        """Budget left, s."""
        return self.mission.budget - self.time

    @property
    def done(self) -> bool:
        """The budget is spent."""
        return self.step_index >= self.n_steps

    def _uniforms(self) -> tuple[np.ndarray, int]:
        """The detection uniforms and their position (at least ``n`` unused), or none."""
        block = self._detection
        if block is None:
            return self._no_draws, 0
        block.ensure(self.n_targets)
        return block.values, block.pos

    def _used(self, u_pos: int) -> None:
        if self._detection is not None:
            self._detection.pos = u_pos

    def _track(self) -> None:
        """Sense without identity: the detector's reports, the tracker's beliefs."""
        assert self._unlabelled is not None
        detector, tracker = self._unlabelled
        self.seen[:] = False
        k = self.step_index
        for j, agent in enumerate(self.agents):  # a team's UAVs in turn, in the same step
            reports = detector.look(agent, positions(self.truth))
            look = tracker.look(
                agent, self.means, self.covariances, reports.positions, new_step=j == 0
            )
            self.seen |= look.seen
            self._rows.append(
                np.column_stack(
                    [np.full(len(look.weight), k), reports.positions, reports.sources]
                    + [look.belief_of, look.weight]
                )
            )
            self._claims += [(k, c.belief, int(reports.sources[c.detection])) for c in look.claims]
        self.logdets[:] = position_logdet(self.covariances)
        self.uncertainty = float(np.sum(self.logdets))

    @property
    def associations(self) -> np.ndarray | None:
        if self._unlabelled is None:
            return None
        return np.concatenate([np.empty((0, 6)), *self._rows])

    @property
    def claims(self) -> np.ndarray | None:
        if self._unlabelled is None:
            return None
        return np.array(self._claims, dtype=float).reshape(-1, 3)

    def _sense(self) -> None:
        if self._unlabelled is not None:
            self._track()
            return
        self._look(0, self.seen)
        self._team_looks()

    def _look(self, j: int, seen: np.ndarray) -> None:
        """UAV ``j``'s look by its own sensor, into ``seen``."""
        n = self.n_targets
        self._sensor.ensure(2 * n)
        u, u_pos = self._uniforms()
        self._sensor.pos, self.uncertainty, u_pos = sense(
            self._records[j].sensor,
            self.agents[j],
            self.truth,
            self.means,
            self.covariances,
            self._factors[j],
            self._sensor.values,
            self._sensor.pos,
            seen,
            self.logdets,
            self._z,
            u,
            u_pos,
            self._held[j],
        )
        self._used(u_pos)

    def _team_looks(self) -> None:
        """The looks of a team's UAVs after the first, in order (``seen``: by any)."""
        for j in range(1, self.agents.shape[0]):
            self._look(j, self._seen_by)
            self.seen |= self._seen_by

    def step_team(self, waypoints: np.ndarray) -> float:
        """Advance one step with each UAV flying towards its row of ``waypoints`` ``(m, 2)``
        m; returns ``U`` after it.

        Raises:
            RuntimeError: the budget is already spent.
        """
        for j in range(1, self.agents.shape[0]):
            if self.step_index < self.n_steps:
                move_vehicle(self._records[j], self.agents[j], np.asarray(waypoints[j], float))
        return self.step(float(waypoints[0][0]), float(waypoints[0][1]))

    def step(self, waypoint_x: float, waypoint_y: float) -> float:
        """Advance one step with the (first) UAV flying towards ``(waypoint_x, waypoint_y)``
        m (a team's others moved by `step_team`); returns ``U`` after it.

        Raises:
            RuntimeError: the budget is already spent.
        """
        if self.step_index >= self.n_steps:
            raise RuntimeError("the mission's budget is spent; start a new World")
        n = self.n_targets
        motion, sensor = self._motion, self._sensor
        d = self._truth_size
        motion.ensure(d * n)
        sensor.ensure(2 * n)
        z = motion.values[motion.pos : motion.pos + d * n].reshape(n, d)
        motion.pos += d * n
        wp = self._waypoint
        wp[0] = waypoint_x
        wp[1] = waypoint_y
        if self._unlabelled is not None:
            world_advance(
                self.mission.record, self.agent, wp, self.truth_motion, self.truth, z,
                self._sqrt_q, self.means, self.covariances,
            )  # fmt: skip
            self.step_index += 1
            self._track()
            return self.uncertainty
        u, u_pos = self._uniforms()
        sensor.pos, self.uncertainty, u_pos = world_step(
            self.mission.record,
            self.agent,
            wp,
            self.truth_motion,
            self.truth,
            z,
            self._sqrt_q,
            self.means,
            self.covariances,
            self._factors[0],
            sensor.values,
            sensor.pos,
            (self.seen, self.logdets, self._z, self._held[0]),
            u,
            u_pos,
        )
        self._used(u_pos)
        self._team_looks()
        self.step_index += 1
        return self.uncertainty

    def observation(self) -> Observation:
        """What a planner sees now (read-only copies)."""
        arrays = [self.agents.copy(), self.means.copy(), self.covariances.copy(), self.seen.copy()]
        for a in arrays:
            a.flags.writeable = False
        return Observation(self.step_index, self.time, self.remaining_budget, *arrays)
