"""``hptrack`` command line: thin typer commands over the library, rendered with rich."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import matplotlib
import typer
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from hptrack.cli.common import clean_errors, console, parse_options, write_json
from hptrack.registry import PLANNERS, make_planner
from hptrack.scenario import Scenario, load_scenario, random_scenario, save_scenario
from hptrack.sim.episode import run_episode

matplotlib.use("Agg")

app = typer.Typer(help="Hierarchical planning for long-horizon multi-target tracking with one UAV.",
                  no_args_is_help=True, add_completion=False)
scenario_app = typer.Typer(help="Create and check scenario files.", no_args_is_help=True)
app.add_typer(scenario_app, name="scenario")

DEFAULT_PLANNER = "mcts"


def _load_or_random(path: Path | None, random: bool, targets: int, seed: int | None,
                    homogeneous: bool) -> Scenario:
    if (path is None) == (not random):
        raise ValueError("give either a SCENARIO file or --random")
    if random:
        return random_scenario(targets, seed=0 if seed is None else seed, homogeneous=homogeneous)
    scenario = load_scenario(path)
    return scenario if seed is None else scenario.with_seed(seed)


@app.command()
def simulate(
    scenario_path: Annotated[Path | None, typer.Argument(metavar="[SCENARIO]",
                                                         help="Scenario YAML file.")] = None,
    random: Annotated[bool, typer.Option("--random", help="Use a random scenario.")] = False,
    targets: Annotated[int, typer.Option(help="Targets in a --random scenario.")] = 4,
    homogeneous: Annotated[bool, typer.Option(help="Shared q and prior (--random).")] = False,
    planner: Annotated[str, typer.Option(help=f"One of: {', '.join(PLANNERS)}.")] = (
        DEFAULT_PLANNER),
    seed: Annotated[int | None, typer.Option(help="Seed (overrides the file's).")] = None,
    iterations: Annotated[int | None, typer.Option(help="Tree-search iterations per decision.")
                          ] = None,
    time_limit: Annotated[float | None, typer.Option(help="Planning seconds per decision.")
                          ] = None,
    option: Annotated[list[str] | None, typer.Option("--option", "-o",
                                                     help="Planner option KEY=VALUE.")] = None,
    json_path: Annotated[Path | None, typer.Option("--json", help="Write a JSON summary.")
                         ] = None,
    plot: Annotated[Path | None, typer.Option(help="Write the mission figure (PNG).")] = None,
    record_path: Annotated[Path | None, typer.Option("--record",
                                                     help="Save the episode (.npz).")] = None,
) -> None:
    """Plan and simulate one mission; print the per-target summary and U."""
    with clean_errors():
        scenario = _load_or_random(scenario_path, random, targets, seed, homogeneous)
        options = parse_options(option)
        if iterations is not None:
            options["iterations"] = iterations
        if time_limit is not None:
            options["time_limit"] = time_limit
        agent = make_planner(planner, **options)
        with Progress(TextColumn("[bold]{task.description}"), BarColumn(), TimeElapsedColumn(),
                      console=console, transient=True) as progress:
            task = progress.add_task(f"{planner} mission", total=None)
            record = run_episode(scenario, agent,
                                 on_step=lambda k, n: progress.update(task, completed=k, total=n))
        _print_summary(record)
        if json_path:
            write_json(json_path, record.summary())
        if record_path:
            record.save(record_path)
        if plot:
            from hptrack.viz.mission import save_mission_figure

            plot.parent.mkdir(parents=True, exist_ok=True)
            save_mission_figure(record, str(plot))
            console.print(f"figure written to {plot}")


def _print_summary(record) -> None:
    table = Table(title=f"{record.planner} mission, seed {record.seed}, "
                        f"{record.times[-1]:.0f} s")
    table.add_column("target")
    table.add_column("final log det Σxy", justify="right")
    table.add_column("detections (steps)", justify="right")
    for tid, logdet, count in zip(record.target_ids, record.per_target_logdet,
                                  record.detection_counts(), strict=True):
        table.add_row(tid, f"{logdet:.3f}", str(int(count)))
    table.add_section()
    table.add_row("U", f"{record.uncertainty:.3f}", str(int(record.detections.sum())))
    console.print(table)


@scenario_app.command("random")
def scenario_random(
    targets: Annotated[int, typer.Option(help="Number of targets.")],
    seed: Annotated[int, typer.Option(help="Seed; fixes every drawn value.")] = 0,
    homogeneous: Annotated[bool, typer.Option(help="One q and one prior for all targets.")
                           ] = False,
    output: Annotated[Path, typer.Option("--output", "-o", help="YAML file to write.")] = Path(
        "scenario.yaml"),
) -> None:
    """Write the paper's random scenario (Sec. V) to a YAML file."""
    with clean_errors():
        save_scenario(random_scenario(targets, seed=seed, homogeneous=homogeneous), output)
        console.print(f"{targets}-target scenario (seed {seed}) written to {output}")


@scenario_app.command("check")
def scenario_check(path: Annotated[Path, typer.Argument(help="Scenario YAML file.")]) -> None:
    """Validate a scenario file."""
    with clean_errors():
        scenario = load_scenario(path)
        console.print(f"{path}: valid, {len(scenario.targets)} targets, "
                      f"{scenario.budget:g} s budget")


@app.command("planners")
def list_planners() -> None:
    """List the registered planners."""
    for name in PLANNERS:
        console.print(name)


def _register_commands() -> None:
    from hptrack.cli import benchmark, coverage

    benchmark.register(app)
    coverage.register(app)


_register_commands()


def main() -> None:
    """Entry point of the ``hptrack`` script."""
    app()
