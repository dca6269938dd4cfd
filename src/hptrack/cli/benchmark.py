"""``hptrack benchmark``: the paper's multi-target comparison, resumable, on K workers or a Dask
cluster."""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path
from typing import Annotated

import typer
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

from hptrack.cli.common import (
    SETTING_HELP,
    check_output_dir,
    check_output_path,
    check_seed,
    check_workers,
    console,
    error_console,
    planner_settings_for,
    progress_display,
    write_json,
    writing,
)
from hptrack.interface import InputError
from hptrack.models.mission import MAX_TARGETS
from hptrack.models.motion import ProcessNoiseForm

MAX_SCENARIOS = 1_000_000
"""Most scenarios per number of targets (the paper uses 100)."""


def _int_list(text: str, option: str) -> tuple[int, ...]:
    try:
        values = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise InputError(f"{option} expects comma-separated integers, got {text!r}") from None
    if not values or min(values) < 1 or max(values) > MAX_TARGETS:
        raise InputError(f"{option} expects integers between 1 and {MAX_TARGETS}, got {text!r}")
    return values


def benchmark(
    targets: Annotated[
        str, typer.Option(help="Numbers of targets, comma-separated.")
    ] = "2,3,4,5,6",
    scenarios: Annotated[int, typer.Option(min=1, help="Scenarios per number of targets.")] = 100,
    planners: Annotated[
        str, typer.Option(help="Planner names, comma-separated.")
    ] = "mcts,greedy,stationary",
    homogeneous: Annotated[
        bool, typer.Option("--homogeneous/--heterogeneous", help=SETTING_HELP)
    ] = False,
    first_seed: Annotated[int, typer.Option(help="First scenario seed.")] = 0,
    process_noise_form: Annotated[
        ProcessNoiseForm,
        typer.Option(
            help="Per-step Q: 'continuous' (velocity block q tau I, the default) or 'paper_text' "
            "(q I, as printed in the paper)."
        ),
    ] = "continuous",
    motion: Annotated[
        str,
        typer.Option(
            help="The targets' motion, for beliefs and truth: constant_velocity (the paper's), "
            "random_walk:D (D m^2/s), ornstein_uhlenbeck:K (K 1/s), singer:ALPHA:SIGMA (1/s, "
            "m/s^2) or constant_acceleration:J:SIGMA (m^2/s^5, m/s^2); values left out take "
            "the model's defaults."
        ),
    ] = "constant_velocity",
    detection_probability: Annotated[
        float,
        typer.Option(
            help="The sensor's chance of detecting a target inside its footprint at each look "
            "(1: the paper's sensor)."
        ),
    ] = 1.0,
    blind: Annotated[
        bool,
        typer.Option(
            "--blind",
            help="Tell the planners the paper's certain sensor (Pd = 1, no false alarms) while "
            "the world's detector misses or reports false alarms (needs --detection-probability "
            "below 1 or --false-alarm-density above 0).",
        ),
    ] = False,
    unlabelled: Annotated[
        bool,
        typer.Option(
            "--unlabelled",
            help="Detections name no target: positions only, associated by the tracker (GNN).",
        ),
    ] = False,
    false_alarm_density: Annotated[
        float,
        typer.Option(
            help="False alarms per m^2 per look inside the footprint (needs --unlabelled).",
        ),
    ] = 0.0,
    detection_correlation_time: Annotated[
        float,
        typer.Option(
            help="Seconds one detection draw holds while a target stays in the footprint, so "
            "misses come in runs (0: independent looks; needs --detection-probability below 1).",
        ),
    ] = 0.0,
    no_fly: Annotated[
        bool,
        typer.Option(
            "--no-fly",
            help="Add one to three random no-fly circles covering 10-25 % of the targets' "
            "square to every scenario (margin 10 m).",
        ),
    ] = False,
    team: Annotated[
        int,
        typer.Option(
            help="UAVs per scenario, all from the start (a team flies with the team-* planners)."
        ),
    ] = 1,
    iterations: Annotated[
        int | None, typer.Option(help="Tree-search iterations per decision.")
    ] = None,
    time_limit: Annotated[float | None, typer.Option(help="Planning seconds per decision.")] = None,
    option: Annotated[
        list[str] | None,
        typer.Option(
            "--option", "-o", help="Planner option PLANNER.KEY=VALUE (KEY=VALUE with one planner)."
        ),
    ] = None,
    workers: Annotated[
        int | None,
        typer.Option(
            help="Episodes in flight: worker processes (default 1), or with Dask tasks submitted "
            "at once (default: the cluster's worker threads)."
        ),
    ] = None,
    scheduler: Annotated[
        str | None,
        typer.Option(
            help="Run episodes on the Dask scheduler at this address (e.g. tcp://host:8786)."
        ),
    ] = None,
    dask_local: Annotated[
        int | None,
        typer.Option(help="Run episodes on a local Dask cluster of this many worker processes."),
    ] = None,
    scheduler_timeout: Annotated[
        float, typer.Option(help="Seconds to wait for the --scheduler to answer.")
    ] = 10.0,
    db: Annotated[Path, typer.Option(help="SQLite results file (resumable).")] = Path(
        "results/benchmark.db"
    ),
    out: Annotated[Path, typer.Option(help="Folder for tables and figures.")] = Path(
        "results/benchmark"
    ),
    json_path: Annotated[Path | None, typer.Option("--json", help="Write a JSON summary.")] = None,
    figure_planners: Annotated[
        str | None,
        typer.Option(help="Planners drawn side by side on the first scenario (default: all)."),
    ] = None,
    figure_targets: Annotated[
        int | None,
        typer.Option(help="Number of targets of the figure's scenario (default: the largest)."),
    ] = None,
    metric: Annotated[
        str,
        typer.Option(
            help="The metric the tables, the summary CSV and --json report: U, gospa_mean, "
            "gospa_end, track_loss or never_detected."
        ),
    ] = "U",
) -> None:
    """Run the multi-target benchmark (paper Tables II-III); results are stored as they finish."""
    from hptrack.experiments.benchmark import (
        BenchmarkConfig,
        check_effort,
        check_metric,
        motion_label,
        run_benchmark,
        scenario_for,
        summarise,
    )
    from hptrack.experiments.store import ResultStore
    from hptrack.registry import check_team, planner_entry

    check_seed(first_seed, "--first-seed")
    if scenarios < 1:
        raise InputError(f"--scenarios must be a positive integer, got {scenarios}")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be a positive integer, got {workers}")
    if not 1 <= scenarios <= MAX_SCENARIOS:
        raise InputError(f"--scenarios must be between 1 and {MAX_SCENARIOS:,}, got {scenarios}")
    dask = scheduler is not None or dask_local is not None
    if dask:
        from hptrack.experiments.dask_cluster import check_dask_options

        check_dask_options(scheduler, dask_local, scheduler_timeout)
    check_effort(iterations, time_limit)
    check_metric(metric)
    names = tuple(dict.fromkeys(p.strip() for p in planners.split(",") if p.strip()))
    if not names:
        raise InputError(f"--planners expects planner names, got {planners!r}")
    for name in names:
        planner_entry(name)
    counts = _int_list(targets, "--targets")
    if workers is not None and not dask:
        workers = check_workers(workers, scenarios * len(counts) * len(names))
    settings = planner_settings_for(names, option, iterations, time_limit)
    for name in (figure_planners or "").split(","):
        if name.strip() and name.strip() not in names:
            raise InputError(f"--figure-planners: {name.strip()!r} is not among --planners")
    if figure_targets is not None and figure_targets not in counts:
        raise InputError(f"--figure-targets {figure_targets} is not among --targets {targets}")
    check_output_dir(out, "--out")
    check_output_path(json_path, "--json")
    config = BenchmarkConfig(
        planners=names,
        settings=settings,
        target_counts=counts,
        scenarios=scenarios,
        homogeneous=homogeneous,
        first_seed=first_seed,
        process_noise_form=process_noise_form,
        motion="" if motion_label(motion) is None else motion,
        detection_probability=detection_probability,
        blind=blind,
        no_fly=no_fly,
        team=team,
        labelled=not unlabelled,
        false_alarm_density=false_alarm_density,
        detection_correlation_time=detection_correlation_time,
    )
    check_team(names, team)
    scenario_for(config.keys()[0])  # a bad --motion value is refused before any work
    with ExitStack() as stack:
        store = ResultStore(db)
        stack.callback(store.close)
        executor, in_flight = None, workers or 1
        if dask:
            from hptrack.experiments.dask_cluster import dask_executor

            pool = stack.enter_context(dask_executor(scheduler, dask_local, scheduler_timeout))
            if workers is None and pool.threads == 0:
                raise InputError(
                    f"--scheduler {scheduler}: the cluster has no workers yet; "
                    "give --workers N (episodes in flight)"
                )
            executor, in_flight = pool.executor, workers or pool.threads
            console.print(
                f"Dask scheduler {escape(pool.address)}: {pool.threads} worker "
                f"threads, {in_flight} episodes in flight"
            )
        with progress_display(
            "benchmark",
            "episodes",
            TextColumn("[bold]benchmark"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.description}"),
        ) as progress:
            task = progress.add_task("", total=None)

            def on_done(row, finished, total):
                progress.update(
                    task,
                    completed=finished,
                    total=total,
                    description=f"{row.key.planner} n={row.key.n_targets} "
                    f"seed={row.key.seed}: U={row.uncertainty:.2f}",
                )

            def on_wait(stored, total):
                progress.update(
                    task,
                    completed=stored,
                    total=total,
                    description=f"waiting for {total - stored} episodes that another "
                    "run on this database holds",
                )

            try:
                ran = run_benchmark(
                    config, store, in_flight, on_done, executor=executor, on_wait=on_wait
                )
            except KeyboardInterrupt:
                error_console.print(
                    f"interrupted: the episodes finished so far are kept in {db}; run the same "
                    "command again to resume",
                    markup=False,
                    highlight=False,
                    soft_wrap=True,
                )
                raise
            keys = set(config.keys())
            rows = [r for r in store.rows() if r.key in keys]
    console.print(f"{ran} episodes run now, {len(rows)} of {len(keys)} in the table ({db})")
    with writing(out, "--out"):
        _write_report(config, rows, out, figure_planners, figure_targets, metric)
    if json_path:
        summary = summarise(rows, config.planners, metric)
        write_json(
            json_path, {p: {str(n): c for n, c in by_n.items()} for p, by_n in summary.items()}
        )


def _write_report(
    config,
    rows,
    out: Path,
    figure_planners: str | None,
    figure_targets: int | None,
    metric: str,
) -> None:
    from rich.markdown import Markdown

    from hptrack.experiments.benchmark import planner_for, planner_mission_for, scenario_for
    from hptrack.experiments.report import benchmark_report, write_csv
    from hptrack.experiments.store import EpisodeKey
    from hptrack.sim.episode import run_episode
    from hptrack.viz.benchmark import plot_trajectories, save_uncertainty_boxes
    from hptrack.viz.style import new_figure, save_figure

    out.mkdir(parents=True, exist_ok=True)
    text = benchmark_report(config, rows, metric)
    (out / "table.md").write_text(text)
    write_csv(rows, out / "episodes.csv", metric)
    console.print(Markdown(text))
    if rows:
        save_uncertainty_boxes(
            rows,
            out / "uncertainty_boxes.png",
            config.planners,
            f"U per planner at the budget's end ({config.setting} setting)",
        )
    names = (
        [p.strip() for p in figure_planners.split(",")]
        if figure_planners
        else list(config.planners)
    )
    n_figure = figure_targets or max(config.target_counts)
    records = []
    for name in names:
        key = EpisodeKey(
            name, n_figure, config.first_seed, config.setting, config.settings[name].canonical()
        )
        scenario = scenario_for(key)
        told = planner_mission_for(key, scenario)
        records.append(run_episode(scenario, planner_for(key), planner_mission=told))
    fig = new_figure(6.0 * len(names) + 1.0, 7.0)
    plot_trajectories(fig, records)
    save_figure(fig, out / "trajectories.png", dpi=110)
    console.print(f"tables and figures written to {out}")


def register(app: typer.Typer) -> None:
    """Add the ``benchmark`` command to ``app``."""
    app.command("benchmark")(benchmark)
