"""``hptrack coverage`` and ``hptrack validate-coverage``: one coverage sub-task, and the
estimator-accuracy experiment of the paper's Sec. V-A (Table I, Fig. 5)."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import typer
from pydantic import TypeAdapter, ValidationError
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

from hptrack.cli.common import (
    check_figure_path,
    check_memory,
    check_output_dir,
    check_output_path,
    check_seed,
    check_workers,
    console,
    progress_display,
    write_json,
    writing,
)
from hptrack.coverage import CoverageSubtask
from hptrack.experiments.coverage_validation import (
    RUN_BYTES,
    ValidationConfig,
    case_rows,
    draw_case,
    mape_json,
    run_validation,
    summarise,
    table_rows,
    write_reports,
)
from hptrack.interface import InputError, MissionSpec, one_line, shown
from hptrack.models.motion import ProcessNoiseForm
from hptrack.models.sensor import certain
from hptrack.models.sensor import detection_table as checked_detection
from hptrack.models.state import state_from, velocities
from hptrack.scenario import load_scenario
from hptrack.scenario.model import MAX_DETECTION_CORRELATION_TIME, MotionSpec

MAX_DELAY_S = 3600.0
"""Longest departure delay of ``validate-coverage``, s (an hour; the paper's budget is 900 s)."""
MAX_CASES = 1_000_000
"""Most ``validate-coverage`` cases (the paper uses 1000)."""
MAX_RUNS = 10_000_000
"""Most sampled trajectories per case and delay (the paper uses 10,000)."""


def _whole_steps(seconds: float, time_step: float, name: str, longest: float) -> int:
    if not (math.isfinite(seconds) and 0 <= seconds <= longest):
        raise InputError(f"{name} must be between 0 and {longest:g} s, got {seconds}")
    steps = round(seconds / time_step)
    if seconds < 0 or abs(seconds / time_step - steps) > 1e-9:
        raise InputError(
            f"{name} {seconds:g} s is not a non-negative whole number of {time_step:g} s steps"
        )
    return steps


def _parse_delays(text: str) -> tuple[float, ...]:
    try:
        values = tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise InputError(f"--delays expects comma-separated seconds, got {text!r}") from None
    if not values or not all(math.isfinite(v) and v >= 0 for v in values):
        raise InputError(f"--delays expects finite non-negative seconds, got {text!r}")
    return values


def coverage(
    scenario_path: Annotated[Path, typer.Argument(metavar="SCENARIO", help="Scenario YAML file.")],
    target: Annotated[str, typer.Option(help="Id of the target to search for.")],
    delay: Annotated[float, typer.Option(help="Seconds the agent waits at its start first.")] = 0.0,
    json_path: Annotated[
        Path | None,
        typer.Option("--json", help="Write the plan: estimate, CDF per step, planned positions."),
    ] = None,
    plot: Annotated[Path | None, typer.Option(help="Write the plan figure (PNG).")] = None,
) -> None:
    """Plan one coverage sub-task (intercept + shifting spiral) and print its estimate."""
    check_output_path(json_path, "--json")
    check_figure_path(plot, "--plot")
    scenario = load_scenario(scenario_path)
    mission = scenario.mission_spec()
    if target not in mission.target_ids:
        raise InputError(
            f"--target {target!r} is not a target of {scenario_path}; targets are "
            f"{list(mission.target_ids)}"
        )
    i = mission.target_ids.index(target)
    if math.isfinite(delay) and delay >= mission.budget:
        raise InputError(f"--delay {delay:g} s leaves no budget (budget {mission.budget:g} s)")
    d = _whole_steps(delay, mission.time_step, "--delay", mission.budget)
    q = float(mission.process_noise[i])
    means, covs = mission.motion.predict(
        scenario.means()[i : i + 1], scenario.covariances()[i : i + 1], q, d * mission.time_step
    )
    subtask = CoverageSubtask(
        np.asarray(scenario.agent.position),
        means[0],
        covs[0],
        q,
        mission,
        mission.budget - delay,
        i,
        d,
    )
    est, sharp = subtask.estimate, subtask.sharp_estimate
    table = Table(title=escape(f"coverage of {target} after waiting {delay:g} s"))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in (
        ("intercept flight", f"{subtask.intercept_time:.1f} s"),
        ("t_cutoff (from coverage start)", f"{est.cutoff_time:.1f} s"),
        ("p_find", f"{est.p_find:.4f}"),
        ("E[T_find] (from coverage start)", f"{est.expected_time:.2f} s"),
        ("cut by the budget", "yes" if est.budget_limited else "no"),
        ("sharp p_find (flight included)", f"{sharp.p_find:.4f}"),
        ("sharp E[duration | find] (from departure)", f"{sharp.expected_time:.2f} s"),
    ):
        table.add_row(name, value)
    console.print(table)
    positions = subtask.planned_positions()
    if json_path:
        write_json(
            json_path,
            {
                "target": target,
                "delay": delay,
                "time_step": mission.time_step,
                "agent_speed": mission.agent_speed,
                "sensor_diameter": mission.sensor.sensor_diameter,
                "process_noise_form": mission.process_noise_form,
                "belief_at_departure": {
                    "mean": means[0].tolist(),
                    "covariance": covs[0].tolist(),
                    "process_noise": q,
                },
                "intercept_time": subtask.intercept_time,
                "intercept_steps": subtask.intercept.steps,
                "t_cutoff": est.cutoff_time,
                "cutoff_steps": est.cutoff_steps,
                "p_find": est.p_find,
                "expected_time": est.expected_time,
                "budget_limited": est.budget_limited,
                "cdf": est.cdf.tolist(),
                "positions": positions.tolist(),
                "sharp_p_find": sharp.p_find,
                "sharp_expected_time": sharp.expected_time,
            },
        )
    if plot:
        from hptrack.viz.coverage import save_plan_figure

        n = subtask.intercept.steps
        start_mean = subtask.intercept.start
        if mission.motion.straight:
            start_state = state_from(start_mean, velocities(means[0]))
        else:  # the whole mean state predicted to the coverage's start
            start_state = mission.motion.predict(means[:1], covs[:1], q, n * mission.time_step)[0][
                0
            ]
        end_mean, end_cov = mission.motion.predict(
            start_state[None], subtask.start_covariance[None], q, est.cutoff_time
        )
        with writing(plot, "--plot"):
            save_plan_figure(
                str(plot),
                positions,
                n,
                start_mean,
                subtask.start_covariance[:2, :2],
                end_mean[0, :2],
                end_cov[0, :2, :2],
                est.cdf,
                mission.time_step,
                title=f"coverage sub-task of target {target} after waiting {delay:g} s",
            )
        console.print(f"figure written to {plot}")


MOTION_ADAPTER: TypeAdapter[MotionSpec] = TypeAdapter(MotionSpec)

MotionName = Literal[
    "constant_velocity", "random_walk", "ornstein_uhlenbeck", "singer", "constant_acceleration"
]
"""The belief motions ``validate-coverage`` offers (`hptrack.scenario.model.MotionSpec`)."""


def motion_of(name: str, process_noise_form: str, **parameters: float | None) -> MotionSpec | None:
    """The scenario ``motion:`` spec of ``--motion`` and its ``parameters`` (the options'
    values by field name; ``None``: the model's default). ``None`` for constant velocity, the
    default.

    Raises:
        InputError: a parameter out of its range, or given to a model without it, naming the
            option.
    """
    given = {field: value for field, value in parameters.items() if value is not None}
    if name == "constant_velocity":
        if given:
            field = next(iter(given))
            raise InputError(f"--{field.replace('_', '-')} is not a parameter of --motion {name}")
        return None
    if process_noise_form != "continuous":
        raise InputError(
            f"--process-noise-form {process_noise_form} is a form of constant velocity's Q, "
            f"not of --motion {name}"
        )
    fields = type(MOTION_ADAPTER.validate_python({"model": name})).model_fields
    for field in given:
        if field not in fields:
            raise InputError(f"--{field.replace('_', '-')} is not a parameter of --motion {name}")
    data = {"model": name, **given}
    try:
        return MOTION_ADAPTER.validate_python(data)
    except ValidationError as err:
        field = str(err.errors()[0]["loc"][-1])
        reason = one_line(err.errors()[0]["msg"])
        value = data.get(field)
        raise InputError(f"--{field.replace('_', '-')}: {reason} (value {shown(value)})") from None


def detection_of(probability: float, table: str | None) -> float | tuple[tuple[float, float], ...]:
    """The ``detection_probability`` of ``--detection-probability`` or ``--detection-table``
    (comma-separated ``distance_m:Pd`` rows, e.g. ``0:0.9,30:0.8,50:0.5``); 1 when neither.

    Raises:
        InputError: both given, a row that is not two numbers, or a value the sensor refuses
            (`hptrack.models.sensor.detection_table`), naming the option.
    """
    if table is None:
        try:
            checked_detection(probability)
        except ValueError as err:
            raise InputError(f"--detection-probability: {err}") from None
        return float(probability)
    if probability != 1.0:
        raise InputError("give --detection-probability or --detection-table, not both")
    rows = []
    for part in table.split(","):
        cells = part.split(":")
        try:
            if len(cells) != 2:
                raise ValueError
            rows.append((float(cells[0]), float(cells[1])))
        except ValueError:
            raise InputError(
                f"--detection-table expects comma-separated distance_m:Pd rows, got {table!r}"
            ) from None
    try:
        checked_detection(rows)
    except ValueError as err:
        raise InputError(f"--detection-table: {err}") from None
    return tuple(rows)


def validate_coverage(
    cases: Annotated[int, typer.Option(help="Random single-target cases.")] = 1000,
    runs: Annotated[int, typer.Option(help="Sampled trajectories per case and delay.")] = 10000,
    delays: Annotated[
        str, typer.Option(help="Departure delays t_d, s, comma-separated.")
    ] = "0,100,200",
    seed: Annotated[int, typer.Option(help="Root seed.")] = 0,
    out: Annotated[
        Path, typer.Option(help="Results folder (resumed if it holds cases.csv).")
    ] = Path("results/coverage-validation"),
    workers: Annotated[int, typer.Option(help="Worker processes.")] = 1,
    json_path: Annotated[
        Path | None,
        typer.Option("--json", help="Write {delay: {mape_p_find, mape_expected_time}} (percent)."),
    ] = None,
    process_noise_form: Annotated[
        ProcessNoiseForm, typer.Option(help="Q form: continuous (default) or paper_text.")
    ] = "continuous",
    sample_case: Annotated[int, typer.Option(help="Case drawn in the CDF figure.")] = 0,
    motion: Annotated[
        MotionName,
        typer.Option(help="The targets' motion, for beliefs and truth alike."),
    ] = "constant_velocity",
    diffusion: Annotated[
        float | None,
        typer.Option(help="random_walk: position variance per second per axis, m^2/s [5]."),
    ] = None,
    damping: Annotated[
        float | None,
        typer.Option(
            help="ornstein_uhlenbeck: the velocity's decay rate [0.01]; singer: the "
            "acceleration's [0.02], 1/s."
        ),
    ] = None,
    acceleration_std: Annotated[
        float | None,
        typer.Option(
            help="singer: the acceleration's stationary spread [0.002]; constant_acceleration: "
            "its prior spread [0.001], m/s^2 per axis."
        ),
    ] = None,
    jerk_intensity: Annotated[
        float | None,
        typer.Option(help="constant_acceleration: the white jerk's intensity, m^2/s^5 [1e-8]."),
    ] = None,
    budget: Annotated[
        float | None,
        typer.Option(
            help="Mission budget, s from the start (delay included); needed by every motion "
            "but constant_velocity, whose P_cdf may never stop rising."
        ),
    ] = None,
    detection_probability: Annotated[
        float,
        typer.Option(
            help="Chance that a look detects a target inside the footprint, each step "
            "independently, in (0, 1] (1: the paper's sensor); estimators and runs alike."
        ),
    ] = 1.0,
    detection_table: Annotated[
        str | None,
        typer.Option(
            help="Pd by distance from the footprint's centre instead: comma-separated "
            "distance_m:Pd rows from 0 m, e.g. 0:0.9,30:0.8,50:0.5 (linear, the last held)."
        ),
    ] = None,
    detection_correlation_time: Annotated[
        float,
        typer.Option(
            help="Seconds one detection draw holds while the target stays in the footprint "
            "(0: independent looks; needs a detection probability below 1)."
        ),
    ] = 0.0,
) -> None:
    """Estimator-accuracy experiment (paper Sec. V-A): MAPE of P_find and E[T_find] per delay,
    for the paper's estimator and the sharp one on the same simulated runs."""
    check_seed(seed)
    detection = detection_of(detection_probability, detection_table)
    hold = detection_correlation_time
    if not (math.isfinite(hold) and 0.0 <= hold <= MAX_DETECTION_CORRELATION_TIME):
        raise InputError(
            f"--detection-correlation-time must be between 0 and "
            f"{MAX_DETECTION_CORRELATION_TIME:g} s, got {shown(hold)}"
        )
    if hold > 0.0 and certain(detection):
        raise InputError(
            "--detection-correlation-time needs a detection probability below 1 (no misses to "
            "correlate)"
        )
    motion_spec = motion_of(
        motion,
        process_noise_form,
        diffusion=diffusion,
        damping=damping,
        acceleration_std=acceleration_std,
        jerk_intensity=jerk_intensity,
    )
    if motion != "constant_velocity" and budget is None:
        raise InputError(
            f"--motion {motion} needs a --budget (s): its P_cdf may never stop rising, so "
            "t_cutoff may never come"
        )
    if budget is not None and not (math.isfinite(budget) and 0.0 < budget <= MAX_DELAY_S * 10):
        raise InputError(f"--budget must be in (0, {MAX_DELAY_S * 10:g}] s, got {shown(budget)}")
    for value, name, most in ((cases, "--cases", MAX_CASES), (runs, "--runs", MAX_RUNS)):
        if not 1 <= value <= most:
            raise InputError(f"{name} must be between 1 and {most:,}, got {shown(value)}")
    workers = check_workers(workers, cases)
    for delay in _parse_delays(delays):
        _whole_steps(delay, MissionSpec().time_step, "--delays", MAX_DELAY_S)
    check_memory(workers * runs * RUN_BYTES, f"--runs {runs} on {workers} worker(s)")
    check_output_dir(out, "--out")
    check_output_path(json_path, "--json")
    config = ValidationConfig(
        cases=cases,
        runs=runs,
        delays=_parse_delays(delays),
        seed=seed,
        mission=MissionSpec(
            process_noise_form=process_noise_form,
            detection_probability=detection,
            detection_correlation_time=hold,
        ),
        motion=motion_spec,
        budget=budget,
    )
    if not 0 <= sample_case < cases:
        raise InputError(f"--sample-case {sample_case} is not among the {cases} cases")
    for delay in config.delays:
        if budget is not None and delay >= budget:
            raise InputError(f"--delays {delay:g} s is not before --budget {budget:g} s")
    sensing = "" if detection == 1.0 else f"detection probability: {detection}; "
    console.print(
        f"motion: {motion}; Q form: {process_noise_form}; {sensing}{cases} cases x "
        f"{len(config.delays)} delays x {runs} runs; {workers} worker(s); results in {out}"
    )
    start = time.perf_counter()
    with progress_display(
        "validation",
        "cases",
        TextColumn("[bold]cases"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
    ) as progress:
        task = progress.add_task("", total=cases)
        rows = run_validation(
            config, out, workers, on_case=lambda done, total: progress.update(task, completed=done)
        )
    wall = time.perf_counter() - start
    summary = summarise(rows, config.delays)
    write_reports(summary, out, wall)
    _print_table(summary, wall)
    from hptrack.viz.coverage import save_cdf_figure

    _, panels = case_rows(draw_case(sample_case, seed), config, keep_times=True)
    figure = out / f"cdf-case-{sample_case}.png"
    save_cdf_figure(
        panels, str(figure), title=f"case {sample_case}: estimated against simulated ({runs} runs)"
    )
    console.print(
        f"tables in {out}/mape.md, mape.csv and mape-both.json, per-case rows in "
        f"{out}/cases.csv, figure {figure}"
    )
    if json_path:
        write_json(json_path, mape_json(summary))


TERMINAL_COLUMNS = (
    "t_d (s)",
    "cases",
    "P_find: paper's estimator",
    "sharp",
    "paper's Table I (published)",
    "E[T_find]: paper's estimator",
    "sharp",
    "paper's Table I (published)",
)
"""Headers of ``validate-coverage``'s terminal table (`table_rows`' cells)."""


def _print_table(summary: dict, wall: float) -> None:
    table = Table(
        title=f"coverage estimator accuracy (MAPE, %), {wall:.0f} s",
        caption="E[T_find]: paper's estimator from the coverage start; sharp: "
        "sub-task duration from departure; paper's Table I: the numbers it published",
    )
    for name in TERMINAL_COLUMNS:
        table.add_column(name, justify="right")
    for row in table_rows(summary):
        table.add_row(*row)
    console.print(table)


def register(app: typer.Typer) -> None:
    """Add the ``coverage`` and ``validate-coverage`` commands to ``app``."""
    app.command("coverage")(coverage)
    app.command("validate-coverage")(validate_coverage)
