"""A short simulated mission shared by the figure and animation tests."""

import pytest

from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode


@pytest.fixture(scope="session")
def short_mission():
    """Two targets, 60 s (120 steps), greedy planner; beliefs stored at every step."""
    scenario = random_scenario(2, seed=1).model_copy(update={"budget": 60.0})
    return scenario, run_episode(scenario, make_planner("greedy"))
