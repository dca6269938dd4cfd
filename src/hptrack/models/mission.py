"""The mission's constants as one compiled record, and the rules on it (paper Sec. III, V-A).

`Mission` is what every compiled kernel takes instead of loose constants: it is built and
validated once (`mission_record`, or `hptrack.interface.MissionSpec.record`). How the beliefs
assume the targets move is its ``motion`` part (`hptrack.models.belief_motion`: the paper's
constant velocity by default, with either form of Eq. (1)'s ``Q``), dispatched at compile time.

The world's parts are fields of the record, registered classes dispatched at compile time:
``sensor`` (`hptrack.models.sensor`) and ``vehicle`` (`hptrack.models.vehicle`).

The rules, one place each: `steps_left` (whole steps of a remaining budget, the same for
the mission's budget), `intercept_steps` (the whole steps of the flight to a belief mean, asked
of the sensor, the vehicle and the motion), `reachable_before_budget` (an intercept that ends
strictly before the budget), `MAX_TARGETS` (what one decision of the planner holds in memory).
The motion's kernels are offered here on the record (`predict_covariance_on`,
`position_covariance_on`, `mean_position_on`, ...), so that no layer above the models handles
the motion itself.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np
from numba import types
from numba.extending import overload

from hptrack.models import belief_motion as bm
from hptrack.models.belief_motion import ConstantVelocity, registered_motion
from hptrack.models.fence import FenceSpec
from hptrack.models.measurement import check_noise_covariance
from hptrack.models.motion import motion_noise_factors
from hptrack.models.riccati import riccati_table_of
from hptrack.models.sensor import (
    FootprintSensor,
    SensorPart,
    certain,
    detecting_sensor,
    footprint_radius,
    hold_looks_of,
    negative_information_sensor,
    sensor_measures,
)
from hptrack.models.vehicle import (
    FencedHolonomicVehicle,
    HolonomicVehicle,
    VehiclePart,
    vehicle_approach_step,
    vehicle_intercept_time,
    vehicle_open_space,
    vehicle_sees,
)

MAX_TARGETS = 256
"""Most targets of a mission. The search's action list takes any number (63 per ``int64``
word, `hptrack.planning.subtask_mdp.in_list`); the cap bounds what a decision holds: the memo,
24 bytes per target and budget step (11 MB at the paper's 1800 steps), and a state node's
action slots, 86 bytes each, one per action (22 KB per node at 256 targets). A scenario file
of 256 targets fits the file bounds (`hptrack.scenario.io.MAX_VALUES`)."""

STEP_TOLERANCE = 1e-9
"""The one slack of every whole-step rule, in steps: a time within this of ``k tau`` is step
``k`` (rounding ``t / tau`` down, as `steps_left` and the controller's clock do, or up, as an
intercept's whole steps do)."""


class Mission(NamedTuple):
    """The mission's constants, as the compiled kernels take them (SI units).

    Attributes:
        time_step: ``tau``, s.
        process_noise: ``(n,)`` per-target noise intensities ``q``, m^2/s^3.
        n_steps: whole steps in the budget ``N``.
        motion: how the beliefs assume the targets move, a registered part of
            `hptrack.models.belief_motion` (`ConstantVelocity` by default).
        sensor: the sensor part (`hptrack.models.sensor`; the paper's `FootprintSensor`:
            diameter ``w`` and ``R``; `DetectingFootprintSensor` when the detection
            probability is not 1).
        vehicle: the vehicle part (`hptrack.models.vehicle`; the paper's
            `HolonomicVehicle`: speed ``v_a`` and step length ``v_a tau``;
            `FencedHolonomicVehicle` when a fence is given).
        false_alarm_density: ``lambda``, the false detections a look reports per m^2 of its
            footprint (Poisson; 0, the paper's sensor, by default). The paper's planner does not
            use it; a search that models false finds does
            (`hptrack.coverage.false_finds`).
    """

    time_step: float
    process_noise: np.ndarray
    n_steps: int
    motion: tuple
    sensor: SensorPart
    vehicle: VehiclePart
    false_alarm_density: float = 0.0


def mission_record(
    time_step: float,
    budget: float,
    agent_speed: float,
    sensor_diameter: float,
    measurement_noise: np.ndarray,
    process_noise: np.ndarray,
    continuous_noise: bool = True,
    motion: tuple | None = None,
    detection_probability: float | Sequence = 1.0,
    fence: FenceSpec | None = None,
    negative_information: bool = False,
    detection_correlation_time: float = 0.0,
    false_alarm_density: float = 0.0,
) -> Mission:
    """The validated `Mission` (``continuous_noise``: the continuous form of ``Q``, else
    the paper's printed one; ``motion``: a registered belief motion, default constant velocity
    with that ``Q``; ``detection_probability``: a number or a table of rows ``[distance from the
    footprint's centre, m; Pd]``, `hptrack.models.sensor.detection_table`: 1, the default,
    gives the paper's `FootprintSensor`, anything else a `DetectingFootprintSensor`;
    ``fence``: where the vehicle may fly, `hptrack.models.fence`, a `FencedHolonomicVehicle`;
    ``negative_information``: a `NegativeInformationSensor` of that detector instead, whose
    looks that see nothing update the beliefs; ``detection_correlation_time``: s, how long a
    detector's draw holds while a target stays in the footprint, 0 for independent looks,
    `hptrack.models.sensor.hold_looks_of`; ``false_alarm_density``: false detections per m^2
    per look, `Mission.false_alarm_density`).

    Raises:
        ValueError: a constant not positive and finite, ``R`` not symmetric positive definite,
            a ``q`` negative or not finite, more than `MAX_TARGETS` targets, a bad detection
            probability, a false alarm density negative or not finite.
    """
    for name, value in (
        ("time_step", time_step),
        ("budget", budget),
        ("agent_speed", agent_speed),
        ("sensor_diameter", sensor_diameter),
    ):
        if isinstance(value, bool) or not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    noise = np.ascontiguousarray(check_noise_covariance(measurement_noise))
    q = np.ascontiguousarray(np.array(process_noise, dtype=float).reshape(-1))
    if not np.all(np.isfinite(q) & (q >= 0.0)):
        raise ValueError(f"process_noise must be finite and >= 0, got {q.tolist()}")
    if q.size > MAX_TARGETS:
        raise ValueError(f"at most {MAX_TARGETS} targets, got {q.size}")
    tau = float(time_step)
    if motion is None:
        motion = ConstantVelocity(tau if continuous_noise else 1.0)
    registered_motion(motion)
    noise.flags.writeable = False
    q.flags.writeable = False
    sensor: SensorPart = FootprintSensor(float(sensor_diameter), noise)
    try:
        certain_detection = certain(detection_probability)
    except ValueError as err:
        raise ValueError(f"detection_probability: {err}") from None
    if not isinstance(negative_information, bool):
        raise ValueError(
            f"negative_information must be true or false, got {negative_information!r}"
        )
    correlation = float(detection_correlation_time)
    if not (math.isfinite(correlation) and correlation >= 0.0):
        raise ValueError(f"detection_correlation_time must be >= 0 s, got {correlation!r}")
    if correlation > 0.0 and negative_information:
        raise ValueError("negative_information needs independent looks (correlation time 0)")
    clutter = float(false_alarm_density)
    if not (math.isfinite(clutter) and clutter >= 0.0):
        raise ValueError(f"false_alarm_density must be >= 0 per m^2, got {false_alarm_density!r}")
    step = float(agent_speed) * tau
    if negative_information:
        sensor = negative_information_sensor(
            float(sensor_diameter), noise, detection_probability, step
        )
    elif not certain_detection:
        hold = hold_looks_of(correlation, tau)
        sensor = detecting_sensor(float(sensor_diameter), noise, detection_probability, step, hold)
    return Mission(
        time_step=tau,
        process_noise=q,
        n_steps=steps_left(tau, float(budget)),
        motion=motion,
        sensor=sensor,
        vehicle=vehicle_part(float(agent_speed), tau, fence),
        false_alarm_density=clutter,
    )


def vehicle_part(speed: float, time_step: float, fence: FenceSpec | None) -> VehiclePart:
    """The vehicle part: the paper's `HolonomicVehicle` at ``speed`` (m/s), fenced by
    ``fence`` when one is given."""
    if fence is None:
        return HolonomicVehicle(speed, speed * time_step)
    return FencedHolonomicVehicle(speed, speed * time_step, fence.compiled())


@numba.njit(cache=True)
def steps_left(time_step, remaining_budget):
    """Whole steps of ``time_step`` s in ``remaining_budget`` s (the budget's ``N`` too)."""
    return int(math.floor(remaining_budget / time_step + STEP_TOLERANCE))


@numba.njit(cache=True, inline="always")
def reachable_before_budget(intercept_steps, left):
    """An intercept of ``intercept_steps`` (``-1``: never) ends strictly before the ``left``
    steps of the budget run out."""
    return 0 <= intercept_steps < left


@numba.njit(cache=True, inline="always")
def intercept_flight(mission, agent_x, agent_y, x, y, vx, vy):
    """The intercept flight from the agent at ``(agent_x, agent_y)`` to a belief mean at
    ``(x, y)`` m moving at ``(vx, vy)`` m/s, asked of the mission's sensor and vehicle:
    ``(t, n)``, the vehicle's exact intercept time ``t`` (s) and its whole steps
    ``n = ceil(t / tau)`` (less `STEP_TOLERANCE`); ``(0, 0)`` when the sensor already measures
    the mean, ``(inf, -1)`` when the vehicle cannot catch it (`hptrack.coverage.intercept` has
    the convention)."""
    if sensor_measures(mission.sensor, agent_x, agent_y, x, y):
        return 0.0, 0
    t = vehicle_intercept_time(mission.vehicle, agent_x, agent_y, x, y, vx, vy)
    if math.isinf(t):
        return t, -1
    return t, int(math.ceil(t / mission.time_step - STEP_TOLERANCE))


@numba.njit(cache=True, inline="always")
def intercept_steps(mission, agent_x, agent_y, x, y, vx, vy):
    """The whole steps ``n`` of `intercept_flight` (``0``: measured at once, ``-1``: never)."""
    return intercept_flight(mission, agent_x, agent_y, x, y, vx, vy)[1]


DOUBLINGS = 64
"""Most doublings of the bracket of an intercept of a curved mean path (`intercept_flight_on`)."""
BISECTION_ROUNDS = 200
"""Most halvings of that bracket; it stops earlier at machine precision."""


@numba.njit(cache=True, inline="always")
def _reaches(mission, agent_x, agent_y, mean, elapsed, s):
    """Whether the vehicle can be, ``s`` s from now, where the mean predicted ``elapsed + s``
    s ahead will be."""
    x, y = mean_position_on(mission, mean, elapsed + s)
    return vehicle_intercept_time(mission.vehicle, agent_x, agent_y, x, y, 0.0, 0.0) <= s


@numba.njit(cache=True)
def intercept_flight_on(mission, agent_x, agent_y, mean, elapsed):
    """`intercept_flight` to the belief mean ``mean`` (a state) predicted ``elapsed`` s ahead by
    the mission's motion, along its predicted path: the closed form when the mean moves
    straight; otherwise the earliest ``t`` at which the vehicle can be where the mean will be,
    by doubling and bisection (one root: the mean's speed stays below the vehicle's,
    `hptrack.models.belief_motion`)."""
    x, y, vx, vy = mean_state_on(mission, mean, elapsed)
    if moves_straight_on(mission):
        return intercept_flight(mission, agent_x, agent_y, x, y, vx, vy)
    if sensor_measures(mission.sensor, agent_x, agent_y, x, y):
        return 0.0, 0
    if math.isinf(vehicle_intercept_time(mission.vehicle, agent_x, agent_y, x, y, vx, vy)):
        return math.inf, -1
    lo, hi = 0.0, max(mission.time_step, 1e-9)
    for _ in range(DOUBLINGS):
        if _reaches(mission, agent_x, agent_y, mean, elapsed, hi):
            break
        lo, hi = hi, 2.0 * hi
    else:
        return math.inf, -1
    for _ in range(BISECTION_ROUNDS):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        if _reaches(mission, agent_x, agent_y, mean, elapsed, mid):
            hi = mid
        else:
            lo = mid
    return hi, int(math.ceil(hi / mission.time_step - STEP_TOLERANCE))


@numba.njit(cache=True)
def intercept_steps_to(mission, agent_x, agent_y, mean, elapsed=0.0):
    """The whole steps of `intercept_flight_on` to the belief mean ``mean`` (a state) predicted
    ``elapsed`` s ahead (``0``: measured at once, ``-1``: never)."""
    return intercept_flight_on(mission, agent_x, agent_y, mean, elapsed)[1]


@numba.njit(cache=True)
def approach_step_to(mission, agent_x, agent_y, mean, steps, elapsed=0.0):
    """The vehicle's displacement per step relative to the belief mean ``mean`` (a state)
    predicted ``elapsed`` s ahead, on an intercept flight of ``steps`` whole steps, m
    (`hptrack.models.vehicle`); along a curved mean path, relative to the mean's average
    velocity over the flight."""
    x, y, vx, vy = mean_state_on(mission, mean, elapsed)
    tau = mission.time_step
    if not moves_straight_on(mission) and steps > 0:
        ex, ey = mean_position_on(mission, mean, elapsed + steps * tau)
        vx, vy = (ex - x) / (steps * tau), (ey - y) / (steps * tau)
    return vehicle_approach_step(mission.vehicle, agent_x, agent_y, x, y, vx, vy, tau, steps)


QUADRATURE_RINGS = 12
"""Rings of equal probability of `visible_find`'s quadrature."""
QUADRATURE_ANGLES = 24
"""Points per ring of that quadrature (staggered between rings)."""


@numba.njit(cache=True)
def visible_find(mission, mean, elapsed, cov, q, p_find, cutoff_steps):
    """A coverage estimate's chance of a find ``p_find`` (within ``cutoff_steps`` of the
    spiral's start) less what the footprint cannot cover from where the vehicle may fly
    (exactly ``p_find`` in open space); ``mean`` (a state) is the belief's predicted
    ``elapsed`` s ahead to the spiral's start, ``cov`` its covariance there, ``q`` its noise.

    The spiral sweeps the belief's probability from its centre out, its ``P_cdf`` rising as
    ``1 - exp(-c t)`` for a sweep of constant area rate; so the ellipse holding mass ``u`` is
    swept at ``t_u = t_cutoff ln(1 - u) / ln(1 - p_find)``. A quadrature of equal weights,
    `QUADRATURE_RINGS` rings of equal mass steps ``u`` in ``(0, p_find)``, `QUADRATURE_ANGLES`
    points on each at the Mahalanobis radius ``sqrt(-2 ln(1 - u))`` of the belief predicted to
    the ring's time around its mean then, counts the share of points the vehicle's footprint can
    see (`hptrack.models.vehicle`); ``p_find`` times that share is returned. The time the
    spiral spends over what the footprint cannot see is not spent covering: the vehicle is held
    at the fence while the spiral is there, so each ring is reached later than ``t_u`` by the
    hidden share of the time of the rings before it (a ring's time: between its bounds of mass
    ``p_find k / R`` and ``p_find (k + 1) / R``), by when the belief has moved on relative to
    the fixed fence."""
    if vehicle_open_space(mission.vehicle) or p_find <= 0.0:
        return p_find
    tau = mission.time_step
    radius = footprint_radius(mission.sensor)
    top = min(p_find, 1.0 - 1e-12)
    scale = cutoff_steps / math.log(1.0 - top)
    seen = 0
    held = 0.0  # steps the spiral has spent over what the footprint cannot see
    for k in range(QUADRATURE_RINGS):
        u = p_find * (k + 0.5) / QUADRATURE_RINGS
        log_miss = math.log(1.0 - u)
        steps = scale * log_miss + held
        x, y = mean_position_on(mission, mean, elapsed + steps * tau)
        sxx, sxy, syy = position_covariance_on(mission, cov, q, steps)
        l11 = math.sqrt(sxx)
        l21 = sxy / l11
        l22 = math.sqrt(max(syy - l21 * l21, 0.0))
        r = math.sqrt(-2.0 * log_miss)
        ring_seen = 0
        for j in range(QUADRATURE_ANGLES):
            theta = 2.0 * math.pi * (j + 0.5 * (k % 2)) / QUADRATURE_ANGLES
            zx, zy = r * math.cos(theta), r * math.sin(theta)
            if vehicle_sees(mission.vehicle, x + l11 * zx, y + l21 * zx + l22 * zy, radius):
                ring_seen += 1
        seen += ring_seen
        lo = top * k / QUADRATURE_RINGS
        hi = top * (k + 1) / QUADRATURE_RINGS
        hidden = 1.0 - ring_seen / QUADRATURE_ANGLES
        held += hidden * scale * (math.log(1.0 - hi) - math.log(1.0 - lo))
    return p_find * (seen / (QUADRATURE_RINGS * QUADRATURE_ANGLES))


@numba.njit(cache=True, inline="always")
def predict_covariance_on(mission, cov, q, steps, out):
    """``out = F cov F' + Q`` over ``steps`` steps of the mission's motion (Eq. (1) for
    constant velocity); ``out`` may be ``cov``."""
    bm.predict_covariance(mission.motion, mission.time_step, cov, q, steps, out)


@numba.njit(cache=True, inline="always")
def position_covariance_on(mission, cov, q, steps):
    """``(sxx, sxy, syy)`` of the position covariance after ``steps`` steps, m^2."""
    return bm.position_covariance(mission.motion, mission.time_step, cov, q, steps)


@numba.njit(cache=True, inline="always")
def position_polynomials_on(mission, cov, q):
    """The motion's position terms of ``cov``, read by `position_det_on`: a tuple whose entries
    0, 3 and 6 are ``sxx``, ``syy``, ``sxy`` now (for constant velocity the polynomials of
    `hptrack.models.motion.position_polynomials`)."""
    return bm.position_terms(mission.motion, mission.time_step, cov, q)


@numba.njit(cache=True, inline="always")
def position_det_on(mission, poly, steps):
    """``det Sigma^xy`` (m^4) after ``steps`` steps from `position_polynomials_on`'s terms."""
    return bm.position_det(mission.motion, mission.time_step, poly, steps)


@numba.njit(cache=True, inline="always")
def position_det_rate_on(mission, poly, steps):
    """``(det Sigma^xy, d det / d steps)`` from `position_polynomials_on`'s terms."""
    return bm.position_det_rate(mission.motion, mission.time_step, poly, steps)


@numba.njit(cache=True, inline="always")
def mean_position_on(mission, mean, elapsed):
    """``(x, y)`` of the belief mean ``[x, y, vx, vy]`` predicted ``elapsed`` s ahead, m."""
    x, y, _, _ = bm.mean_state(mission.motion, mission.time_step, mean, elapsed)
    return x, y


@numba.njit(cache=True, inline="always")
def mean_state_on(mission, mean, elapsed):
    """``(x, y, vx, vy)``: the belief mean predicted ``elapsed`` s ahead."""
    return bm.mean_state(mission.motion, mission.time_step, mean, elapsed)


@numba.njit(cache=True, inline="always")
def predict_mean_on(mission, mean, elapsed, out):
    """The whole belief mean state predicted ``elapsed`` s ahead, written into ``out`` (which
    may be ``mean``)."""
    bm.predict_mean(mission.motion, mission.time_step, mean, elapsed, out)


@numba.njit(cache=True, inline="always")
def state_size_on(mission):
    """``d``, the length of a belief state under the mission's motion (a compile-time
    constant)."""
    return bm.state_size(mission.motion)


def state_size(mission: Mission) -> int:
    """``d``, the length of a belief state under the mission's motion (4 or 6)."""
    return registered_motion(mission.motion).state_size


@numba.njit(cache=True, inline="always")
def moves_straight_on(mission):
    """Whether the belief mean moves in a straight line at its velocity (constant velocity:
    then intercepts and spiral shifts have closed forms)."""
    return bm.moves_straight(mission.motion)


@numba.njit(cache=True)
def mission_moves_straight(mission):
    """`moves_straight_on` for Python callers."""
    return moves_straight_on(mission)


@numba.njit(cache=True)
def mean_position_at_on(mission, mean, elapsed):
    """`mean_position_on` for Python callers."""
    return mean_position_on(mission, mean, elapsed)


def _cv_velocity_variance(motion, tau):
    raise NotImplementedError


@overload(_cv_velocity_variance)
def _cv_velocity_variance_impl(motion, tau):
    if isinstance(motion, types.BaseNamedTuple) and motion.instance_class is ConstantVelocity:
        return lambda motion, tau: motion.velocity_variance_per_q
    return lambda motion, tau: tau


@numba.njit(cache=True, inline="always")
def motion_noise_factors_on(mission):
    """`hptrack.models.motion.motion_noise_factors` of the constant-velocity truth on the
    mission: its ``Q`` form when the beliefs assume constant velocity, else the continuous
    form."""
    return motion_noise_factors(
        mission.time_step, _cv_velocity_variance(mission.motion, mission.time_step)
    )


@numba.njit(cache=True)
def _step_matrices_on(mission, q, f, qq):
    bm.step_matrices(mission.motion, mission.time_step, q, f, qq)


class FollowTables(NamedTuple):
    """Every target's `riccati_table` (measured at every step),
    stacked: ``a``, ``g``, ``h`` ``(n, L, d, d)`` and ``length`` ``(n,)`` valid entries."""

    a: np.ndarray
    g: np.ndarray
    h: np.ndarray
    length: np.ndarray


def follow_tables(mission: Mission, max_steps: int | None = None) -> FollowTables:
    """The targets' Riccati tables up to ``max_steps`` (default the mission's ``N``): build
    them once per mission; a table holds for any shorter horizon."""
    steps = mission.n_steps if max_steps is None else int(max_steps)
    tables = []
    d = state_size(mission)
    for q in mission.process_noise:
        f, qq = np.empty((d, d)), np.empty((d, d))
        _step_matrices_on(mission, float(q), f, qq)
        tables.append(riccati_table_of(f, qq, mission.sensor.measurement_noise, steps))
    lengths = np.array([t[3] for t in tables], dtype=np.int64)
    top = int(lengths.max()) if lengths.size else 1
    stacked = [
        np.stack([t[k][:top] for t in tables]) if tables else np.zeros((0, 1, d, d))
        for k in range(3)
    ]
    return FollowTables(stacked[0], stacked[1], stacked[2], lengths)
