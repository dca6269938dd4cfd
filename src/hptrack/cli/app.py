"""``hptrack`` command line: thin typer commands over the library, rendered with rich.

`main` is the entry point: bad input (an `InputError` or a
command-line usage error) is one line on stderr and exit code 2; any other exception is a bug:
its traceback, a line asking to report it, and exit code 1.
"""

from __future__ import annotations

import errno
import inspect
import math
import sys
import traceback
import typing
from pathlib import Path
from typing import Annotated

import matplotlib
import numpy as np
import typer
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from hptrack import __version__
from hptrack.cli.common import (
    SETTING_HELP,
    check_figure_path,
    check_output_path,
    check_seed,
    console,
    error_console,
    planner_settings_for,
    progress_display,
    write_json,
    writing,
)
from hptrack.interface import InputError, one_line
from hptrack.models.mission import MAX_TARGETS
from hptrack.registry import PLANNERS, make_planner
from hptrack.scenario import Scenario, load_scenario, random_scenario, save_scenario
from hptrack.scenario.model import MAX_AGENTS, MAX_STEPS
from hptrack.scenario.random import with_no_fly
from hptrack.sim.episode import record_bytes, run_episode
from hptrack.sim.metrics import gospa_cutoff

matplotlib.use("Agg")

app = typer.Typer(
    help="Hierarchical planning for long-horizon multi-target tracking with a UAV or a team.",
    no_args_is_help=True,
    add_completion=False,
)
scenario_app = typer.Typer(help="Create and check scenario files.", no_args_is_help=True)
app.add_typer(scenario_app, name="scenario")

DEFAULT_PLANNER = "mcts"
MAX_RECORD_BYTES = 2 * 2**30
"""Largest episode record ``simulate`` keeps in memory (a larger one is refused up front)."""


def _version(value: bool) -> None:
    if value:
        console.print(f"hptrack {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option(
            "--version", callback=_version, is_eager=True, help="Print the version and exit."
        ),
    ] = False,
) -> None:
    """Hierarchical planning for long-horizon multi-target tracking with one UAV."""


def draw_seed() -> int:
    """A fresh seed from the operating system's entropy (printed so that a run can be repeated)."""
    return int(np.random.SeedSequence().generate_state(1, np.uint32)[0])


def _check_team_size(team: int) -> None:
    if not 1 <= team <= MAX_AGENTS:
        raise InputError(f"--team must be between 1 and {MAX_AGENTS}, got {team}")


def _load_or_random(
    path: Path | None,
    random: bool,
    targets: int,
    seed: int | None,
    homogeneous: bool,
    team: int = 1,
) -> Scenario:
    if (path is None) == (not random):
        raise InputError("give either a SCENARIO file or --random")
    if not random and team != 1:
        raise InputError("--team goes with --random (a scenario file gives its team as agents:)")
    if random:
        if not 1 <= targets <= MAX_TARGETS:
            raise InputError(f"--targets must be between 1 and {MAX_TARGETS}, got {targets}")
        _check_team_size(team)
        return random_scenario(targets, seed=seed, homogeneous=homogeneous, team=team)
    scenario = load_scenario(path)
    return scenario if seed is None else scenario.with_seed(seed)


@app.command()
def simulate(
    scenario_path: Annotated[
        Path | None, typer.Argument(metavar="[SCENARIO]", help="Scenario YAML file.")
    ] = None,
    random: Annotated[bool, typer.Option("--random", help="Use a random scenario.")] = False,
    targets: Annotated[int, typer.Option(help="Targets in a --random scenario.")] = 4,
    team: Annotated[int, typer.Option(help="UAVs in a --random scenario, all from its start.")] = 1,
    homogeneous: Annotated[
        bool, typer.Option("--homogeneous/--heterogeneous", help=SETTING_HELP)
    ] = False,
    planner: Annotated[str, typer.Option(help=f"One of: {', '.join(PLANNERS)}.")] = (
        DEFAULT_PLANNER
    ),
    seed: Annotated[
        int | None,
        typer.Option(
            help="Seed (overrides the file's); with --random and no seed one is drawn and printed."
        ),
    ] = None,
    iterations: Annotated[
        int | None, typer.Option(help="Tree-search iterations per decision.")
    ] = None,
    time_limit: Annotated[float | None, typer.Option(help="Planning seconds per decision.")] = None,
    option: Annotated[
        list[str] | None,
        typer.Option("--option", "-o", help="Planner option KEY=VALUE (or PLANNER.KEY=VALUE)."),
    ] = None,
    json_path: Annotated[Path | None, typer.Option("--json", help="Write a JSON summary.")] = None,
    plot: Annotated[Path | None, typer.Option(help="Write the mission figure (PNG).")] = None,
    record_path: Annotated[
        Path | None, typer.Option("--record", help="Save the episode (.npz).")
    ] = None,
    belief_stride: Annotated[
        int,
        typer.Option(help="Store the beliefs every this many steps (the last is always stored)."),
    ] = 1,
    animate_path: Annotated[
        Path | None,
        typer.Option(
            "--animate", help="Also write an animation of the mission (.gif, or .mp4 with ffmpeg)."
        ),
    ] = None,
) -> None:
    """Plan and simulate one mission; print the per-target summary and U."""
    check_seed(seed)
    if belief_stride < 1:
        raise InputError(f"--belief-stride must be a positive integer, got {belief_stride}")
    for path, name in ((json_path, "--json"), (record_path, "--record")):
        check_output_path(path, name)
    check_figure_path(plot, "--plot")
    if animate_path is not None:
        from hptrack.cli.animate import check_animation_output

        check_animation_output(animate_path, "--animate")
    drawn = random and seed is None
    if drawn:
        seed = draw_seed()
    scenario = _load_or_random(scenario_path, random, targets, seed, homogeneous, team)
    settings = planner_settings_for((planner,), option, iterations, time_limit)[planner]
    _check_record_size(len(scenario.targets), scenario.n_steps, belief_stride)
    if drawn:
        console.print(f"seed {seed} (drawn; pass --seed {seed} to repeat this mission)")
    agent = make_planner(planner, settings)
    with progress_display(
        f"{planner} mission",
        "steps",
        TextColumn(f"[bold]{escape(planner)} mission"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("steps"),
        TimeElapsedColumn(),
        TextColumn("left"),
        TimeRemainingColumn(),
        transient=True,
    ) as progress:
        task = progress.add_task("", total=scenario.n_steps)
        record = run_episode(
            scenario,
            agent,
            belief_stride=belief_stride,
            on_step=lambda k, n: progress.update(task, completed=k),
        )
    if not math.isfinite(record.uncertainty):
        raise RuntimeError(f"the mission ended with a non-finite U ({record.uncertainty})")
    _print_summary(record)
    if json_path:
        write_json(
            json_path, {**record.summary(), "scenario_seed": scenario.seed, "seed_drawn": drawn}
        )
    if record_path:
        with writing(record_path, "--record"):
            record.save(record_path)
    if plot:
        from hptrack.viz.mission import save_mission_figure

        with writing(plot, "--plot"):
            save_mission_figure(record, str(plot))
        console.print(f"figure written to {escape(str(plot))}")
    if animate_path is not None:
        from hptrack.cli.animate import write_animation

        write_animation(record, animate_path)


def _check_record_size(n_targets: int, n_steps: int, belief_stride: int) -> None:
    """Refuse, before the mission, a record larger than `MAX_RECORD_BYTES`, naming the
    smallest ``--belief-stride`` that fits (the per-step part does not shrink with it)."""
    need = record_bytes(n_targets, n_steps, belief_stride)
    if need <= MAX_RECORD_BYTES:
        return
    fixed = record_bytes(n_targets, n_steps, n_steps + 1)
    advice = f"a shorter budget (at most {MAX_STEPS:,} steps)"
    if fixed <= MAX_RECORD_BYTES:
        stride = belief_stride
        while record_bytes(n_targets, n_steps, stride) > MAX_RECORD_BYTES:
            stride = max(stride + 1, 2 * stride)
        low = stride // 2
        while low + 1 < stride:  # the smallest stride that fits
            mid = (low + stride) // 2
            if record_bytes(n_targets, n_steps, mid) <= MAX_RECORD_BYTES:
                stride = mid
            else:
                low = mid
        advice = f"--belief-stride {stride} or more, or " + advice
    raise InputError(
        f"the mission of {n_steps:,} steps needs about {need / 2**30:.1f} GiB for its "
        f"record (at most {MAX_RECORD_BYTES / 2**30:g} GiB); use {advice}"
    )


def _print_summary(record) -> None:
    table = Table(
        title=escape(f"{record.planner} mission, seed {record.seed}, {record.times[-1]:.0f} s")
    )
    table.add_column("target")
    table.add_column("final log det Σxy", justify="right")
    table.add_column("detections (steps)", justify="right")
    for tid, logdet, count in zip(
        record.target_ids, record.per_target_logdet, record.detection_counts(), strict=True
    ):
        table.add_row(escape(tid), f"{logdet:.3f}", str(int(count)))
    table.add_section()
    table.add_row("U", f"{record.uncertainty:.3f}", str(int(record.detections.sum())))
    console.print(table)
    metrics = record.metrics()
    cutoff = gospa_cutoff(record.sensor_diameter)
    lost = metrics["tracks_lost"]
    for line in (
        f"GOSPA (p = 2, c = {cutoff:g} m): mean {metrics['gospa_mean']:.3f} m, "
        f"end {metrics['gospa_end']:.3f} m",
        f"track loss: {metrics['track_loss']} of {len(record.target_ids)} targets at the end "
        "(outside the 99 % ellipse, or swapped)" + (f": {', '.join(lost)}" if lost else ""),
    ):
        console.print(escape(line), highlight=False, soft_wrap=True)


@scenario_app.command("random")
def scenario_random(
    targets: Annotated[int, typer.Option(help="Number of targets.")],
    seed: Annotated[int, typer.Option(help="Seed; fixes every drawn value.")] = 0,
    team: Annotated[
        int, typer.Option(help="UAVs (agents:), all from the start; 1: one agent:.")
    ] = 1,
    homogeneous: Annotated[
        bool, typer.Option("--homogeneous/--heterogeneous", help=SETTING_HELP)
    ] = False,
    output: Annotated[Path, typer.Option("--output", "-o", help="YAML file to write.")] = Path(
        "scenario.yaml"
    ),
    no_fly: Annotated[
        bool,
        typer.Option(
            "--no-fly",
            help="Add one to three random no-fly circles covering 10-25 % of the targets' "
            "square (a fence: block, margin 10 m).",
        ),
    ] = False,
) -> None:
    """Write the paper's random scenario (Sec. V) to a YAML file."""
    check_seed(seed)
    if not 1 <= targets <= MAX_TARGETS:
        raise InputError(f"--targets must be between 1 and {MAX_TARGETS}, got {targets}")
    _check_team_size(team)
    check_output_path(output, "--output")
    with writing(output, "--output"):
        scenario = random_scenario(targets, seed=seed, homogeneous=homogeneous, team=team)
        save_scenario(with_no_fly(scenario, seed) if no_fly else scenario, output)
    console.print(f"{targets}-target scenario (seed {seed}) written to {escape(str(output))}")


@scenario_app.command("check")
def scenario_check(path: Annotated[Path, typer.Argument(help="Scenario YAML file.")]) -> None:
    """Validate a scenario file."""
    scenario = load_scenario(path)
    console.print(
        f"{escape(str(path))}: valid, {len(scenario.targets)} targets, {scenario.budget:g} s budget"
    )


def _shown(value: object) -> str:
    """An option value as a user would type it after ``-o KEY=``."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, list | tuple):
        return ",".join(map(_shown, value))
    return f"{value:g}" if isinstance(value, float) else str(value)


def option_defaults(name: str) -> dict[str, str]:
    """Each option of planner ``name`` with its default as the planner resolves it (an option
    without a default shows ``required``)."""
    settings_type = PLANNERS[name].settings_type
    try:
        resolved = settings_type.from_options(name, {}).as_json()
    except InputError:  # a required option: show the declared defaults
        resolved = {
            key: "required" if field.is_required() else field.default
            for key, field in settings_type.model_fields.items()
        }
    return {key: value if value == "required" else _shown(value) for key, value in resolved.items()}


def preset_changes(name: str) -> dict[str, dict[str, str]]:
    """For a planner with a ``preset`` option: per other preset, the defaults it changes."""
    field = PLANNERS[name].settings_type.model_fields.get("preset")
    if field is None:
        return {}
    base = option_defaults(name)
    out = {}
    for preset in typing.get_args(field.annotation):
        if preset != base["preset"]:
            other = PLANNERS[name].settings_type.from_options(name, {"preset": preset}).as_json()
            out[preset] = {
                k: _shown(v)
                for k, v in other.items()
                if k != "preset" and k in base and _shown(v) != base[k]
            }
    return out


@app.command("planners")
def list_planners() -> None:
    """List the registered planners, each option with its default (set with -o KEY=VALUE)."""
    table = Table(title="planners (set an option with -o KEY=VALUE)", show_lines=True)
    table.add_column("planner", style="bold", no_wrap=True)
    table.add_column("what it does")
    table.add_column("options (defaults)", overflow="fold")
    for name, entry in PLANNERS.items():
        lines = [", ".join(f"{k}={v}" for k, v in option_defaults(name).items()) or "none"]
        for preset, changes in preset_changes(name).items():
            changed = ", ".join(f"{k}={v}" for k, v in changes.items())
            lines.append(f"-o preset={preset} sets {changed}")
        table.add_row(escape(name), escape(entry.summary), escape("\n".join(lines)))
    console.print(table)


def _register_commands() -> None:
    from hptrack.cli import (
        animate,
        benchmark,
        coverage,
        examples,
        fit_detection,
        flight,
        learn,
        warm_up,
    )

    animate.register(app)
    benchmark.register(app)
    coverage.register(app)
    examples.register(app)
    fit_detection.register(app)
    flight.register(app)
    learn.register(app)
    warm_up.register(app)
    _one_line_summaries(app)


def _one_line_summaries(typer_app: typer.Typer) -> None:
    """Give every command of ``typer_app`` (and of its groups) its docstring's first paragraph
    on one line as the summary in the command lists (Typer's rich help keeps the docstring's
    line breaks there)."""
    for info in typer_app.registered_commands:
        if info.short_help is None and info.callback is not None and info.callback.__doc__:
            first = inspect.cleandoc(info.callback.__doc__).split("\n\n")[0]
            info.short_help = " ".join(first.split())
    for group in typer_app.registered_groups:
        if group.typer_instance is not None:
            _one_line_summaries(group.typer_instance)


_register_commands()


def _is(err: BaseException, name: str) -> bool:
    """Whether ``err`` is a command-line framework exception called ``name`` (click's, or the
    copy of click that typer vendors)."""
    return any(cls.__name__ == name for cls in type(err).__mro__)


def _given(err: Exception, argv: list[str]) -> str:
    """`` (got VALUE)`` for a bad option value, taken from the command line."""
    opts = getattr(getattr(err, "param", None), "opts", None) or []
    for i, token in enumerate(argv):
        for opt in opts:
            if token == opt and i + 1 < len(argv):
                return f" (got {argv[i + 1]!r})"
            if token.startswith(opt + "="):
                return f" (got {token[len(opt) + 1 :]!r})"
    return ""


WRITE_ERRNOS = (errno.ENOSPC, errno.EROFS, errno.EDQUOT, errno.EFBIG, errno.EIO)
"""Errors of a write the machine refused (disk full, read-only, quota, too large, I/O): one
line naming the file, never a traceback."""


def _refuse(message: str) -> None:
    message = one_line(message)
    error_console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    sys.exit(2)


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``hptrack`` script (exit codes: 0 done, 1 a bug, 2 bad input)."""
    try:
        code = app(args=argv, prog_name="hptrack", standalone_mode=False)
    except InputError as err:
        _refuse(str(err))
    except KeyboardInterrupt:
        error_console.print("interrupted", highlight=False)
        sys.exit(130)
    except Exception as err:
        if _is(err, "Exit"):
            sys.exit(err.exit_code)
        if _is(err, "Abort"):
            error_console.print("interrupted", highlight=False)
            sys.exit(130)
        if isinstance(err, OSError) and err.errno in WRITE_ERRNOS:
            _refuse(f"{err.filename or 'an output file'}: the write failed ({err.strerror})")
        if _is(err, "NoArgsIsHelpError"):  # the help is shown above
            _refuse("give a command (listed above), e.g. hptrack simulate --random")
        if _is(err, "UsageError"):
            _refuse(err.format_message() + _given(err, sys.argv[1:] if argv is None else argv))
        traceback.print_exc()
        error_console.print(
            "[bold red]This is a bug in hptrack, not a problem with your input: "
            "please report it with the traceback above.[/]",
            highlight=False,
        )
        sys.exit(1)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()
