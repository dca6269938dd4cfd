"""Interception of a moving belief mean (paper Sec. IV-C, "Node Expansion";
``docs/model.md``, "The coverage sub-task").

Before the shifting spiral of Sec. IV-A starts, the agent flies in a straight line at its full
speed ``v_a`` to the point where the belief mean, moving at the estimated velocity ``v_hat``, can
first be reached: the mission's vehicle answers when (`hptrack.models.vehicle`, the closed form
of the holonomic point) and the mission record turns it into whole steps
(`hptrack.models.mission.intercept_flight`); this module plans the flight from it.

Under a belief motion whose mean does not move in a straight line (random walk,
Ornstein-Uhlenbeck: `hptrack.models.belief_motion`) the mean's path ``m(t)`` is the motion's
prediction, its speed never above ``|v_hat|``: the intercept is the earliest ``t`` at which the
vehicle can be at ``m(t)``, one root found by doubling and bisection
(`hptrack.models.mission.intercept_flight_on`), and the agent flies straight to ``m(n tau)``.

Time-step convention (shared by the sub-task, the tree search and the validation experiment):
the simulator moves in whole steps of ``tau``, so the intercept takes ``n = ceil(t / tau)`` steps
(with a 1e-9 slack against round-off). The agent flies straight at full speed towards the point
the mean reaches at step ``n``, ``mean + v_hat n tau``, which it can reach by then because
``|d + v_hat s| - v_a s`` decreases in ``s``; the last step may be shorter than ``v_a tau``.
The coverage starts at step ``n`` from the covariance propagated ``n`` steps. If the belief mean
already lies inside the sensor footprint (``|d| <= w/2``) the coverage starts at once: ``n = 0``
and the spiral is anchored at the agent's position (see `hptrack.coverage.subtask`): the
mission's sensor decides (`hptrack.models.sensor`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hptrack.models.mission import (
    Mission,
    intercept_flight,
    intercept_flight_on,
    mean_position_at_on,
    mission_moves_straight,
    state_size,
)
from hptrack.models.state import position_of, speeds, velocity_of


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


def plan_intercept(mission: Mission, agent_position: np.ndarray, mean: np.ndarray) -> Intercept:
    """Plan the intercept of the belief mean ``mean`` (a state ``[x, y, vx, vy]``, m and m/s)
    by the mission's vehicle from ``agent_position`` (m), with the whole-step convention.

    Raises:
        ValueError: non-finite inputs, or a target the vehicle cannot catch (its estimated
            speed not below the agent's).
    """
    agent = _finite_vector("agent_position", agent_position)
    state = np.asarray(mean, dtype=float)
    d = state_size(mission)
    if state.shape != (d,) or not np.all(np.isfinite(state)):
        raise ValueError(f"mean must be {d} finite numbers (a state), got {mean!r}")
    x, y = position_of(state)
    vx, vy = velocity_of(state)
    if mission_moves_straight(mission):
        t, steps = intercept_flight(mission, agent[0], agent[1], x, y, vx, vy)
    else:
        t, steps = intercept_flight_on(mission, agent[0], agent[1], state, 0.0)
    if steps < 0:
        raise ValueError(
            f"the target's estimated speed {float(speeds(state)):g} m/s is not below the "
            f"agent speed {mission.vehicle.speed:g} m/s: the belief mean cannot be intercepted"
        )
    if steps == 0:
        return Intercept(0.0, 0, agent, mission.time_step)
    if mission_moves_straight(mission):
        reached = np.array([x + vx * steps * mission.time_step, y + vy * steps * mission.time_step])
    else:
        reached = np.array(mean_position_at_on(mission, state, steps * mission.time_step))
    return Intercept(t, steps, reached, mission.time_step)


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
