"""Planner registry: names to planner classes and their settings, so that the simulator and the
CLI never import a planner.

Each entry builds a fresh `Planner` from validated settings
(`hptrack.settings`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hptrack.baselines.arvi import ArviPlanner, ArviSettings
from hptrack.baselines.astar import AStarPlanner, AStarSettings
from hptrack.baselines.clairvoyant import ClairvoyantPlanner
from hptrack.baselines.coverage import CoveragePlanner, CoverageSettings
from hptrack.baselines.greedy import GreedyPlanner
from hptrack.baselines.stationary import StationaryPlanner
from hptrack.interface import InputError, Planner, TruthReader
from hptrack.learning.policy_planner import AdfqPlanner, AdfqSettings, Sb3Planner, Sb3Settings
from hptrack.planning.hierarchical import HierarchicalPlanner, MctsSettings
from hptrack.planning.tour import TourPlanner, TourSettings
from hptrack.settings import NoSettings, PlannerSettings
from hptrack.teams.auction import TeamCbbaPlanner, TeamCbbaSettings
from hptrack.teams.sequential import (
    TeamClairvoyantPlanner,
    TeamGreedyPlanner,
    TeamGreedySettings,
    TeamMctsPlanner,
    TeamMctsSettings,
)


@dataclass(frozen=True)
class PlannerEntry:
    """A registered planner: its settings model and the factory that takes them."""

    settings_type: type[PlannerSettings]
    factory: Callable[[Any], Planner]
    summary: str
    flies_team: bool = False
    """It flies a team of UAVs (the others fly one and refuse more)."""

    @property
    def reads_truth(self) -> bool:
        """Whether the planner reads the true target states (a reference the simulator alone can
        run; never flown)."""
        return isinstance(self.factory, type) and issubclass(self.factory, TruthReader)


PLANNERS: dict[str, PlannerEntry] = {
    "mcts": PlannerEntry(
        MctsSettings,
        HierarchicalPlanner,
        "the paper's hierarchical planner (MCTS over coverage sub-tasks)",
    ),
    "tour": PlannerEntry(
        TourSettings,
        TourPlanner,
        "revisit tour over the whole budget, scored in the sub-task MDP",
    ),
    "stationary": PlannerEntry(NoSettings, StationaryPlanner, "stays at its start"),
    "greedy": PlannerEntry(NoSettings, GreedyPlanner, "chases the most uncertain reachable target"),
    "coverage": PlannerEntry(
        CoverageSettings,
        CoveragePlanner,
        "pursues one target (-o target=ID) with coverage sub-tasks",
    ),
    "clairvoyant": PlannerEntry(
        NoSettings,
        ClairvoyantPlanner,
        "READS THE TRUE TARGET STATES: perfect-knowledge reference, simulation only",
    ),
    "arvi": PlannerEntry(ArviSettings, ArviPlanner, "Anytime Reduced Value Iteration"),
    "astar": PlannerEntry(AStarSettings, AStarPlanner, "A* with an information heuristic"),
    "adfq": PlannerEntry(
        AdfqSettings,
        AdfqPlanner,
        "Deep ADFQ policy (-o model=PATH, epsilon; default: shipped model for n)",
    ),
    "team-mcts": PlannerEntry(
        TeamMctsSettings,
        TeamMctsPlanner,
        "a team: the hierarchical planner on every UAV, planned one UAV at a time",
        flies_team=True,
    ),
    "team-cbba": PlannerEntry(
        TeamCbbaSettings,
        TeamCbbaPlanner,
        "a team: targets allocated by CBBA, then the hierarchical planner per UAV on its bundle",
        flies_team=True,
    ),
    "team-greedy": PlannerEntry(
        TeamGreedySettings,
        TeamGreedyPlanner,
        "a team: greedy on every UAV, each on targets no other UAV claims",
        flies_team=True,
    ),
    "team-clairvoyant": PlannerEntry(
        TeamGreedySettings,
        TeamClairvoyantPlanner,
        "READS THE TRUE TARGET STATES: a team of perfect-knowledge references",
        flies_team=True,
    ),
    "sb3": PlannerEntry(
        Sb3Settings,
        Sb3Planner,
        "stable-baselines3 PPO policy (-o model=PATH; default: shipped for n)",
    ),
}


def planner_entry(name: str) -> PlannerEntry:
    """The entry of ``name``, or an `InputError` listing the names."""
    try:
        return PLANNERS[name]
    except KeyError:
        raise InputError(
            f"unknown planner {name!r}; choose from {', '.join(sorted(PLANNERS))}"
        ) from None


def check_team(planners: Any, team: int) -> None:
    """Refuse, before any work, a planner of one UAV for a team of ``team`` (and a team
    planner is fine with one).

    Raises:
        InputError: one of ``planners`` flies one UAV and ``team > 1``.
    """
    if team > 1:
        for name in planners:
            if not planner_entry(name).flies_team:
                teams = ", ".join(n for n, e in PLANNERS.items() if e.flies_team)
                raise InputError(
                    f"planner {name!r} flies one UAV; a team of {team} flies with one of {teams}"
                )


def planner_settings(name: str, options: dict[str, Any] | None = None) -> PlannerSettings:
    """Validated settings of planner ``name`` from ``options`` (one-line errors)."""
    return planner_entry(name).settings_type.from_options(name, options)


def make_planner(name: str, settings: PlannerSettings | dict[str, Any] | None = None) -> Planner:
    """A fresh planner ``name`` with ``settings`` (a settings object or raw options)."""
    entry = planner_entry(name)
    if not isinstance(settings, PlannerSettings):
        settings = entry.settings_type.from_options(name, settings)
    return entry.factory(settings)
