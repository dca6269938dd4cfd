"""The mission's constants as one compiled record, and the rules on it (paper Sec. III, V-A).

`Mission` is what every compiled kernel takes instead of loose constants: it is built and
validated once (`mission_record`, or `hptrack.interface.MissionSpec.record`). The
per-step process noise of Eq. (1) enters the kernels through ``q`` and
`Mission.velocity_variance_per_q`, the lower-right (velocity) block of the per-step ``Q``
divided by ``q``: ``tau`` for the continuous white-noise-acceleration form, ``1`` for the
paper's printed form (`hptrack.models.motion`).

The world's parts are fields of the record, registered classes dispatched at compile time:
``sensor`` (`hptrack.models.sensor`) and ``vehicle`` (`hptrack.models.vehicle`).

The rules, one place each: `steps_left` (whole steps of a remaining budget, the same for
the mission's budget), `intercept_steps` (the whole steps of the flight to a belief mean, asked
of the sensor and the vehicle), `reachable_before_budget` (an intercept that ends strictly
before the budget), `MAX_TARGETS` (the planner's action list is an ``int64`` bitmask). The kernels
of `hptrack.models.motion` and `hptrack.models.riccati` that need the noise form are
offered here on the record (`predict_covariance_on`, `position_covariance_on`, ...),
so that no layer above the models handles it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from hptrack.models.measurement import check_noise_covariance
from hptrack.models.motion import (
    motion_noise_factors,
    position_covariance_after,
    position_polynomials,
    predict_covariance,
)
from hptrack.models.riccati import riccati_table
from hptrack.models.sensor import FootprintSensor, SensorPart, sensor_measures
from hptrack.models.state import position_of, velocity_of
from hptrack.models.vehicle import (
    HolonomicVehicle,
    VehiclePart,
    vehicle_approach_step,
    vehicle_intercept_time,
)

MAX_TARGETS = 62
"""Most targets of a mission: the planner's action list is an ``int64`` bitmask."""

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
        velocity_variance_per_q: the velocity block of the per-step ``Q`` over ``q``, s
            (``tau``, continuous form) or 1 (the paper's printed form).
        sensor: the sensor part (`hptrack.models.sensor`; the paper's `FootprintSensor`:
            diameter ``w`` and ``R``).
        vehicle: the vehicle part (`hptrack.models.vehicle`; the paper's
            `HolonomicVehicle`: speed ``v_a`` and step length ``v_a tau``).
    """

    time_step: float
    process_noise: np.ndarray
    n_steps: int
    velocity_variance_per_q: float
    sensor: SensorPart
    vehicle: VehiclePart


def mission_record(
    time_step: float,
    budget: float,
    agent_speed: float,
    sensor_diameter: float,
    measurement_noise: np.ndarray,
    process_noise: np.ndarray,
    continuous_noise: bool = True,
) -> Mission:
    """The validated `Mission` (``continuous_noise``: the continuous form of ``Q``, else
    the paper's printed one).

    Raises:
        ValueError: a constant not positive and finite, ``R`` not symmetric positive definite,
            a ``q`` negative or not finite, more than `MAX_TARGETS` targets.
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
    noise.flags.writeable = False
    q.flags.writeable = False
    tau = float(time_step)
    return Mission(
        time_step=tau,
        process_noise=q,
        n_steps=steps_left(tau, float(budget)),
        velocity_variance_per_q=tau if continuous_noise else 1.0,
        sensor=FootprintSensor(float(sensor_diameter), noise),
        vehicle=HolonomicVehicle(float(agent_speed), float(agent_speed) * tau),
    )


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


@numba.njit(cache=True)
def intercept_steps_to(mission, agent_x, agent_y, mean):
    """`intercept_steps` to the belief mean ``mean`` (a state, `hptrack.models.state`)."""
    x, y = position_of(mean)
    vx, vy = velocity_of(mean)
    return intercept_steps(mission, agent_x, agent_y, x, y, vx, vy)


@numba.njit(cache=True)
def approach_step_to(mission, agent_x, agent_y, mean, steps):
    """The vehicle's displacement per step relative to the belief mean ``mean`` (a state) on an
    intercept flight of ``steps`` whole steps, m (`hptrack.models.vehicle`)."""
    x, y = position_of(mean)
    vx, vy = velocity_of(mean)
    return vehicle_approach_step(
        mission.vehicle, agent_x, agent_y, x, y, vx, vy, mission.time_step, steps
    )


@numba.njit(cache=True, inline="always")
def predict_covariance_on(mission, cov, q, steps, out):
    """`hptrack.models.motion.predict_covariance` with the mission's ``tau`` and ``Q``."""
    predict_covariance(cov, q, steps, mission.time_step, mission.velocity_variance_per_q, out)


@numba.njit(cache=True, inline="always")
def position_covariance_on(mission, cov, q, steps):
    """`hptrack.models.motion.position_covariance_after` on the mission."""
    return position_covariance_after(
        cov, q, steps, mission.time_step, mission.velocity_variance_per_q
    )


@numba.njit(cache=True, inline="always")
def position_polynomials_on(mission, cov, q):
    """`hptrack.models.motion.position_polynomials` on the mission."""
    return position_polynomials(cov, q, mission.time_step, mission.velocity_variance_per_q)


@numba.njit(cache=True, inline="always")
def motion_noise_factors_on(mission):
    """`hptrack.models.motion.motion_noise_factors` on the mission."""
    return motion_noise_factors(mission.time_step, mission.velocity_variance_per_q)


class FollowTables(NamedTuple):
    """Every target's `riccati_table` (measured at every step),
    stacked: ``a``, ``g``, ``h`` ``(n, L, 4, 4)`` and ``length`` ``(n,)`` valid entries."""

    a: np.ndarray
    g: np.ndarray
    h: np.ndarray
    length: np.ndarray


def follow_tables(mission: Mission, max_steps: int | None = None) -> FollowTables:
    """The targets' Riccati tables up to ``max_steps`` (default the mission's ``N``): build
    them once per mission; a table holds for any shorter horizon."""
    steps = mission.n_steps if max_steps is None else int(max_steps)
    tables = [
        riccati_table(
            float(q),
            mission.time_step,
            mission.velocity_variance_per_q,
            mission.sensor.measurement_noise,
            steps,
        )
        for q in mission.process_noise
    ]
    lengths = np.array([t[3] for t in tables], dtype=np.int64)
    top = int(lengths.max()) if lengths.size else 1
    stacked = [
        np.stack([t[k][:top] for t in tables]) if tables else np.zeros((0, 1, 4, 4))
        for k in range(3)
    ]
    return FollowTables(stacked[0], stacked[1], stacked[2], lengths)
