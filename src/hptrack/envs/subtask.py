"""``hptrack/SubtaskTracking-v0``: the tracking problem at the paper's decision level.

An action is "pursue target ``i``" (paper Sec. IV-C): inside one ``step`` the agent flies the
coverage sub-task of `CoverageSubtask`, the intercept of the
belief mean and then the shifting spiral, until the target is measured, ``t_cutoff`` is reached
or the budget ends, on the simulator's step physics (`hptrack.sim.step.World`). The
hierarchical planner's tree search decides over the same actions, so learned agents and the
search can be compared on the same decisions.

Rules (those of the tree search's sub-task MDP, `hptrack.planning.subtask_mdp`):

* choosing the target that the previous sub-task just found follows it (flying at its predicted
  position every step) to the end of the budget;
* action ``i`` is *feasible* when the agent can reach target ``i``'s belief mean before the
  budget ends (``0 <= n_i < steps left``, ``n_i`` the intercept steps) or ``i`` is the target
  just found (the search's rule, `hptrack.planning.subtask_flight.feasible`; the sub-task is
  flown by `hptrack.planning.subtask_flight.SubtaskFlight`, as the planner flies it). An
  infeasible action (including a padding slot ``i >= n``) hovers one step.
  `SubtaskTrackingEnv.action_masks` and ``info["action_mask"]`` give the feasible ones.
  Unlike the tree search, a target missed earlier may be chosen again.

Observation: `hptrack.envs.observation`, as ``Tracking-v0``. Reward: ``-(change of U) / n``
over the sub-task. ``info`` as ``Tracking-v0`` plus ``action_mask`` and ``last_found``, and after
a step ``subtask``: the sub-task's record (`hptrack.subtasks.Subtask.to_json`: ``kind``
(``"pursue"``, ``"follow"``, ``"hover"`` for an infeasible action), ``target``,
``start_step``, ``end_step``, ``outcome`` (``"found"``; ``"missed"``: ``t_cutoff`` reached;
``"budget"``: the budget ended first; ``"followed"``; ``"infeasible"``), and for a pursuit its
plan: ``intercept_time``, ``t_cutoff``, ``p_find``, ``expected_time``, ``budget_limited``),
with ``action`` (the index chosen), ``steps`` and ``duration`` (s).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from hptrack.envs.tracking import MissionEnv, discrete_action
from hptrack.planning.subtask_flight import SubtaskFlight, feasible
from hptrack.subtasks import HOVER, ActionTable, Subtask, SubtaskAction


class SubtaskTrackingEnv(MissionEnv):
    """``hptrack/SubtaskTracking-v0`` (module docstring); arguments as
    `MissionEnv`. The action space is ``Discrete(n)``, or
    ``Discrete(max_targets)`` with padding."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.action_space = spaces.Discrete(self.layout.n_slots)
        self.last_found: int | None = None

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        self.last_found = None
        return super().reset(seed=seed, options=options)

    @property
    def _table(self) -> ActionTable:
        """The actions: one per target, no dwell."""
        return ActionTable(self._world().n_targets)

    def action_masks(self) -> np.ndarray:
        """``(n_slots,)`` bool: the feasible actions now (module docstring; the tree search's
        rule, `hptrack.planning.subtask_flight.feasible`, with every target in the action
        list)."""
        w = self._world()
        mask = np.zeros(self.layout.n_slots, dtype=bool)
        if w.done:
            return mask
        observation = w.observation()
        every = np.ones(w.n_targets, dtype=bool)
        for i in range(w.n_targets):
            mask[i] = feasible(self._table, i, w.mission, observation, every, self.last_found)
        return mask

    def _info(self) -> dict[str, Any]:
        return {
            **super()._info(),
            "action_mask": self.action_masks(),
            "last_found": self.last_found,
        }

    def _fly(self, action: SubtaskAction) -> tuple[Subtask, str]:
        """Fly ``action`` (`SubtaskFlight`) until it ends or the budget does; its record and
        outcome."""
        w = self._world()
        observation = w.observation()
        flight = SubtaskFlight(action, observation, w.mission)
        while True:
            x, y = flight.waypoint(observation)
            self._advance(float(x), float(y))
            observation = w.observation()
            if action.kind == "hover" or flight.done(observation) or w.done:
                break
        if action.kind == "hover":
            return flight.record, "infeasible"
        if action.kind == "follow":
            return flight.record, "followed"
        if flight.found(observation):
            return flight.record, "found"
        return flight.record, "budget" if w.done else "missed"

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        world = self._check_running()
        i = discrete_action(action, self.layout.n_slots)
        feasible_now = bool(self.action_masks()[i])
        before = world.uncertainty
        chosen = self._table.action(i, self.last_found) if feasible_now else None
        record, outcome = self._fly(chosen or HOVER)
        self.last_found = i if outcome == "found" else None
        steps = world.step_index - record.start_step
        reward = -(world.uncertainty - before) / world.n_targets
        info = self._info()
        info["subtask"] = {
            **record.ended(world.step_index, outcome).to_json(),
            "action": i,
            "steps": steps,
            "duration": steps * world.mission.time_step,
        }
        return self._observation(), float(reward), False, world.done, info
