"""Interception of a moving belief mean (paper Sec. IV-C, "Node Expansion";
``docs/model.md``, "The coverage sub-task").

Before the shifting spiral of Sec. IV-A starts, the agent flies in a straight line at its full
speed ``v_a`` to the point where the belief mean, moving at the estimated velocity ``v_hat``, can
first be reached. With ``d = mean - agent`` the intercept time ``t`` is the smallest ``t >= 0`` with

    |d + v_hat t| = v_a t   <=>   (v_a^2 - |v_hat|^2) t^2 - 2 (d . v_hat) t - |d|^2 = 0,

whose only non-negative root exists for every ``d`` when ``|v_hat| < v_a``.

Under a belief motion whose mean does not move in a straight line (random walk,
Ornstein-Uhlenbeck: `hptrack.models.belief_motion`) the mean's path ``m(t)`` is the motion's
prediction, its speed never above ``|v_hat|``, so ``|m(t) - agent| - v_a t`` falls strictly
from ``|d|`` and is negative from ``|d| / (v_a - |v_hat|)`` on: its one root is found by
bisection on that bracket (`path_intercept_time`). The agent flies straight to ``m(n tau)``.

Time-step convention (shared by the sub-task, the tree search and the validation experiment):
the simulator moves in whole steps of ``tau``, so the intercept takes ``n = ceil(t / tau)`` steps
(with a 1e-9 slack against round-off). The agent flies straight at full speed towards the point
the mean reaches at step ``n``, ``mean + v_hat n tau``, which it can reach by then because
``|d + v_hat s| - v_a s`` decreases in ``s``; the last step may be shorter than ``v_a tau``.
The coverage starts at step ``n`` from the covariance propagated ``n`` steps. If the belief mean
already lies inside the sensor footprint (``|d| <= w/2``) the coverage starts at once: ``n = 0``
and the spiral is anchored at the agent's position (see `hptrack.coverage.subtask`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from hptrack.models.mission import (
    STEP_TOLERANCE,
    Mission,
    mean_position_on,
    mean_state_on,
    moves_straight_on,
)

BISECTION_ROUNDS = 200
"""Most halvings of the bracket of a curved intercept (`path_intercept_time`); it stops
earlier at machine precision."""


@numba.njit(cache=True)
def intercept_time(
    agent_x: float,
    agent_y: float,
    mean_x: float,
    mean_y: float,
    vel_x: float,
    vel_y: float,
    speed: float,
) -> float:
    """Smallest ``t >= 0`` (s) with ``|mean + vel t - agent| = speed t`` (closed form).

    Positions in m, velocities in m/s. Returns ``inf`` when ``|vel| >= speed`` (the target cannot
    be caught for sure; `plan_intercept` turns that into an error) and ``0`` when the agent
    is on the mean.
    """
    dx = mean_x - agent_x
    dy = mean_y - agent_y
    closing = speed * speed - (vel_x * vel_x + vel_y * vel_y)
    if closing <= 0.0:
        return math.inf
    dd = dx * dx + dy * dy
    if dd == 0.0:
        return 0.0
    dv = dx * vel_x + dy * vel_y
    root = math.sqrt(dv * dv + closing * dd)
    # Two algebraically equal forms of the positive root; each avoids cancellation on its side.
    if dv >= 0.0:
        return (dv + root) / closing
    return dd / (root - dv)


@numba.njit(cache=True)
def intercept_steps(
    agent_x: float,
    agent_y: float,
    mean_x: float,
    mean_y: float,
    vel_x: float,
    vel_y: float,
    speed: float,
    tau: float,
    footprint_radius: float,
) -> int:
    """Whole steps of the intercept flight (module docstring): ``ceil(t / tau)``, or ``0`` when
    the mean is within ``footprint_radius`` (m) of the agent. ``-1`` when ``|vel| >= speed``."""
    dx = mean_x - agent_x
    dy = mean_y - agent_y
    if dx * dx + dy * dy <= footprint_radius * footprint_radius:
        return 0
    t = intercept_time(agent_x, agent_y, mean_x, mean_y, vel_x, vel_y, speed)
    if math.isinf(t):
        return -1
    return int(math.ceil(t / tau - STEP_TOLERANCE))


@numba.njit(cache=True)
def approach_step(
    agent_x: float,
    agent_y: float,
    mean_x: float,
    mean_y: float,
    vel_x: float,
    vel_y: float,
    speed: float,
    tau: float,
    steps: int,
) -> tuple:
    """The agent's displacement per step relative to the belief mean during an intercept flight
    of ``steps`` whole steps (module docstring), m: ``v_a tau u - v_hat tau`` with ``u`` the unit
    vector towards the mean at step ``steps``. ``(0, 0)`` when ``steps <= 0``."""
    if steps <= 0:
        return 0.0, 0.0
    dx = mean_x + vel_x * steps * tau - agent_x
    dy = mean_y + vel_y * steps * tau - agent_y
    length = math.hypot(dx, dy)
    return speed * tau * dx / length - vel_x * tau, speed * tau * dy / length - vel_y * tau


@numba.njit(cache=True)
def path_intercept_time(mission, agent_x, agent_y, mean, elapsed):
    """Smallest ``t >= 0`` (s) with ``|m(elapsed + t) - agent| = v_a t`` for the mission's
    predicted mean path ``m`` of the belief mean ``mean`` ``(4,)`` (module docstring), by
    bisection; ``inf`` when the mean is not slower than the agent."""
    x, y, vx, vy = mean_state_on(mission, mean, elapsed)
    speed = mission.speed
    slack = speed - math.hypot(vx, vy)
    if slack <= 0.0:
        return math.inf
    distance = math.hypot(x - agent_x, y - agent_y)
    if distance == 0.0:
        return 0.0
    lo, hi = 0.0, distance / slack
    for _ in range(BISECTION_ROUNDS):
        mid = 0.5 * (lo + hi)
        if mid <= lo or mid >= hi:
            break
        mx, my = mean_position_on(mission, mean, elapsed + mid)
        if math.hypot(mx - agent_x, my - agent_y) > speed * mid:
            lo = mid
        else:
            hi = mid
    return hi


@numba.njit(cache=True)
def intercept_steps_on(mission, agent_x, agent_y, mean, elapsed):
    """`intercept_steps` for the belief mean ``mean`` ``(4,)`` predicted ``elapsed`` s ahead
    by the mission's motion (the closed form when it moves straight, else
    `path_intercept_time`)."""
    x, y, vx, vy = mean_state_on(mission, mean, elapsed)
    tau, radius = mission.time_step, mission.footprint_radius
    if moves_straight_on(mission):
        return intercept_steps(agent_x, agent_y, x, y, vx, vy, mission.speed, tau, radius)
    dx = x - agent_x
    dy = y - agent_y
    if dx * dx + dy * dy <= radius * radius:
        return 0
    t = path_intercept_time(mission, agent_x, agent_y, mean, elapsed)
    if math.isinf(t):
        return -1
    return int(math.ceil(t / tau - STEP_TOLERANCE))


@numba.njit(cache=True)
def approach_step_on(mission, agent_x, agent_y, mean, elapsed, steps):
    """`approach_step` for the belief mean ``mean`` predicted ``elapsed`` s ahead: the agent's
    mean displacement per step relative to the predicted mean over an intercept flight of
    ``steps`` steps, m (constant when the mean moves straight)."""
    x, y, vx, vy = mean_state_on(mission, mean, elapsed)
    tau = mission.time_step
    if moves_straight_on(mission):
        return approach_step(agent_x, agent_y, x, y, vx, vy, mission.speed, tau, steps)
    if steps <= 0:
        return 0.0, 0.0
    ex, ey = mean_position_on(mission, mean, elapsed + steps * tau)
    dx, dy = ex - agent_x, ey - agent_y
    length = math.hypot(dx, dy)
    step = mission.speed * tau
    return step * dx / length - (ex - x) / steps, step * dy / length - (ey - y) / steps


@dataclass(frozen=True, eq=False)
class Intercept:
    """A planned intercept flight.

    Attributes:
        time: exact intercept time ``t`` from the closed form, s.
        steps: whole steps of the flight ``n`` (module docstring).
        start: ``(2,)`` where the coverage starts, m (the mean at step ``n``, or the agent's
            position when the mean is already inside the footprint).
        time_step: ``tau``, s.
    """

    time: float
    steps: int
    start: np.ndarray
    time_step: float

    @property
    def duration(self) -> float:
        """Flight time in whole steps, ``n tau``, s."""
        return self.steps * self.time_step


def _finite_vector(name: str, value: np.ndarray | tuple[float, float]) -> np.ndarray:
    array = np.asarray(value, dtype=float)
    if array.shape != (2,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be two finite numbers, got {value!r}")
    return array


def plan_intercept(
    agent_position: np.ndarray,
    mean_position: np.ndarray,
    mean_velocity: np.ndarray,
    speed: float,
    time_step: float,
    sensor_diameter: float,
) -> Intercept:
    """Plan the intercept of a belief mean moving at ``mean_velocity`` (m/s) by an agent at
    ``agent_position`` (m) flying at ``speed`` (m/s), with the whole-step convention.

    Raises:
        ValueError: non-finite inputs, non-positive speed, time step or footprint, or a target
            whose estimated speed is not below the agent's.
    """
    agent = _finite_vector("agent_position", agent_position)
    mean = _finite_vector("mean_position", mean_position)
    velocity = _finite_vector("mean_velocity", mean_velocity)
    for name, value in (
        ("speed", speed),
        ("time_step", time_step),
        ("sensor_diameter", sensor_diameter),
    ):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    target_speed = float(np.hypot(*velocity))
    if target_speed >= speed:
        raise ValueError(
            f"the target's estimated speed {target_speed:g} m/s is not below the "
            f"agent speed {speed:g} m/s: the belief mean cannot be intercepted"
        )
    if np.hypot(*(mean - agent)) <= 0.5 * sensor_diameter:
        return Intercept(0.0, 0, agent, time_step)
    t = intercept_time(agent[0], agent[1], mean[0], mean[1], velocity[0], velocity[1], speed)
    steps = math.ceil(t / time_step - STEP_TOLERANCE)
    return Intercept(t, steps, mean + velocity * steps * time_step, time_step)


def plan_intercept_on(agent_position: np.ndarray, mean: np.ndarray, mission: Mission) -> Intercept:
    """`plan_intercept` of the belief mean ``mean`` ``(4,)`` moving by the ``mission``
    record's motion (the closed form when it moves straight).

    Raises:
        ValueError: as `plan_intercept`.
    """
    mean = np.asarray(mean, dtype=float)
    tau, diameter = mission.time_step, 2.0 * mission.footprint_radius
    if bool(_moves_straight(mission)):
        return plan_intercept(agent_position, mean[:2], mean[2:], mission.speed, tau, diameter)
    agent = _finite_vector("agent_position", agent_position)
    _finite_vector("mean_position", mean[:2])
    target_speed = float(np.hypot(*_finite_vector("mean_velocity", mean[2:])))
    if target_speed >= mission.speed:
        raise ValueError(
            f"the target's estimated speed {target_speed:g} m/s is not below the "
            f"agent speed {mission.speed:g} m/s: the belief mean cannot be intercepted"
        )
    if np.hypot(*(mean[:2] - agent)) <= mission.footprint_radius:
        return Intercept(0.0, 0, agent, tau)
    t = float(path_intercept_time(mission, agent[0], agent[1], mean, 0.0))
    steps = math.ceil(t / tau - STEP_TOLERANCE)
    start = np.array(_mean_position(mission, mean, steps * tau))
    return Intercept(t, steps, start, tau)


@numba.njit(cache=True)
def _moves_straight(mission):
    return moves_straight_on(mission)


@numba.njit(cache=True)
def _mean_position(mission, mean, elapsed):
    return mean_position_on(mission, mean, elapsed)


def intercept_path(
    agent_position: np.ndarray,
    intercept: Intercept,
    step_length: float,
    steps: np.ndarray | None = None,
) -> np.ndarray:
    """Agent positions ``(len(steps), 2)`` at the given steps (default ``0..n``) of the intercept
    flight: straight towards ``intercept.start`` at ``step_length`` (m) per step, the last step
    possibly shorter; from step ``n`` on the agent is at ``intercept.start``."""
    agent = np.asarray(agent_position, dtype=float)
    steps = np.arange(intercept.steps + 1) if steps is None else np.asarray(steps)
    delta = intercept.start - agent
    length = float(np.hypot(*delta))
    if length == 0.0:
        return np.repeat(agent[None, :], steps.shape[0], axis=0)
    travelled = np.minimum(steps * step_length, length)
    path = agent + travelled[:, None] * (delta / length)
    path[steps >= intercept.steps] = intercept.start  # exact arrival despite round-off
    return path


def intercept_waypoint(
    agent_position: np.ndarray, intercept: Intercept, step_length: float, step: int
) -> np.ndarray:
    """The agent's position ``(2,)`` at one ``step`` of the intercept flight (no allocation of
    the whole path, whatever its length)."""
    return intercept_path(agent_position, intercept, step_length, np.array([step]))[0]
