"""Shared scenarios for the runtime tests."""

from pathlib import Path

import pytest

from hptrack.scenario import load_scenario

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "paper-flight.yaml"


@pytest.fixture
def flight_scenario():
    """The paper-flight example (two targets 20 m apart at 3 m/s, 60 s)."""
    return load_scenario(EXAMPLE)


@pytest.fixture
def example_path():
    """Path of the paper-flight example."""
    return EXAMPLE


@pytest.fixture
def flight_cli(cli):
    """The ``cli`` fixture with the flight commands registered."""
    from hptrack.cli import app as app_module
    from hptrack.cli.flight import register

    if "fly" not in {command.name for command in app_module.app.registered_commands}:
        register(app_module.app)
    return cli
