"""Interception of a moving belief mean (paper Sec. IV-C, "Node Expansion";
``docs/model.md``, "The coverage sub-task").

Before the shifting spiral of Sec. IV-A starts, the agent flies in a straight line at its full
speed ``v_a`` to the point where the belief mean, moving at the estimated velocity ``v_hat``, can
first be reached. With ``d = mean - agent`` the intercept time ``t`` is the smallest ``t >= 0`` with

    |d + v_hat t| = v_a t   <=>   (v_a^2 - |v_hat|^2) t^2 - 2 (d . v_hat) t - |d|^2 = 0,

whose only non-negative root exists for every ``d`` when ``|v_hat| < v_a``.

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

from hptrack.models.mission import STEP_TOLERANCE


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
