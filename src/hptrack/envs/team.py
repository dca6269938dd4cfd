"""``hptrack/TeamTracking-v0``: the step-level tracking problem of a team of UAVs as a
Gymnasium environment, one centralised agent choosing every UAV's action.

One step is one simulator step of the team (`hptrack.sim.step.World.step_team`): every UAV
flies by its own action, then the UAVs look in turn, the first first (`docs/teams.md`, "The
simulator"). Random scenarios put ``team`` alike UAVs at the start of the one-UAV scenario of the
same seed (`hptrack.scenario.random.random_scenario`); ``reset(options={"scenario": ...})``
flies a team scenario of that size.

Actions, one row per UAV in the order of ``agents:``, each flown as `TrackingEnv`'s are
(`hptrack.envs.tracking.action_waypoint`, at that UAV's own speed):

* ``action_type="discrete"`` (default): ``MultiDiscrete([13] * team)``;
* ``action_type="box"``: ``Box(-1, 1, (team, 2))``.

Observation: ``Box`` ``(team * size,)``, the single UAV's observation vectors of the UAVs one
after the other: ``obs.reshape(team, size)[j]`` is UAV ``j``'s, from its own position
(`hptrack.envs.observation`: every target relative to it, the budget left, the mask), so that
one policy can be shared by the UAVs or the whole vector read at once (flat, as the common
learners take it). Reward and
``info`` as `TrackingEnv`'s (the team's ``U``), with ``agents`` ``(team, 2)`` m.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from hptrack.envs.tracking import HEADINGS, MissionEnv, action_waypoint
from hptrack.interface import InputError, shown
from hptrack.scenario.model import MAX_AGENTS

ACTION_TYPES = ("discrete", "box")


class TeamTrackingEnv(MissionEnv):
    """``hptrack/TeamTracking-v0`` (module docstring).

    Args:
        team: the UAVs, 2 to `MAX_AGENTS` (default 2).
        action_type: ``"discrete"`` (13 actions per UAV, default) or ``"box"``.
        **kwargs: `MissionEnv`'s.
    """

    def __init__(self, team: int = 2, action_type: str = "discrete", **kwargs: Any) -> None:
        if (
            isinstance(team, bool)
            or not isinstance(team, int | np.integer)
            or not 2 <= team <= MAX_AGENTS
        ):
            raise InputError(f"team must be an integer in 2..{MAX_AGENTS}, got {shown(team)}")
        if action_type not in ACTION_TYPES:
            raise InputError(f"action_type must be 'discrete' or 'box', got {action_type!r}")
        self.team_size = int(team)
        super().__init__(**kwargs)
        low, high = self.layout.bounds()
        self.observation_space = spaces.Box(
            np.tile(low, self.team_size), np.tile(high, self.team_size), dtype=np.float32
        )
        self.action_type = action_type
        self.action_space = (
            spaces.MultiDiscrete([len(HEADINGS)] * self.team_size)
            if action_type == "discrete"
            else spaces.Box(-1.0, 1.0, (self.team_size, 2), dtype=np.float32)
        )

    def waypoints(self, action: Any) -> np.ndarray:
        """Where ``action`` sends each UAV this step, ``(team, 2)`` m.

        Raises:
            ValueError: an action that is not one row per UAV, or a row outside its space.
        """
        w = self._world()
        try:
            rows = np.asarray(action)
        except (TypeError, ValueError):
            rows = np.empty(0)
        want = (self.team_size,) if self.action_type == "discrete" else (self.team_size, 2)
        if rows.shape != want:
            raise ValueError(f"action must have shape {want}, one row per UAV, got {shown(action)}")
        return np.array(
            [
                action_waypoint(
                    self.action_type,
                    rows[j],
                    w.agents[j],
                    w.mission.vehicle_mission(j).step_length,
                )
                for j in range(self.team_size)
            ]
        )

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        world = self._check_running()
        before = world.uncertainty
        world.step_team(self.waypoints(action))
        self._record()
        reward = -(world.uncertainty - before) / world.n_targets
        return self._observation(), float(reward), False, world.done, self._info()

    def _observation(self) -> np.ndarray:
        w = self._world()
        left = w.remaining_budget / w.mission.budget
        return np.concatenate(
            [self.layout.encode(agent, w.means, w.logdets, w.seen, left) for agent in w.agents]
        )

    def _info(self) -> dict[str, Any]:
        return {**super()._info(), "agents": self._world().agents.copy()}
