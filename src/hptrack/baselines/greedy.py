"""The ``greedy`` reference planner: chase the most uncertain reachable target, one at a time.

A simple, sensible policy without look-ahead, the floor every tree-search planner must beat:

1. Pick the target whose position uncertainty (``log det Sigma^xy``) would be largest when the
   agent reaches its belief mean, among the targets it can reach inside the remaining budget and
   has not given up on.
2. Fly straight at the target's current belief mean (pure pursuit at ``v_a``).
3. Once the target is measured, its uncertainty drops and step 1 picks the next one; with a
   single target it simply keeps following it.
4. If the agent reaches the belief mean without measuring the target, it gives up on it; when
   every target has been given up on, the list is cleared.

With a fence (`hptrack.models.fence`) the way to a mean is the shortest free flight to its
nearest free point (`approach_length`): the reach times of step 1 are its length over the
closing speed, and step 4 gives up once the agent is there (a mean inside a no-fly zone is never
reached). The waypoint stays the belief mean: the fenced vehicle flies the shortest free flight
towards it, which is pure pursuit around the zones.
"""

from __future__ import annotations

import numpy as np

from hptrack.interface import CurrentPlan, MissionSpec, Observation, one_vehicle
from hptrack.models.beliefs import position_logdet
from hptrack.models.fence import approach_length
from hptrack.models.state import positions, speeds
from hptrack.models.vehicle import FencedHolonomicVehicle
from hptrack.settings import NoSettings


class GreedyPlanner:
    """Most-uncertain-reachable-target pursuit (module docstring)."""

    name = "greedy"

    def __init__(self, settings: NoSettings | None = None) -> None:
        self.settings = settings or NoSettings()
        self.claimed: np.ndarray | None = None
        """``(n,)`` bool: targets another UAV of a team has claimed, never chosen while they
        are (set by a team planner, `hptrack.teams`); ``None``: none."""

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        one_vehicle(self.name, mission)
        self._mission = mission
        vehicle = mission.record.vehicle
        self._fence = vehicle.fence if isinstance(vehicle, FencedHolonomicVehicle) else None
        self._target: int | None = None
        self._given_up = np.zeros(mission.n_targets, dtype=bool)

    def _distances(self, obs: Observation) -> np.ndarray:
        """How far the agent flies to each belief mean now, m: straight, or with a fence the
        shortest free flight to the mean's nearest free point (module docstring)."""
        means = positions(obs.means)
        if self._fence is None:
            return np.hypot(*(means - obs.agent_position).T)
        return np.array([approach_length(self._fence, obs.agent_position, m) for m in means])

    def _reach_times(self, obs: Observation) -> np.ndarray:
        """Time to reach each belief mean flying at full speed (conservative), s."""
        closing = self._mission.agent_speed - speeds(obs.means)
        return self._distances(obs) / closing

    def _choose(self, obs: Observation) -> int | None:
        if self.claimed is not None and self.claimed.all():
            return None  # a team's other UAVs hold every target
        reach = self._reach_times(obs)
        free = True if self.claimed is None else ~self.claimed
        candidates = (~self._given_up) & (reach <= obs.remaining_budget) & free
        if not candidates.any():
            self._given_up[:] = False
            candidates = (reach <= obs.remaining_budget) & free
        if not candidates.any():
            return int(np.argmin(np.where(free, reach, np.inf)))
        predicted = self._mission.motion.predict(
            obs.means, obs.covariances, self._mission.process_noise, reach
        )[1]
        score = np.where(candidates, position_logdet(predicted), -np.inf)
        return int(np.argmax(score))

    def act(self, observation: Observation) -> np.ndarray:
        obs = observation
        if self._target is not None and obs.detected[self._target]:
            self._given_up[:] = False
            self._target = None
        if self._target is not None and self.claimed is not None and self.claimed[self._target]:
            self._target = None
        if self._target is not None:
            if self._fence is None:
                gap = np.hypot(*(positions(obs.means[self._target]) - obs.agent_position))
            else:
                gap = approach_length(self._fence, obs.agent_position, obs.means[self._target])
            if gap < self._mission.step_length:
                self._given_up[self._target] = True
                self._target = None
        if self._target is None:
            self._target = self._choose(obs)
        if self._target is None:
            return obs.agent_position.copy()
        return positions(obs.means[self._target]).copy()

    @property
    def target(self) -> int | None:
        """The target chased now (``None``: none)."""
        return self._target

    def current_plan(self) -> CurrentPlan:
        """No sub-tasks: nothing to show."""
        return CurrentPlan()

    def episode_info(self) -> dict:
        return {"settings": self.settings.as_json()}
