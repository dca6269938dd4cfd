"""Mission figure in the style of the paper's Fig. 6: agent path coloured by time, true target
paths, and belief ellipses at a few times. Functions take an Axes and return artists."""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.patches import Ellipse

from hptrack.sim.record import EpisodeRecord

CONFIDENCE_SCALE_95 = float(np.sqrt(-2.0 * np.log(0.05)))  # chi-squared, 2 dof, 95 %


def covariance_ellipse(center: np.ndarray, cov_xy: np.ndarray,
                       scale: float = CONFIDENCE_SCALE_95, **kwargs) -> Ellipse:
    """Ellipse patch of ``scale`` standard deviations of a 2x2 position covariance (m^2)."""
    values, vectors = np.linalg.eigh(cov_xy)
    angle = np.degrees(np.arctan2(vectors[1, 1], vectors[0, 1]))
    width, height = 2.0 * scale * np.sqrt(values[::-1])
    return Ellipse(tuple(center), width, height, angle=angle, **kwargs)


def plot_mission(ax: Axes, record: EpisodeRecord, n_ellipses: int = 4,
                 cmap: str = "viridis") -> dict:
    """Draw one mission on ``ax``; returns the artists by role.

    Args:
        ax: target axes (equal aspect is set).
        record: the episode to draw.
        n_ellipses: how many evenly spaced times get 95 % belief ellipses.
        cmap: colour map for the agent's time.
    """
    times = record.times
    path = record.agent_path
    segments = np.stack([path[:-1], path[1:]], axis=1)
    agent = LineCollection(segments, cmap=cmap, linewidths=1.6, zorder=3)
    agent.set_array(times[1:])
    ax.add_collection(agent)
    colors = [f"C{i % 10}" for i in range(len(record.target_ids))]
    artists: dict = {"agent": agent, "targets": [], "ellipses": [], "detections": []}
    for i, (tid, color) in enumerate(zip(record.target_ids, colors, strict=True)):
        truth = record.true_states[:, i, :2]
        (line,) = ax.plot(truth[:, 0], truth[:, 1], color=color, lw=1.0, label=tid)
        ax.plot(*truth[0], marker="o", color=color, ms=4)
        ax.plot(*truth[-1], marker="s", color=color, ms=4)
        artists["targets"].append(line)
        seen = record.detections[:, i]
        if seen.any():
            artists["detections"].append(
                ax.scatter(path[seen, 0], path[seen, 1], s=6, color=color, zorder=4))
    picks = np.unique(np.linspace(0, len(record.belief_steps) - 1, n_ellipses).round().astype(int))
    for j in picks:
        alpha = 0.25 + 0.5 * j / max(len(record.belief_steps) - 1, 1)
        for i, color in enumerate(colors):
            patch = covariance_ellipse(record.belief_means[j, i, :2],
                                       record.belief_covariances[j, i, :2, :2],
                                       fill=False, edgecolor=color, lw=0.8, alpha=alpha, ls="--")
            ax.add_patch(patch)
            artists["ellipses"].append(patch)
    ax.plot(*path[0], marker="^", color="k", ms=7, label="agent start", zorder=5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{record.planner}: U = {record.uncertainty:.2f}")
    ax.legend(loc="best", fontsize="small")
    return artists


def save_mission_figure(record: EpisodeRecord, path: str, dpi: int = 130) -> None:
    """Write the mission figure (with a time colour bar) to ``path`` (PNG or PDF)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 6.5))
    ax = fig.add_subplot()
    artists = plot_mission(ax, record)
    fig.colorbar(artists["agent"], ax=ax, label="time (s)")
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
