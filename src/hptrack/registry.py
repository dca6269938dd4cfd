"""Planner registry: names to factories, so the simulator and the CLI never import a planner.

Each factory takes keyword options (the planner's parameters) and returns a fresh
:class:`~hptrack.sim.interface.Planner`.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable

from hptrack.baselines.arvi import ArviPlanner
from hptrack.baselines.astar import AStarPlanner
from hptrack.baselines.greedy import GreedyPlanner
from hptrack.baselines.stationary import StationaryPlanner
from hptrack.coverage.subtask import CoveragePlanner
from hptrack.planning.hierarchical import HierarchicalPlanner
from hptrack.sim.interface import Planner

PLANNERS: dict[str, Callable[..., Planner]] = {
    "mcts": HierarchicalPlanner,
    "stationary": StationaryPlanner,
    "greedy": GreedyPlanner,
    "coverage": CoveragePlanner,
    "arvi": ArviPlanner.from_options,
    "astar": AStarPlanner.from_options,
}


def make_planner(name: str, **options) -> Planner:
    """Build the planner registered as ``name`` with ``options``."""
    try:
        factory = PLANNERS[name]
    except KeyError:
        raise ValueError(f"unknown planner {name!r}; choose from {sorted(PLANNERS)}") from None
    params = inspect.signature(factory).parameters.values()
    if not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
        accepted = {p.name for p in params}
        unknown = sorted(set(options) - accepted)
        if unknown:
            raise ValueError(f"planner {name!r} takes no option {', '.join(unknown)}; "
                             f"its options: {sorted(accepted) or 'none'}")
    return factory(**options)
