"""``hptrack learn``: train Deep ADFQ or stable-baselines3 PPO on ``hptrack/Tracking-v0``,
resumable (the same command continues a killed run), and draw a run's training curve."""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from hptrack.cli.common import (
    check_figure_path,
    check_memory,
    check_output_dir,
    check_seed,
    console,
    error_console,
    progress_display,
)
from hptrack.interface import InputError
from hptrack.models.mission import MAX_TARGETS

learn_app = typer.Typer(
    help="Train learning baselines on hptrack/Tracking-v0 (resumable).", no_args_is_help=True
)

MAX_TRAINING_STEPS = 10**10
"""Most environment steps of one training run (about a year at 300 steps per second)."""
MAX_VALIDATION_SCENARIOS = 10_000
"""Most validation scenarios (at about 2 s per 50, a validation of 10,000 takes 7 min)."""
PROGRESS_EVERY = 250
"""Steps between progress-bar refreshes."""

Targets = Annotated[int, typer.Option(help="Number of targets (one model per number).")]
Steps = Annotated[int, typer.Option(help="Environment steps to train in total.")]
Out = Annotated[
    Path,
    typer.Option(
        help="Run folder (checkpoints, best model, curve); rerunning the command resumes it."
    ),
]
Seed = Annotated[int, typer.Option(help="Seed of the run.")]
Homogeneous = Annotated[
    bool,
    typer.Option(
        "--homogeneous/--heterogeneous",
        help="Shared q and prior (homogeneous) or drawn per target (heterogeneous, the paper's "
        "Table III); default heterogeneous.",
    ),
]
ValidationScenarios = Annotated[
    int, typer.Option(help="Fixed validation scenarios (seeds 1e9 + i).")
]
ValidationInterval = Annotated[int, typer.Option(help="Steps between validations.")]
CheckpointInterval = Annotated[
    int, typer.Option(help="Least steps between checkpoints (taken at episode or rollout ends).")
]


def _require_learn_extra() -> None:
    try:
        import gymnasium  # noqa: F401
        import torch  # noqa: F401
    except ModuleNotFoundError as err:
        raise InputError(
            f"hptrack learn needs the learn extra ({err.name} is missing): "
            "pip install 'hptrack[learn]'"
        ) from None


def _check_common(
    targets: int,
    steps: int,
    seed: int,
    out: Path,
    validation_scenarios: int,
    validation_interval: int,
    checkpoint_interval: int,
) -> None:
    if not 1 <= targets <= MAX_TARGETS:
        raise InputError(f"--targets must be between 1 and {MAX_TARGETS}, got {targets}")
    if not 1 <= steps <= MAX_TRAINING_STEPS:
        raise InputError(f"--steps must be between 1 and {MAX_TRAINING_STEPS:g}, got {steps}")
    check_seed(seed)
    for option, value in (
        ("--validation-scenarios", validation_scenarios),
        ("--validation-interval", validation_interval),
        ("--checkpoint-interval", checkpoint_interval),
    ):
        if value < 1:
            raise InputError(f"{option} must be at least 1, got {value}")
    if validation_scenarios > MAX_VALIDATION_SCENARIOS:
        raise InputError(
            f"--validation-scenarios must be at most {MAX_VALIDATION_SCENARIOS:,}, "
            f"got {validation_scenarios}"
        )
    if out.exists() and not out.is_dir():
        raise InputError(f"--out {out}: is a file, not a folder")


@contextmanager
def _run_folder(out: Path) -> Iterator[None]:
    """Create the run folder ``out`` (one line if it cannot be), and remove the folders this
    made again when the command is refused before writing anything into them."""
    made = [p for p in (out, *out.parents) if not p.exists()]
    check_output_dir(out, "--out")
    try:
        yield
    except InputError:
        for folder in made:  # deepest first; only empty ones
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def _train(trainer: Any, name: str, out: Path, total: int) -> dict[str, Any]:
    """Run ``trainer`` to ``total`` steps with a progress display, then draw its curve."""
    columns = (
        TextColumn(f"[bold]{escape(name)}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        TextColumn("{task.description}"),
    )
    start = time.perf_counter()
    with progress_display(name, "steps", *columns) as progress:
        task = progress.add_task("", total=total)

        def on_progress(p) -> None:
            if p.step % PROGRESS_EVERY == 0 or p.step >= total:
                progress.update(
                    task,
                    completed=p.step,
                    description=(
                        f"episodes {p.episodes}  return(10) {p.recent_return:.3f}  "
                        f"validation U {p.validation_u:.2f}  best {p.best_u:.2f}"
                    ),
                )

        summary = trainer.run(on_progress)
    console.print(
        f"{name}: {summary['steps']} steps, {summary['episodes']} episodes, "
        f"{time.perf_counter() - start:.0f} s this session; best validation U "
        f"{summary['best_U']:.3f} at step {summary['best_step']}"
        f"{' (untrained)' if summary['best_untrained'] else ''}; last "
        f"{summary['last_validation_U']:.3f}; model {escape(summary['best_model'])}"
    )
    if summary["best_untrained"]:
        error_console.print(
            f"warning: no validation of the trained policy beat the untrained one (best at step "
            f"{summary['best_step']}, before any learning): {summary['best_model']} is the "
            "untrained policy; train longer (a larger --steps resumes this run)",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
    _write_figure(out, out / "curve.png")
    return summary


def _write_figure(run: Path, path: Path, title: str | None = None) -> None:
    from hptrack.learning.curves import save_training_curve

    save_training_curve(run, path, title)
    console.print(f"training curve written to {escape(str(path))}")


@learn_app.command("adfq")
def learn_adfq(
    targets: Targets,
    steps: Steps,
    out: Out,
    homogeneous: Homogeneous = False,
    seed: Seed = 0,
    validation_scenarios: ValidationScenarios = 50,
    validation_interval: ValidationInterval = 25_000,
    checkpoint_interval: CheckpointInterval = 10_000,
    warmup: Annotated[int, typer.Option(help="Steps of exploration before learning.")] = 10_000,
    allow_untrained: Annotated[
        bool,
        typer.Option(
            "--allow-untrained",
            help="Run even when --steps is not above --warmup (no learning: the network stays "
            "untrained).",
        ),
    ] = False,
    buffer: Annotated[int, typer.Option(help="Replay capacity, transitions.")] = 200_000,
    prioritized: Annotated[
        bool, typer.Option(help="Prioritised replay (alpha 0.6, beta 0.4 -> 1) instead of uniform.")
    ] = False,
) -> None:
    """Train Deep ADFQ (Thompson sampling, ADFQ posterior targets) on Tracking-v0."""
    _check_common(
        targets, steps, seed, out, validation_scenarios, validation_interval, checkpoint_interval
    )
    if warmup < 0 or buffer < 1:
        raise InputError(f"--warmup must be >= 0 and --buffer >= 1, got {warmup} and {buffer}")
    # two float32 observations (6 features per target, the budget, a mask), action, reward,
    # end flag, and the priority tree's two float64 leaves
    check_memory(buffer * (8 * (7 * targets + 1) + 8 + 8 + 1 + 16), f"--buffer {buffer}")
    _require_learn_extra()
    from hptrack.learning.agent import AdfqConfig
    from hptrack.learning.train import TrainConfig, Trainer, tracking_task

    config = TrainConfig(
        steps=steps,
        seed=seed,
        validation_interval=validation_interval,
        checkpoint_interval=checkpoint_interval,
        agent=AdfqConfig(warmup_steps=warmup, buffer_size=buffer, prioritized=prioritized),
    )
    with _run_folder(out):
        trainer = Trainer(
            tracking_task(targets, homogeneous, validation_scenarios), config, out, allow_untrained
        )
    _train(trainer, f"adfq n={targets}", out, steps)


@learn_app.command("sb3-ppo")
def learn_sb3_ppo(
    targets: Targets,
    steps: Steps,
    out: Out,
    homogeneous: Homogeneous = False,
    seed: Seed = 0,
    validation_scenarios: ValidationScenarios = 50,
    validation_interval: ValidationInterval = 25_000,
    checkpoint_interval: CheckpointInterval = 10_000,
) -> None:
    """Train stable-baselines3 PPO (MlpPolicy, one 1800-step rollout per update) on
    Tracking-v0."""
    _check_common(
        targets, steps, seed, out, validation_scenarios, validation_interval, checkpoint_interval
    )
    _require_learn_extra()
    try:
        import stable_baselines3  # noqa: F401
    except ModuleNotFoundError:
        raise InputError(
            "hptrack learn sb3-ppo needs stable-baselines3: pip install 'hptrack[learn]'"
        ) from None
    from hptrack.learning.sb3 import PpoConfig, PpoTrainer, trained_steps
    from hptrack.learning.train import tracking_task

    config = PpoConfig(
        steps=steps,
        seed=seed,
        validation_interval=validation_interval,
        checkpoint_interval=checkpoint_interval,
    )
    with _run_folder(out):
        trainer = PpoTrainer(tracking_task(targets, homogeneous, validation_scenarios), config, out)
    rounded = trained_steps(steps, config.n_steps)
    if rounded != steps:
        console.print(
            f"PPO trains whole rollouts of {config.n_steps:,} steps: --steps {steps:,} "
            f"trains {rounded:,} steps"
        )
    _train(trainer, f"sb3-ppo n={targets}", out, rounded)


@learn_app.command("plot")
def learn_plot(
    run: Annotated[Path, typer.Argument(help="Run folder of 'hptrack learn'.")],
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="PNG to write (default RUN/curve.png).")
    ] = None,
    title: Annotated[
        str | None,
        typer.Option(help="Figure title (default: algorithm, n, setting from the run's config)."),
    ] = None,
) -> None:
    """Draw a run's training curve: final U of the training episodes and of the validation
    scenarios against steps, with the never-observed U."""
    path = output or run / "curve.png"
    check_figure_path(path, "--output")
    _write_figure(run, path, title)


def register(app: typer.Typer) -> None:
    """Add the ``learn`` command group (``adfq``, ``sb3-ppo``, ``plot``) to ``app``."""
    app.add_typer(learn_app, name="learn")
