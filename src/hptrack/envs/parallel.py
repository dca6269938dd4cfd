"""The team's environment in PettingZoo's parallel API (optional extra ``hptrack[marl]``): one
agent per UAV, ``"uav_0"``, ``"uav_1"``, ..., in the order of ``agents:``.

`TeamParallelEnv` wraps `hptrack.envs.team.TeamTrackingEnv` and splits it by rows: UAV ``j``
observes its own row (the one-UAV observation vector from its position) and acts with its own
row of the team's action (``Discrete(13)`` or ``Box(-1, 1, (2,))``); every UAV gets the team's
reward (the team's ``U`` is one shared score) and the team's ``info``. The episode ends for every
UAV at once, by truncation at the budget's end, after which ``agents`` is empty (PettingZoo's
convention). The dynamics, the seeds and the numbers are the team environment's.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from hptrack.envs.team import TeamTrackingEnv
from hptrack.envs.tracking import HEADINGS, RESET_OPTIONS


class TeamParallelEnv(ParallelEnv):
    """A team of UAVs as PettingZoo agents (module docstring).

    Args:
        **kwargs: `TeamTrackingEnv`'s (``team``, ``action_type``, ``n_targets``, ...).
    """

    metadata = {"name": "hptrack_team_tracking_v0", "render_modes": ["rgb_array"]}

    def __init__(self, **kwargs: Any) -> None:
        self.team = TeamTrackingEnv(**kwargs)
        self.render_mode = self.team.render_mode
        self.possible_agents = [f"uav_{j}" for j in range(self.team.team_size)]
        self.agents: list[str] = []
        low, high = self.team.layout.bounds()
        self._observation_space = spaces.Box(low, high, dtype=np.float32)
        self._action_space = (
            spaces.Discrete(len(HEADINGS))
            if self.team.action_type == "discrete"
            else spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        )

    def observation_space(self, agent: str) -> spaces.Space:
        """Every UAV's observation space: the one-UAV vector."""
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Space:
        """Every UAV's action space: the one-UAV action."""
        return self._action_space

    def _split(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        rows = obs.reshape(len(self.possible_agents), -1)
        return {agent: rows[j] for j, agent in enumerate(self.possible_agents)}

    def reset(
        self, seed: int | None = None, options: dict | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict]]:
        """`TeamTrackingEnv.reset`, split by UAV. PettingZoo's API lets any ``options`` through:
        only the team environment's own (``scenario``, ``seed``) are passed on (and checked
        there), any other key is left out."""
        known = {k: v for k, v in (options or {}).items() if k in RESET_OPTIONS}
        obs, info = self.team.reset(seed=seed, options=known)
        self.agents = list(self.possible_agents)
        return self._split(obs), {agent: info for agent in self.agents}

    def step(self, actions: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One team step with every UAV's action (``actions`` names each UAV once).

        Raises:
            ValueError: an action missing for a UAV, or one for an agent not in the episode.
        """
        if sorted(actions) != sorted(self.agents):
            raise ValueError(
                f"actions must name every UAV of the episode once ({', '.join(self.agents)}), "
                f"got {', '.join(map(str, actions)) or 'none'}"
            )
        action = np.array([actions[agent] for agent in self.possible_agents])
        obs, reward, terminated, truncated, info = self.team.step(action)
        agents = self.agents
        if terminated or truncated:
            self.agents = []
        return (
            self._split(obs),
            {agent: reward for agent in agents},
            {agent: terminated for agent in agents},
            {agent: truncated for agent in agents},
            {agent: info for agent in agents},
        )

    def render(self) -> np.ndarray | None:
        """The team environment's mission figure (``render_mode="rgb_array"``)."""
        return self.team.render()

    def close(self) -> None:
        self.team.close()
