"""Team planners that plan the UAVs one at a time (multiagent rollout over sub-tasks).

Every UAV runs its own planner of one UAV (``team-mcts``: the hierarchical planner,
`hptrack.planning.hierarchical`; ``team-greedy``: `hptrack.baselines.greedy`;
``team-clairvoyant``: the perfect-knowledge reference, `hptrack.baselines.clairvoyant`) on its
own mission and the shared beliefs. At each step the UAVs act in order; before a UAV acts, the
targets the others claim (as it knows them over the link, `hptrack.teams.link`) leave its
action list; after it acts, its claim is the target it flies for. A UAV that chooses a new
sub-task therefore fixes the choices of the UAVs before it and of those mid-sub-task, as in
multiagent rollout (Bhattacharya, Kailas, Badyal, Gil and Bertsekas, CoRL 2020), at the cost of
one single-UAV search per UAV and decision, linear in the team's size. What it leaves out: a
UAV does not credit the others' future finds in its own model (their targets are out of its
action list, their beliefs grow in its model as if nobody pursued them), and the UAVs after it
are not simulated by a base policy.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, ClassVar

import numpy as np
from pydantic import Field

from hptrack.baselines.clairvoyant import ClairvoyantPlanner
from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import CurrentPlan, InputError, MissionSpec, Observation
from hptrack.planning.hierarchical import HierarchicalPlanner, MctsSettings
from hptrack.settings import NoSettings, PlannerSettings
from hptrack.teams.link import NO_CLAIM, Link

MAX_SHARE_PERIOD_S = 3600.0
"""Longest time between two shares of a limited link, s."""

TEAM_PRESET = "improved"
"""The preset of every UAV's search in ``team-mcts`` and ``team-cbba`` when none is named: the
team tables were measured with it, and the revisit tour inside a team's searches measured worse
with three UAVs (``docs/results/teams.md``)."""


class LinkSettings(PlannerSettings):
    """The team's link (`hptrack.teams.link`).

    Attributes:
        share_period: s between two shares of the UAVs' claims; 0 (default): each claim is
            heard at once.
        drop_rate: the chance that one message (a claim, from one UAV to another, at a
            share) is lost; 0 by default.
    """

    share_period: Annotated[float, Field(ge=0.0, le=MAX_SHARE_PERIOD_S)] = 0.0
    drop_rate: Annotated[float, Field(ge=0.0, lt=1.0)] = 0.0


class TeamMctsSettings(LinkSettings, MctsSettings):
    """Options of ``team-mcts``: every UAV's search (`MctsSettings`, the same for each) and the
    link (`LinkSettings`)."""

    default_preset: ClassVar[str | None] = TEAM_PRESET

    def member_settings(self) -> MctsSettings:
        """One UAV's search settings."""
        return MctsSettings.model_validate({k: getattr(self, k) for k in MctsSettings.model_fields})


class TeamGreedySettings(LinkSettings):
    """Options of ``team-greedy`` and ``team-clairvoyant``: the link (`LinkSettings`)."""


def member_view(observation: Observation, j: int) -> Observation:
    """``observation`` as UAV ``j`` of a team plans on it: its own position, the shared
    beliefs."""
    return Observation(
        observation.step,
        observation.time,
        observation.remaining_budget,
        observation.agent_positions[j : j + 1],
        observation.means,
        observation.covariances,
        observation.detected,
    )


def claim_of(planner: Any) -> int:
    """The target a member planner flies for now (`NO_CLAIM`: none): a sub-task's target,
    or the ``target`` of a planner without sub-tasks."""
    subtask = planner.current_plan().subtask
    if subtask is not None:
        return NO_CLAIM if subtask.target is None else int(subtask.target)
    target = getattr(planner, "target", None)
    return NO_CLAIM if target is None else int(target)


class SequentialTeamPlanner:
    """A team of single-UAV planners, planned one UAV at a time (module docstring).

    Args:
        settings: the team's options (with the link's).
        member: builds one UAV's planner (a fresh one per UAV).
    """

    name = "team"

    def __init__(self, settings: LinkSettings, member: Callable[[], Any]) -> None:
        self.settings = settings
        self._member = member

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        m, n = mission.n_vehicles, mission.n_targets
        streams = rng.spawn(m + 1)
        s = self.settings
        self._n = n
        self._link = Link(m, mission.time_step, s.share_period, s.drop_rate, streams[m])
        self._members = [self._member() for _ in range(m)]
        for j, member in enumerate(self._members):
            member.claimed = self._link.claimed(j, n)
            member.reset(mission.vehicle_mission(j), member_view(observation, j), streams[j])
            self._link.claim(j, claim_of(member))
        self._link.share(observation.step)

    def act(self, observation: Observation) -> np.ndarray:
        out = np.empty((len(self._members), 2))
        for j, member in enumerate(self._members):
            member.claimed = self._link.claimed(j, self._n)
            out[j] = member.act(member_view(observation, j))
            self._link.claim(j, claim_of(member))
        self._link.share(observation.step)
        return out

    def claims(self) -> np.ndarray:
        """``(m,)`` the target each UAV flies for now (`NO_CLAIM`: none)."""
        return np.diagonal(self._link.known).copy()

    def current_plan(self) -> CurrentPlan:
        """The first UAV's (`current_plans` gives every UAV's)."""
        return self._members[0].current_plan()

    def current_plans(self) -> list[CurrentPlan]:
        """Every UAV's current plan, in order."""
        return [member.current_plan() for member in self._members]

    def episode_info(self) -> dict:
        """The settings, every UAV's own episode info (``members``) and the link's counts."""
        return {
            "settings": self.settings.as_json(),
            "members": [member.episode_info() for member in self._members],
            "link": self._link.info(),
        }


class TeamMctsPlanner(SequentialTeamPlanner):
    """``team-mcts``: the hierarchical planner on every UAV, one UAV at a time."""

    name = "team-mcts"

    def __init__(self, settings: TeamMctsSettings | None = None) -> None:
        settings = settings or TeamMctsSettings()
        member = settings.member_settings()
        super().__init__(settings, lambda: HierarchicalPlanner(member))


class TeamGreedyPlanner(SequentialTeamPlanner):
    """``team-greedy``: greedy on every UAV, each chasing the most uncertain target that no
    other UAV claims."""

    name = "team-greedy"

    def __init__(self, settings: TeamGreedySettings | None = None) -> None:
        super().__init__(settings or TeamGreedySettings(), lambda: GreedyPlanner(NoSettings()))


class TeamClairvoyantPlanner(SequentialTeamPlanner):
    """``team-clairvoyant``: the perfect-knowledge reference on every UAV (READS THE TRUE
    TARGET STATES), each planning visits to targets no other UAV claims."""

    name = "team-clairvoyant"
    reads_truth: ClassVar[str] = ClairvoyantPlanner.reads_truth

    def __init__(self, settings: TeamGreedySettings | None = None) -> None:
        settings = settings or TeamGreedySettings()
        super().__init__(settings, lambda: ClairvoyantPlanner(NoSettings()))

    def see_truth(self, states: np.ndarray) -> None:
        """The true target states of this step, for every UAV's reference."""
        for member in self._members:
            member.see_truth(states)

    def act(self, observation: Observation) -> np.ndarray:
        try:
            return super().act(observation)
        except InputError:
            raise InputError(
                "planner 'team-clairvoyant' reads the true target states, which only the "
                "simulator has: use it in hptrack simulate or benchmark"
            ) from None
