"""Training-curve figure of a learning run (``curve.json`` of :mod:`hptrack.learning.train` or
:mod:`hptrack.learning.sb3`)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes

from hptrack.interface import InputError


def load_curve(run: Path) -> list[dict[str, Any]]:
    """The curve entries of run folder ``run``."""
    path = Path(run) / "curve.json"
    if not path.is_file():
        raise InputError(f"run folder {run}: no curve.json (has the run saved a checkpoint?)")
    return json.loads(path.read_text())


def plot_training_curve(
    ax: Axes, curve: list[dict[str, Any]], label: str = "validation", window: int = 10
) -> dict[str, Any]:
    """Gap to the never-observed score, ``Delta U = U - U_never`` (lower is better; 0 is a
    policy that never re-acquires a target after the start), against environment steps: each
    training episode (dots, its own scenario) with a running mean over ``window`` episodes,
    and the mean over the fixed validation scenarios with its standard error. Returns the
    artists by name."""
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
    ax.set_xlabel("environment steps")
    ax.set_ylabel("ΔU = U − U never observed")
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    return artists
