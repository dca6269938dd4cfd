"""Mission figure in the style of the paper's Fig. 6: agent path coloured by time, true target
paths, detections and 95 % belief ellipses at a few times. Functions take an Axes and return
artists.

Colours: targets use the categorical ``tab10`` palette without its grey
(:func:`target_color`); the agent's time runs through :data:`AGENT_TIME_CMAP`, light grey to
black, so an agent segment never looks like a target.
"""

from __future__ import annotations

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Colormap, LinearSegmentedColormap, Normalize
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse

from hptrack.sim.record import EpisodeRecord

CONFIDENCE_SCALE_95 = float(np.sqrt(-2.0 * np.log(0.05)))  # chi-squared, 2 dof, 95 %

TARGET_COLORS: tuple[tuple[float, float, float], ...] = tuple(
    c for k, c in enumerate(mpl.colormaps["tab10"].colors) if k != 7
)
"""Target palette: ``tab10`` without its grey (index 7), which the agent's colours use."""

AGENT_TIME_CMAP: Colormap = LinearSegmentedColormap.from_list("agent_time", ["#c4c4c4", "#000000"])
"""Agent time colours: light grey (mission start) to black (budget's end)."""


def target_color(i: int) -> tuple[float, float, float]:
    """Colour of target ``i`` (cycles after nine targets)."""
    return TARGET_COLORS[i % len(TARGET_COLORS)]


def ellipse_axes(
    cov_xy: np.ndarray, scale: float = CONFIDENCE_SCALE_95
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Full width and height (m) and angle (degrees, of the width axis from +x) of the
    ``scale``-sigma ellipse of 2x2 position covariances ``(..., 2, 2)`` (m^2)."""
    values, vectors = np.linalg.eigh(cov_xy)
    values = np.maximum(values, 0.0)
    angle = np.degrees(np.arctan2(vectors[..., 1, 1], vectors[..., 0, 1]))
    return 2.0 * scale * np.sqrt(values[..., 1]), 2.0 * scale * np.sqrt(values[..., 0]), angle


def covariance_ellipse(
    center: np.ndarray, cov_xy: np.ndarray, scale: float = CONFIDENCE_SCALE_95, **kwargs
) -> Ellipse:
    """Ellipse patch of ``scale`` standard deviations of a 2x2 position covariance (m^2)."""
    width, height, angle = ellipse_axes(cov_xy, scale)
    return Ellipse(tuple(center), float(width), float(height), angle=float(angle), **kwargs)


def plot_mission(
    ax: Axes,
    record: EpisodeRecord,
    n_ellipses: int = 4,
    cmap: str | Colormap = AGENT_TIME_CMAP,
    norm: Normalize | None = None,
    legend: bool = True,
) -> dict:
    """Draw one mission on ``ax``; returns the artists by role (``"agent"`` is the
    time-coloured path, the mappable for a colour bar).

    Args:
        ax: target axes (equal aspect is set).
        record: the episode to draw.
        n_ellipses: how many evenly spaced stored times get 95 % belief ellipses (dashed,
            fainter for earlier times).
        cmap: colour map for the agent's time.
        norm: time (s) to colour; default ``0`` to the mission's end.
        legend: draw the legend below the axes.
    """
    times = record.times
    path = record.agent_path
    segments = np.stack([path[:-1], path[1:]], axis=1)
    agent = LineCollection(
        segments, cmap=cmap, norm=norm or Normalize(0.0, times[-1]), linewidths=1.8, zorder=3
    )
    agent.set_array(times[1:])
    ax.add_collection(agent)
    colors = [target_color(i) for i in range(len(record.target_ids))]
    artists: dict = {"agent": agent, "targets": [], "ellipses": [], "detections": []}
    for i, (tid, color) in enumerate(zip(record.target_ids, colors, strict=True)):
        truth = record.true_states[:, i, :2]
        (line,) = ax.plot(truth[:, 0], truth[:, 1], color=color, lw=1.0, label=tid, zorder=2)
        ax.plot(*truth[0], marker="o", color=color, ms=5, zorder=4)
        ax.plot(*truth[-1], marker="s", color=color, ms=5, zorder=4)
        artists["targets"].append(line)
        seen = record.detections[:, i]
        if seen.any():
            artists["detections"].append(
                ax.scatter(
                    truth[seen, 0],
                    truth[seen, 1],
                    s=14,
                    marker="o",
                    facecolors="none",
                    edgecolors=[color],
                    linewidths=0.7,
                    zorder=4,
                )
            )
    n_stored = len(record.belief_steps)
    picks = np.unique(np.linspace(0, n_stored - 1, n_ellipses).round().astype(int))
    for j in picks:
        alpha = 0.25 + 0.6 * j / max(n_stored - 1, 1)
        for i, color in enumerate(colors):
            patch = covariance_ellipse(
                record.belief_means[j, i, :2],
                record.belief_covariances[j, i, :2, :2],
                fill=False,
                edgecolor=color,
                lw=0.9,
                alpha=alpha,
                ls="--",
            )
            ax.add_patch(patch)
            artists["ellipses"].append(patch)
    ax.plot(*path[0], marker="^", color="k", ms=9, ls="none", zorder=5)
    ax.plot(*path[-1], marker="D", color="k", mfc="white", mew=1.5, ms=7, ls="none", zorder=5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{record.planner}: U = {record.uncertainty:.2f}")
    ellipse_times = ", ".join(f"{t:.0f}" for t in record.belief_steps[picks] * record.time_step)
    proxies = [
        Line2D(
            [],
            [],
            color="0.35",
            lw=0.9,
            ls="--",
            label=f"95 % belief ellipse (t = {ellipse_times} s)",
        ),
        Line2D([], [], color="k", marker="^", ms=8, ls="none", label="agent start"),
        Line2D(
            [], [], color="k", marker="D", mfc="white", mew=1.5, ms=6, ls="none", label="agent end"
        ),
        Line2D([], [], color="0.4", marker="o", ms=5, ls="none", label="target start"),
        Line2D([], [], color="0.4", marker="s", ms=5, ls="none", label="target end"),
        Line2D(
            [],
            [],
            color="0.4",
            marker="o",
            mfc="none",
            ms=5,
            mew=0.7,
            ls="none",
            label="target measured",
        ),
    ]
    artists["legend_handles"] = artists["targets"] + proxies
    if legend:
        artists["legend"] = ax.legend(
            handles=artists["legend_handles"],
            loc="upper center",
            bbox_to_anchor=(0.5, -0.1),
            ncol=3,
            fontsize="small",
        )
    return artists


def save_mission_figure(record: EpisodeRecord, path: str, dpi: int = 130) -> None:
    """Write the mission figure (with the agent-time colour bar) to ``path`` (PNG or PDF)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 8.0))
    ax = fig.add_subplot()
    artists = plot_mission(ax, record)
    fig.colorbar(artists["agent"], ax=ax, label="agent time (s)", shrink=0.8)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
