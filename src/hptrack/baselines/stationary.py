"""The ``stationary`` reference planner: the agent stays where it starts (the floor of floors)."""

from __future__ import annotations

import numpy as np

from hptrack.interface import CurrentPlan, MissionSpec, Observation, one_vehicle
from hptrack.settings import NoSettings


class StationaryPlanner:
    """Hovers at the start position for the whole mission."""

    name = "stationary"

    def __init__(self, settings: NoSettings | None = None) -> None:
        self.settings = settings or NoSettings()

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        one_vehicle(self.name, mission)
        self._home = observation.agent_position.copy()

    def act(self, observation: Observation) -> np.ndarray:
        return self._home

    def current_plan(self) -> CurrentPlan:
        """No sub-tasks: nothing to show."""
        return CurrentPlan()

    def episode_info(self) -> dict:
        return {"settings": self.settings.as_json()}
