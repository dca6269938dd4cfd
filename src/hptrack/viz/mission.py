"""Mission figure in the style of the paper's Fig. 6: agent path coloured by time, true target
paths, detections and 95 % belief ellipses at a few times (one line style per time). Drawing
functions take an Axes and return artists; the style is `hptrack.viz.style`'s.

Colours: targets use the categorical ``tab10`` palette without its grey
(`target_color`); the agent's time runs through `AGENT_TIME_CMAP`, light grey to
black, so an agent segment never looks like a target.
"""

from __future__ import annotations

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.colors import Colormap, LinearSegmentedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerBase, HandlerPatch
from matplotlib.lines import Line2D
from matplotlib.patches import Ellipse, Patch

from hptrack.sim.record import EpisodeRecord
from hptrack.viz.fence import draw_fence
from hptrack.viz.style import (
    DPI,
    colorbar_beside,
    legend_below,
    new_figure,
    save_figure,
    settle_layout,
    style_axes,
)

CONFIDENCE_SCALE_95 = float(np.sqrt(-2.0 * np.log(0.05)))  # chi-squared, 2 dof, 95 %

TARGET_COLORS: tuple[tuple[float, float, float], ...] = tuple(
    c for k, c in enumerate(mpl.colormaps["tab10"].colors) if k != 7
)
"""Target palette: ``tab10`` without its grey (index 7), which the agent's colours use."""

AGENT_TIME_CMAP: Colormap = LinearSegmentedColormap.from_list("agent_time", ["#c4c4c4", "#000000"])
"""Agent time colours: light grey (mission start) to black (budget's end)."""


VEHICLE_COLORS = ("k", "#08306b", "#67000d", "#00441b", "#3f007d", "#7f2704")
"""The end colour of each UAV's time shading (the first: `AGENT_TIME_CMAP`'s black), in turn."""


def vehicle_color(j: int) -> str:
    """UAV ``j``'s colour (its path's shade at the budget's end)."""
    return VEHICLE_COLORS[j % len(VEHICLE_COLORS)]


def vehicle_cmap(j: int) -> Colormap:
    """UAV ``j``'s time colours: light to `vehicle_color` (the first UAV's: `AGENT_TIME_CMAP`)."""
    if j % len(VEHICLE_COLORS) == 0:
        return AGENT_TIME_CMAP
    return LinearSegmentedColormap.from_list(f"uav{j}", ["0.88", vehicle_color(j)])


def vehicle_label(j: int, team: bool) -> str:
    """How the legend names UAV ``j`` (``agent`` when it flies alone)."""
    return f"UAV {j + 1}" if team else "agent"


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


ELLIPSE_LINESTYLES = (":", "-.", "--", "-")
"""Line styles of the belief ellipses from the earliest time drawn to the latest (cycled)."""


def mission_title(record: EpisodeRecord) -> str:
    """``planner, n = 4 targets, seed 0, 900 s`` over ``U = ... (Σ log det Σxy, Σxy in m²)``."""
    return (
        f"{record.planner}, n = {len(record.target_ids)} targets, seed {record.seed}, "
        f"{record.times[-1]:g} s\nU = {record.uncertainty:.2f} (Σ log det Σxy, Σxy in m²)"
    )


class _TimeShadedKey(HandlerBase):
    """Legend key of the agent's path: a short line shaded through the path's colour map."""

    def create_artists(
        self, legend, orig_handle, xdescent, ydescent, width, height, fontsize, trans
    ):
        x = np.linspace(-xdescent, width - xdescent, 9)
        y = np.full_like(x, height / 2.0 - ydescent)
        key = LineCollection(
            np.stack([np.column_stack([x[:-1], y[:-1]]), np.column_stack([x[1:], y[1:]])], 1),
            cmap=orig_handle.get_cmap(),
            norm=Normalize(0.0, 1.0),
            linewidths=orig_handle.get_linewidths(),
            transform=trans,
        )
        key.set_array(np.linspace(0.0, 1.0, 8))
        return [key]


def _ellipse_key(legend, orig_handle, xdescent, ydescent, width, height, fontsize) -> Ellipse:
    """Legend key of a belief ellipse: a small ellipse in the handle's line style."""
    center = (width / 2.0 - xdescent, height / 2.0 - ydescent)
    return Ellipse(center, 0.8 * width, 1.4 * height, ls=orig_handle.get_linestyle())


LEGEND_COLUMN_IN = 1.8
"""Width of a column of the mission figure's legend, inches (its longest entry fits)."""


def legend_columns(fig: Figure) -> int:
    """Columns of the mission legend that fit in ``fig``'s width (four at 7.5 inches)."""
    return max(1, int(fig.get_figwidth() // LEGEND_COLUMN_IN))


def plot_mission(
    ax: Axes,
    record: EpisodeRecord,
    n_ellipses: int = 4,
    cmap: str | Colormap = AGENT_TIME_CMAP,
    norm: Normalize | None = None,
    legend: bool = True,
) -> dict:
    """Draw one mission on ``ax``, titled by `mission_title`; returns the artists by role
    (``"agent"`` is the time-coloured path, the mappable for a colour bar) and the legend's
    ``"legend_handles"`` and ``"legend_handler_map"``.

    The targets' paths and markers are drawn over the agent's path, so a target the agent
    follows stays visible, and the agent's end is a hollow diamond that leaves a target's end
    square in sight. A target's true path, start and end are drawn where the record knows the
    truth (a flight does not): each measurement is marked on the true path, or without the
    truth at the belief's mean just after it. The legend lists only what is drawn.

    Args:
        ax: target axes (equal aspect is set).
        record: the episode to draw.
        n_ellipses: how many evenly spaced stored times get 95 % belief ellipses, one line
            style per time (`ELLIPSE_LINESTYLES`, fainter for earlier times).
        cmap: colour map for the agent's time.
        norm: time (s) to colour; default ``0`` to the mission's end.
        legend: draw the figure's legend below the plots (`legend_below`;
            the figure should have the constrained layout).
    """
    times = record.times
    paths = record.agent_paths
    team = paths.shape[1] > 1
    lines = []
    for j in range(paths.shape[1]):
        path = paths[:, j]
        line = LineCollection(
            np.stack([path[:-1], path[1:]], axis=1),
            cmap=cmap if j == 0 else vehicle_cmap(j),
            norm=norm or Normalize(0.0, times[-1]),
            linewidths=2.4,
            zorder=2,
            label=f"{vehicle_label(j, team)} path (shade: time)",
        )
        line.set_array(times[1:])
        ax.add_collection(line)
        lines.append(line)
    agent = lines[0]
    colors = [target_color(i) for i in range(len(record.target_ids))]
    artists: dict = {
        "agent": agent,
        "vehicles": lines,
        "targets": [],
        "ellipses": [],
        "detections": [],
    }
    keys: list = []  # the targets' legend entries
    known = np.isfinite(record.true_states[..., :2]).all(axis=-1)  # (K+1, n)
    stored = {int(k): j for j, k in enumerate(record.belief_steps)}
    for i, (tid, color) in enumerate(zip(record.target_ids, colors, strict=True)):
        truth = record.true_states[:, i, :2]
        if known[:, i].any():
            (line,) = ax.plot(truth[:, 0], truth[:, 1], color=color, lw=1.2, label=tid, zorder=4)
            first, last = np.flatnonzero(known[:, i])[[0, -1]]
            ax.plot(*truth[first], marker="o", color=color, mec="k", mew=0.5, ms=5.5, zorder=6)
            ax.plot(*truth[last], marker="s", color=color, mec="k", mew=0.5, ms=5.5, zorder=6)
            artists["targets"].append(line)
            keys.append(line)
        else:
            keys.append(Patch(facecolor=color, edgecolor="none", label=tid))
        at = [
            truth[k] if known[k, i] else record.belief_means[stored[k], i, :2]
            for k in np.flatnonzero(record.detections[:, i])
            if known[k, i] or k in stored
        ]
        if at:
            artists["detections"].append(
                ax.scatter(
                    *np.array(at).T,
                    s=14,
                    marker="o",
                    facecolors="none",
                    edgecolors=[color],
                    linewidths=0.7,
                    zorder=5,
                )
            )
    n_stored = len(record.belief_steps)
    picks = np.unique(np.linspace(0, n_stored - 1, n_ellipses).round().astype(int))
    ellipse_keys = []
    for rank, j in enumerate(picks):
        alpha = 0.35 + 0.55 * rank / max(len(picks) - 1, 1)
        style = ELLIPSE_LINESTYLES[rank % len(ELLIPSE_LINESTYLES)]
        for i, color in enumerate(colors):
            patch = covariance_ellipse(
                record.belief_means[j, i, :2],
                record.belief_covariances[j, i, :2, :2],
                fill=False,
                edgecolor=color,
                lw=1.0,
                alpha=alpha,
                ls=style,
                zorder=3,
            )
            ax.add_patch(patch)
            artists["ellipses"].append(patch)
        t = record.belief_steps[j] * record.time_step
        ellipse_keys.append(
            Ellipse(
                (0.0, 0.0),
                1.0,
                1.0,
                fill=False,
                edgecolor="0.2",
                lw=1.0,
                ls=style,
                alpha=alpha,
                label=f"95 % belief, t = {t:.0f} s",
            )
        )
    fence_keys = draw_fence(ax, record.fence) if record.fence is not None else []
    ends = []
    for j in range(paths.shape[1]):
        color = vehicle_color(j)
        ax.plot(*paths[0, j], marker="^", color=color, ms=8, ls="none", zorder=5)
        ax.plot(
            *paths[-1, j], marker="D", color=color, mfc="none", mew=1.4, ms=8, ls="none", zorder=5
        )
        ends += [
            Line2D(
                [],
                [],
                color=color,
                marker="^",
                ms=7,
                ls="none",
                label=f"{vehicle_label(j, team)} start",
            ),
            Line2D(
                [],
                [],
                color=color,
                marker="D",
                mfc="none",
                mew=1.4,
                ms=7,
                ls="none",
                label=f"{vehicle_label(j, team)} end",
            ),
        ]
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    style_axes(ax, mission_title(record))
    marks = [*lines, *ends]
    if artists["targets"]:
        marks += [
            Line2D(
                [],
                [],
                color="0.6",
                mec="k",
                mew=0.5,
                marker=marker,
                ms=5.5,
                ls="none",
                label=label,
            )
            for marker, label in (("o", "target start"), ("s", "target end"))
        ]
    if artists["detections"]:
        where = "" if known[record.detections].all() else " (belief mean)"
        marks.append(
            Line2D(
                [],
                [],
                color="0.4",
                marker="o",
                mfc="none",
                ms=5,
                mew=0.7,
                ls="none",
                label=f"target measured{where}",
            )
        )
    artists["legend_handles"] = keys + ellipse_keys + marks + fence_keys
    artists["legend_handler_map"] = {
        **{line: _TimeShadedKey() for line in lines},
        Ellipse: HandlerPatch(patch_func=_ellipse_key),
    }
    if legend:
        artists["legend"] = legend_below(
            ax.figure,
            artists["legend_handles"],
            ncol=legend_columns(ax.figure),
            handler_map=artists["legend_handler_map"],
        )
    return artists


_SIDES_IN, _ABOVE_BELOW_IN, _LEGEND_ROW_IN = 1.9, 1.3, 0.22  # room around the map, inches


def mission_figure(
    record: EpisodeRecord,
    width_in: float = 7.5,
    height_in: float | None = None,
    dpi: int = DPI,
) -> Figure:
    """The mission figure: `plot_mission` with its legend below and the agent-time
    colour bar beside the map. Without ``height_in`` the height fits the map's aspect, the
    title and the legend."""
    fig = new_figure(width_in, height_in or width_in, dpi)
    ax = fig.add_subplot()
    artists = plot_mission(ax, record)
    colorbar_beside(fig, artists["agent"], ax, "agent time (s)")
    if height_in is None:
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        rows = -(-len(artists["legend_handles"]) // legend_columns(fig))
        map_in = (width_in - _SIDES_IN) * min((y1 - y0) / (x1 - x0), 1.5)
        fig.set_size_inches(width_in, map_in + _ABOVE_BELOW_IN + _LEGEND_ROW_IN * rows)
    settle_layout(fig)
    return fig


def save_mission_figure(record: EpisodeRecord, path: str, dpi: int = DPI) -> None:
    """Write the mission figure (`mission_figure`) to ``path`` (PNG or PDF)."""
    save_figure(mission_figure(record, dpi=dpi), path, dpi)
