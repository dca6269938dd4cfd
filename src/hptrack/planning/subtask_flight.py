"""Flying one sub-task (paper Fig. 2, "execute sub-task"), and the rule of which sub-tasks can be
flown: the one execution and the one feasibility check that the hierarchical planner and the
sub-task environment share with the tree search's MDP.

`SubtaskFlight` flies a `hptrack.subtasks.SubtaskAction` step by step: a pursuit is the
coverage sub-task (`hptrack.coverage.subtask.CoverageSubtask`: intercept, then the shifting
spiral, until the target is measured, ``t_cutoff`` or the budget's end); a follow flies at the
target's predicted position to the end of the budget, a dwell the same for its length; a hover
stays where the vehicle is. `feasible` is the MDP's rule (`hptrack.planning.subtask_mdp.
subtask_feasible`) applied to an observation.
"""

from __future__ import annotations

import numpy as np

from hptrack.coverage.subtask import CoverageSubtask
from hptrack.interface import MissionSpec, Observation
from hptrack.models.mission import steps_left
from hptrack.planning.subtask_mdp import int_state, subtask_feasible
from hptrack.subtasks import ActionTable, Subtask, SubtaskAction


def feasible(
    table: ActionTable,
    index: int,
    mission: MissionSpec,
    observation: Observation,
    available: np.ndarray,
    last_found: int | None,
) -> bool:
    """Whether action ``index`` of ``table`` can be flown from ``observation``: the MDP's rule
    (`subtask_feasible`) with the targets ``available`` (``(n,)`` bool: the action list) and
    the target just found ``last_found``."""
    agent = observation.agent_position
    left = steps_left(mission.time_step, observation.remaining_budget)
    si = int_state(0, np.asarray(available, dtype=bool), -1 if last_found is None else last_found)
    return bool(
        subtask_feasible(
            mission.record,
            np.ascontiguousarray(observation.means),
            np.array(table.stay_steps, dtype=np.int64),
            int(index),
            si,
            float(agent[0]),
            float(agent[1]),
            0.0,
            left,
        )
    )


class SubtaskFlight:
    """One sub-task in flight, from the observation it starts at.

    Args:
        action: what to fly (a dwell's ``parameter`` is its length in steps).
        observation: the observation it starts from.
        mission: the mission facts.
        coverage_steps: a pursuit's longest spiral, steps (the MDP's ``coverage_steps``);
            ``None`` (the paper): ``t_cutoff`` alone.

    Attributes:
        coverage: a pursuit's coverage sub-task (its plan and estimate), else ``None``.
        record: the sub-task's record (a pursuit's with its estimate), to log.
    """

    def __init__(
        self,
        action: SubtaskAction,
        observation: Observation,
        mission: MissionSpec,
        coverage_steps: int | None = None,
    ) -> None:
        self.action = action
        self.mission = mission
        self.start_step = observation.step
        self.coverage: CoverageSubtask | None = None
        if action.kind == "pursue":
            assert action.target is not None  # a pursuit has a target
            self.coverage = CoverageSubtask.from_observation(
                observation, action.target, mission, coverage_steps
            )
            self.record = self.coverage.record()
        else:
            self.record = Subtask(action.kind, action.target, self.start_step, action.parameter)

    @property
    def end_step(self) -> int | None:
        """The step it ends at at the latest (a pursuit without a find, a dwell); ``None``:
        the end of the budget."""
        if self.coverage is not None:
            return self.coverage.end_step
        if self.action.kind == "dwell":
            return self.start_step + int(self.action.parameter or 0)
        return None

    def waypoint(self, observation: Observation) -> np.ndarray:
        """Where to fly for the step after ``observation``, m."""
        if self.coverage is not None:
            return self.coverage.next_waypoint(observation)
        if self.action.target is None:
            return observation.agent_position
        tau = self.mission.time_step
        return self.mission.motion.mean_positions(observation.means[self.action.target], [tau])[0]

    def found(self, observation: Observation) -> bool:
        """Whether a pursuit's target is measured at ``observation``."""
        return self.coverage is not None and self.coverage.found(observation)

    def done(self, observation: Observation) -> bool:
        """A pursuit: found, ``t_cutoff`` reached or the budget spent; a dwell: its length
        flown; a follow or hover: the budget spent."""
        if self.coverage is not None:
            return self.coverage.done(observation)
        end = self.end_step
        return (end is not None and observation.step >= end) or observation.remaining_budget <= 0
