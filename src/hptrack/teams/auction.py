"""``team-cbba``: the allocation baseline of a team. The targets are allocated to the UAVs by
CBBA (`hptrack.planning.cbba`; Choi, Brunet and How, T-RO 2009), each UAV bidding the
estimator's expected gain of its path of pursuits (`hptrack.planning.team_value`), then every
UAV runs its own hierarchical search (`hptrack.planning.hierarchical`) over its bundle alone.

The auction runs at the start and every ``reallocate_period`` s; a UAV's current target is
committed to it (first in its bundle, never outbid), so a reallocation never takes a pursuit
from the UAV flying it. A bundle holds at most ``max_bundle`` targets (default ``ceil(n /
m)``, which lets the team cover every target). With ``drop_rate`` each of the auction's
messages (one UAV to another, one consensus round) is lost with that chance, by a draw of the
planner's generator; CBBA still ends conflict-free when it converges.
"""

from __future__ import annotations

import math
from typing import Annotated, ClassVar

import numpy as np
from pydantic import Field

from hptrack.interface import CurrentPlan, MissionSpec, Observation
from hptrack.planning.cbba import Allocation, cbba
from hptrack.planning.hierarchical import HierarchicalPlanner, MctsSettings
from hptrack.planning.team_value import team_path_value
from hptrack.teams.link import NO_CLAIM
from hptrack.teams.sequential import MAX_SHARE_PERIOD_S, TEAM_PRESET, claim_of, member_view

MAX_ROUNDS = 200
"""Most consensus rounds of one auction."""


class TeamCbbaSettings(MctsSettings):
    """Options of ``team-cbba``: every UAV's search (`MctsSettings`) and the auction's.

    Attributes:
        reallocate_period: s between two auctions (the first is at the start).
        max_bundle: most targets per UAV; ``None``: ``ceil(n / m)``.
        drop_rate: the chance that one message of the auction is lost; 0 by default.
    """

    reallocate_period: Annotated[float, Field(gt=0.0, le=MAX_SHARE_PERIOD_S)] = 30.0
    max_bundle: Annotated[int | None, Field(ge=1)] = None
    drop_rate: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.0
    default_preset: ClassVar[str | None] = TEAM_PRESET

    def member_settings(self) -> MctsSettings:
        """One UAV's search settings."""
        return MctsSettings.model_validate({k: getattr(self, k) for k in MctsSettings.model_fields})


class TeamCbbaPlanner:
    """CBBA, then one search per UAV over its bundle (module docstring)."""

    name = "team-cbba"

    def __init__(self, settings: TeamCbbaSettings | None = None) -> None:
        self.settings = settings or TeamCbbaSettings()
        self._member_settings = self.settings.member_settings()

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        m, n = mission.n_vehicles, mission.n_targets
        streams = rng.spawn(m + 1)
        self._mission, self._rng = mission, streams[m]
        self._every = max(1, math.floor(self.settings.reallocate_period / mission.time_step + 1e-9))
        self._bundle = self.settings.max_bundle or math.ceil(n / m)
        self._auctions: list[dict] = []
        self._members = [HierarchicalPlanner(self._member_settings) for _ in range(m)]
        self._allocate(observation, [None] * m)
        for j, member in enumerate(self._members):
            member.reset(mission.vehicle_mission(j), member_view(observation, j), streams[j])

    def _links(self, _round: int) -> np.ndarray:
        m = len(self._members)
        return self._rng.random((m, m)) >= self.settings.drop_rate

    def _allocate(self, observation: Observation, committed: list[int | None]) -> None:
        """Run an auction and hand each UAV the targets outside its bundle as claimed."""
        mission, m = self._mission, len(self._members)
        value = team_path_value(
            [mission.vehicle_mission(j) for j in range(m)],
            observation.agent_positions,
            observation.means,
            observation.covariances,
            observation.remaining_budget,
            self._member_settings.estimator or "paper",
            self._member_settings.coverage_limit or 0.0,
        )
        allocation: Allocation = cbba(
            m,
            mission.n_targets,
            value,
            self._bundle,
            links=self._links if self.settings.drop_rate > 0.0 else None,
            committed=committed,
            max_rounds=MAX_ROUNDS,
        )
        for j, member in enumerate(self._members):
            mine = np.zeros(mission.n_targets, dtype=bool)
            mine[list(allocation.paths[j])] = True
            member.claimed = ~mine
        self._auctions.append(
            {
                "step": observation.step,
                "committed": committed,
                "paths": [list(p) for p in allocation.paths],
                "rounds": allocation.rounds,
                "converged": allocation.converged,
            }
        )

    def act(self, observation: Observation) -> np.ndarray:
        if observation.step % self._every == 0 and observation.step != self._auctions[-1]["step"]:
            claims = self.claims()
            self._allocate(observation, [None if c == NO_CLAIM else int(c) for c in claims])
        out = np.empty((len(self._members), 2))
        for j, member in enumerate(self._members):
            out[j] = member.act(member_view(observation, j))
        return out

    def claims(self) -> np.ndarray:
        """``(m,)`` the target each UAV flies for now (`NO_CLAIM`: none)."""
        return np.array([claim_of(member) for member in self._members], dtype=np.int64)

    def current_plan(self) -> CurrentPlan:
        """The first UAV's (`current_plans` gives every UAV's)."""
        return self._members[0].current_plan()

    def current_plans(self) -> list[CurrentPlan]:
        """Every UAV's current plan, in order."""
        return [member.current_plan() for member in self._members]

    def episode_info(self) -> dict:
        """The settings, every UAV's own episode info (``members``) and every auction (its
        step, each UAV's committed target and path, its rounds, whether it converged)."""
        return {
            "settings": self.settings.as_json(),
            "members": [member.episode_info() for member in self._members],
            "auctions": self._auctions,
        }
