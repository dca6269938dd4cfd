"""Benchmark figures: box plots of ``U`` per planner for each number of targets."""

from __future__ import annotations

from matplotlib.axes import Axes

from hptrack.experiments.store import EpisodeRow


def plot_uncertainty_boxes(ax: Axes, rows: list[EpisodeRow], n_targets: int) -> dict:
    """Box plot of ``U`` per planner for ``n_targets`` targets on ``ax``."""
    by_planner: dict[str, list[float]] = {}
    for r in rows:
        if r.key.n_targets == n_targets:
            by_planner.setdefault(r.key.planner, []).append(r.uncertainty)
    names = sorted(by_planner)
    artists = ax.boxplot([by_planner[p] for p in names], tick_labels=names)
    ax.set_title(f"n = {n_targets}")
    ax.set_ylabel("U (sum of log det, lower is better)")
    return artists
