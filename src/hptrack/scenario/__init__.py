"""Scenarios: validated model, YAML I/O and the paper's random generators."""

from hptrack.scenario.io import ScenarioError, load_scenario, parse_scenario, save_scenario
from hptrack.scenario.model import AgentSpec, Scenario, TargetSpec
from hptrack.scenario.random import random_scenario

__all__ = [
    "AgentSpec",
    "Scenario",
    "ScenarioError",
    "TargetSpec",
    "load_scenario",
    "parse_scenario",
    "random_scenario",
    "save_scenario",
]
