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
  just found. An infeasible action (including a padding slot ``i >= n``) hovers one step.
  `SubtaskTrackingEnv.action_masks` and ``info["action_mask"]`` give the feasible ones.
  Unlike the tree search, a target missed earlier may be chosen again.

Observation: `hptrack.envs.observation`, as ``Tracking-v0``. Reward: ``-(change of U) / n``
over the sub-task. ``info`` as ``Tracking-v0`` plus ``action_mask`` and ``last_found``, and after
a step ``subtask``: ``target_index``, ``outcome`` (``"found"``; ``"missed"``: ``t_cutoff``
reached; ``"budget"``: the budget ended first; ``"followed"``; ``"infeasible"``), ``start_step``,
``end_step``, ``steps``, ``duration`` (s), and for a coverage its plan (``intercept_time``,
``t_cutoff``, ``p_find``, ``expected_time``, ``budget_limited``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from hptrack.coverage.subtask import CoverageSubtask
from hptrack.envs.tracking import MissionEnv, discrete_action
from hptrack.models.mission import intercept_steps_to, reachable_before_budget, steps_left
from hptrack.models.state import velocity_of


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

    def action_masks(self) -> np.ndarray:
        """``(n_slots,)`` bool: the feasible actions now (module docstring)."""
        w = self._world()
        m = w.mission
        mask = np.zeros(self.layout.n_slots, dtype=bool)
        if w.done:
            return mask
        left = steps_left(m.time_step, w.remaining_budget)
        for i in range(w.n_targets):
            mean = w.means[i]
            if math.hypot(*velocity_of(mean)) >= m.agent_speed:
                continue
            steps = intercept_steps_to(m.record, w.agent[0], w.agent[1], mean)
            mask[i] = reachable_before_budget(steps, left)
        if self.last_found is not None:
            mask[self.last_found] = True
        return mask

    def _info(self) -> dict[str, Any]:
        return {
            **super()._info(),
            "action_mask": self.action_masks(),
            "last_found": self.last_found,
        }

    def _follow(self, i: int) -> None:
        w = self._world()
        while not w.done:
            x, y = w.mission.motion.mean_positions(w.means[i], [w.mission.time_step])[0]
            self._advance(float(x), float(y))

    def _cover(self, i: int) -> tuple[str, dict]:
        w = self._world()
        observation = w.observation()
        subtask = CoverageSubtask.from_observation(observation, i, w.mission)
        while True:
            x, y = subtask.next_waypoint(observation)
            self._advance(float(x), float(y))
            observation = w.observation()
            if subtask.done(observation):
                break
        if subtask.found(observation):
            outcome = "found"
        else:
            outcome = "budget" if w.done else "missed"
        plan = subtask.summary()
        return outcome, {
            k: plan[k]
            for k in ("intercept_time", "t_cutoff", "p_find", "expected_time", "budget_limited")
        }

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        world = self._check_running()
        i = discrete_action(action, self.layout.n_slots)
        feasible = bool(self.action_masks()[i])
        before, start = world.uncertainty, world.step_index
        plan: dict = {}
        if not feasible:
            w = world.agent
            self._advance(float(w[0]), float(w[1]))
            outcome = "infeasible"
        elif i == self.last_found:
            self._follow(i)
            outcome = "followed"
        else:
            outcome, plan = self._cover(i)
        self.last_found = i if outcome == "found" else None
        steps = world.step_index - start
        reward = -(world.uncertainty - before) / world.n_targets
        info = self._info()
        info["subtask"] = {
            "target_index": i,
            "outcome": outcome,
            "start_step": start,
            "end_step": world.step_index,
            "steps": steps,
            "duration": steps * world.mission.time_step,
            **plan,
        }
        return self._observation(), float(reward), False, world.done, info
