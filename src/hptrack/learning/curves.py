"""Training-curve figure of a learning run (``curve.json`` of `hptrack.learning.train` or
`hptrack.learning.sb3`), titled from the run's ``config.json``, in
`hptrack.viz.style`'s style."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from hptrack.interface import InputError
from hptrack.viz.style import legend_below, new_figure, save_figure, style_axes


def load_curve(run: Path) -> list[dict[str, Any]]:
    """The curve entries of run folder ``run``."""
    path = Path(run) / "curve.json"
    if not path.is_file():
        raise InputError(f"run folder {run}: no curve.json (has the run saved a checkpoint?)")
    return json.loads(path.read_text())


def run_title(run: Path) -> str:
    """``Deep ADFQ, n = 4 targets, heterogeneous setting, 50 validation scenarios`` from the
    run's ``config.json`` (the folder's name without one)."""
    path = Path(run) / "config.json"
    if not path.is_file():
        return Path(run).name
    config = json.loads(path.read_text())
    task, train = config.get("task", {}), config.get("train", {})
    algorithm = "PPO (stable-baselines3)" if train.get("algorithm") == "PPO" else "Deep ADFQ"
    parts = [algorithm]
    if "n_targets" in task:
        parts.append(f"n = {task['n_targets']} targets")
    if "setting" in task:
        parts.append(f"{task['setting']} setting")
    if "validation_scenarios" in task:
        parts.append(f"{task['validation_scenarios']} validation scenarios")
    return ", ".join(parts)


def plot_training_curve(
    ax: Axes, curve: list[dict[str, Any]], label: str = "validation", window: int = 10
) -> dict[str, Any]:
    """Gap to the never-observed score, ``Delta U = U - U_never`` (lower is better; 0 is a
    policy that never re-acquires a target after the start), against environment steps: each
    training episode (dots, its own scenario) with a running mean over ``window`` episodes,
    and the mean over the fixed validation scenarios with its standard error. Returns the
    artists by name (a legend is the caller's: `save_training_curve` puts it below)."""
    episodes = [e for e in curve if e["kind"] == "episode"]
    validations = [e for e in curve if e["kind"] == "validation"]
    artists: dict[str, Any] = {
        "zero": ax.axhline(0.0, color="tab:red", ls="--", lw=1, label="never observed (ΔU = 0)")
    }
    if episodes:
        steps = np.array([e["step"] for e in episodes])
        gap = np.array([e["U"] - e["never_observed_U"] for e in episodes])
        artists["episodes"] = ax.scatter(
            steps, gap, s=6, alpha=0.35, color="tab:gray", label="training episodes"
        )
        if len(gap) >= window:
            running = np.convolve(gap, np.ones(window) / window, mode="valid")
            artists["running"] = ax.plot(
                steps[window - 1 :], running, color="tab:gray", label=f"training, mean of {window}"
            )[0]
    if validations:
        artists["validation"] = ax.errorbar(
            [e["step"] for e in validations],
            [e["mean_delta_U"] for e in validations],
            yerr=[e["sem_delta_U"] for e in validations],
            marker="o",
            ms=3,
            capsize=2,
            color="tab:blue",
            label=f"{label} mean (± s.e.)",
        )
    ax.set_xlabel("environment steps (τ = 0.5 s each)")
    ax.set_ylabel("ΔU = U − U never observed\n(sum of log det Σxy, m²; lower is better)")
    style_axes(ax)
    return artists


def save_training_curve(run: Path, path: Path, title: str | None = None) -> None:
    """Write the training curve of run folder ``run`` to ``path``, titled ``title`` or
    `run_title`, with the legend below."""
    fig = new_figure(7.5, 4.8)
    ax = fig.add_subplot()
    artists = plot_training_curve(ax, load_curve(run))
    style_axes(ax, title if title is not None else run_title(run), grid=False)
    legend_below(fig, list(artists.values()), ncol=4)
    save_figure(fig, path)
