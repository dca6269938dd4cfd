"""The ``coverage`` planner: pursue one target with successive coverage sub-tasks, so that the
paper's sub-task (Sec. IV-A, IV-B) can be flown and studied on its own."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field

from hptrack.coverage.subtask import CoverageSubtask
from hptrack.interface import CurrentPlan, InputError, MissionSpec, Observation, Subtask
from hptrack.settings import PlannerSettings


class CoverageSettings(PlannerSettings):
    """Options of the ``coverage`` planner.

    Attributes:
        target: the pursued target's id (required).
    """

    target: Annotated[str, Field(min_length=1)]


class CoveragePlanner:
    """Pursue one target with coverage sub-tasks (name ``"coverage"``).

    While the target is measured the agent flies to its belief mean one step ahead (it keeps
    seeing it); otherwise it runs a `CoverageSubtask`, planning
    a new one from the current belief when the last one was found or reached ``t_cutoff``
    without a detection.
    """

    name = "coverage"

    def __init__(self, settings: CoverageSettings) -> None:
        self.settings = settings

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        target = self.settings.target
        if target not in mission.target_ids:
            raise InputError(
                f"planner 'coverage': option target {target!r} is not a target of "
                f"the scenario; targets are {list(mission.target_ids)}"
            )
        self._index = mission.target_ids.index(target)
        self._mission = mission
        self._subtask: CoverageSubtask | None = None
        self._log: list[dict] = []

    def _close(self, observation: Observation, outcome: str) -> None:
        if self._subtask is not None:
            self._log[-1].update(outcome=outcome, end_step=observation.step)
            self._subtask = None

    def act(self, observation: Observation) -> np.ndarray:
        i = self._index
        if observation.detected[i]:
            self._close(observation, "found")
            return self._mission.motion.mean_positions(
                observation.means[i], [self._mission.time_step]
            )[0]
        if self._subtask is not None and self._subtask.done(observation):
            self._close(observation, "missed")
        if self._subtask is None:
            self._subtask = CoverageSubtask.from_observation(observation, i, self._mission)
            self._log.append(self._subtask.summary())
        return self._subtask.next_waypoint(observation)

    def current_plan(self) -> CurrentPlan:
        """The coverage sub-task being flown, if any."""
        sub = self._subtask
        if sub is None:
            return CurrentPlan()
        return CurrentPlan(Subtask("pursue", sub.target_index, sub.start_step, float(sub.p_find)))

    def episode_info(self) -> dict:
        """The sub-tasks flown, each with its plan and outcome, and the settings."""
        return {"settings": self.settings.as_json(), "subtasks": self._log}
