"""``hptrack warm-up``: compile (or load) ahead of a flight every kernel ``hptrack fly`` can need
with the given planners, into the compile cache that every checkout of the same code shares."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape

from hptrack.cli.common import check_seed, console
from hptrack.cli.examples import shipped_examples
from hptrack.cli.flight import flight_planner_settings
from hptrack.interface import InputError
from hptrack.registry import PLANNERS, planner_entry
from hptrack.scenario import load_scenario

EXAMPLE = "paper-flight.yaml"
"""The packaged scenario warmed when none is given (kernels compile per type, not value)."""


def warm_up(
    scenario_path: Annotated[
        Path | None,
        typer.Argument(
            metavar="[SCENARIO]", help=f"Scenario YAML file (default the packaged {EXAMPLE})."
        ),
    ] = None,
    planner: Annotated[str, typer.Option(help="The planner fly will fly.")] = "mcts",
    iterations: Annotated[
        int | None, typer.Option(help="Tree-search iterations per decision, as given to fly.")
    ] = None,
    time_limit: Annotated[
        float | None, typer.Option(help="Planning seconds per decision, as given to fly.")
    ] = None,
    option: Annotated[
        list[str] | None,
        typer.Option("--option", "-o", help="Planner option KEY=VALUE, as given to fly."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the warm-up's simulated missions.")] = 0,
) -> None:
    """Compile or load every kernel a flight (hptrack fly) with this planner and options can
    need, so that fly starts at once: a fresh install compiles for about a minute, once, and
    every checkout of the same code shares the cache."""
    from hptrack.runtime.warm_up import warm_up_flight

    check_seed(seed)
    if planner_entry(planner).reads_truth:
        raise InputError(
            f"--planner {planner}: it reads the true target states and never flies; choose "
            f"from {', '.join(n for n, e in PLANNERS.items() if not e.reads_truth)}"
        )
    settings = flight_planner_settings(planner, option, iterations, time_limit)
    path = scenario_path or shipped_examples()[EXAMPLE]
    scenario = load_scenario(path)
    cache = os.environ.get("NUMBA_CACHE_DIR", "none")
    console.print(escape(f"warming up {planner} on {path}; compile cache {cache}"), highlight=False)
    seconds = warm_up_flight(scenario, planner, settings, seed)
    console.print(escape(f"{planner}: kernels ready in {seconds:.1f} s"), highlight=False)


def register(app: typer.Typer) -> None:
    """Add ``warm-up`` to ``app``."""
    app.command("warm-up")(warm_up)
