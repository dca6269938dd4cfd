"""hptrack: hierarchical planning for long-horizon multi-target tracking with a UAV or a team.

Implements Yuan, Moon, Cao and Scherer, "Hierarchical Planning for Long-Horizon Multi-Target
Tracking Under Target Motion Uncertainty" (arXiv:2510.10421). SI units throughout: metres,
seconds, metres per second.

The public API is importable from here; each name loads its module on first use, so that
``import hptrack`` stays cheap:

    import hptrack

    scenario = hptrack.random_scenario(n_targets=4, seed=0)
    decision = hptrack.plan(scenario, "mcts", iterations=20_000)
    record = hptrack.run_episode(scenario, hptrack.make_planner("mcts"))
"""

from __future__ import annotations

from importlib import import_module
from typing import TYPE_CHECKING, Any

import hptrack._numba_cache  # noqa: F401  (first: numba's cache directory, before any kernel)

_EXPORTS = {
    "Scenario": "hptrack.scenario",
    "load_scenario": "hptrack.scenario",
    "save_scenario": "hptrack.scenario",
    "random_scenario": "hptrack.scenario",
    "MissionSpec": "hptrack.interface",
    "Observation": "hptrack.interface",
    "Planner": "hptrack.interface",
    "InputError": "hptrack.interface",
    "PLANNERS": "hptrack.registry",
    "make_planner": "hptrack.registry",
    "planner_settings": "hptrack.registry",
    "plan": "hptrack.decision",
    "Decision": "hptrack.decision",
    "run_episode": "hptrack.sim.episode",
    "EpisodeRecord": "hptrack.sim.record",
    "benchmark": "hptrack.experiments.benchmark",
}
"""Public name -> the module that defines it."""

__all__ = [
    "Decision",
    "EpisodeRecord",
    "InputError",
    "MissionSpec",
    "Observation",
    "PLANNERS",
    "Planner",
    "Scenario",
    "benchmark",
    "load_scenario",
    "make_planner",
    "plan",
    "planner_settings",
    "random_scenario",
    "run_episode",
    "save_scenario",
]

if TYPE_CHECKING:
    from hptrack.decision import Decision, plan
    from hptrack.experiments.benchmark import benchmark
    from hptrack.interface import InputError, MissionSpec, Observation, Planner
    from hptrack.registry import PLANNERS, make_planner, planner_settings
    from hptrack.scenario import Scenario, load_scenario, random_scenario, save_scenario
    from hptrack.sim.episode import run_episode
    from hptrack.sim.record import EpisodeRecord


def _version() -> str:
    """The installed distribution's version (pyproject.toml is its one source)."""
    from importlib import metadata

    try:
        return metadata.version("hptrack")
    except metadata.PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


def __getattr__(name: str) -> Any:
    if name == "__version__":
        globals()[name] = value = _version()
        return value
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'hptrack' has no attribute {name!r}")
    value = getattr(import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS, "__version__"})
