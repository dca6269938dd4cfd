"""Benchmark figures: box plots of ``U`` per planner for each number of targets, and missions
of several planners side by side."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from hptrack.sim.record import EpisodeRecord
from hptrack.viz.mission import plot_mission
from hptrack.viz.style import (
    TITLE_PAD,
    TITLE_SIZE,
    colorbar_beside,
    legend_below,
    new_figure,
    save_figure,
    settle_layout,
    style_axes,
)

if TYPE_CHECKING:
    from hptrack.sim.record import EpisodeRow


PLANNER_COLORS = ("#4C72B0", "#DD8452", "#55A868", "#C44E52", "#8172B3", "#937860", "#DA8BC3")
"""Box colours, by a planner's place in the order asked (cycled)."""


def plot_uncertainty_boxes(
    ax: Axes, rows: list[EpisodeRow], n_targets: int, planners: Sequence[str] = ()
) -> dict:
    """Box plot of ``U`` per planner for ``n_targets`` targets on ``ax``: the planners of
    ``planners`` in that order, then any other in the order of ``rows``; boxes of the middle
    half with the median (line) and the mean (white diamond), whiskers to 1.5 IQR."""
    by_planner: dict[str, list[float]] = {p: [] for p in planners}
    for r in rows:
        if r.key.n_targets == n_targets:
            by_planner.setdefault(r.key.planner, []).append(r.uncertainty)
    names = [p for p, values in by_planner.items() if values]
    artists = ax.boxplot(
        [by_planner[p] for p in names],
        tick_labels=names,
        patch_artist=True,
        showmeans=True,
        widths=0.6,
        medianprops={"color": "k", "lw": 1.2},
        meanprops={"marker": "D", "mfc": "white", "mec": "k", "ms": 4.5},
        flierprops={"marker": "o", "ms": 3, "mfc": "none", "mec": "0.45", "alpha": 0.7},
    )
    for k, box in enumerate(artists["boxes"]):
        box.set_facecolor(PLANNER_COLORS[k % len(PLANNER_COLORS)])
        box.set_alpha(0.75)
    episodes = {len(by_planner[p]) for p in names}
    count = f", {episodes.pop()} scenarios" if len(episodes) == 1 else ""
    style_axes(ax, f"n = {n_targets} targets{count}")
    ax.grid(False, axis="x")
    ax.set_ylabel("U (sum of log det Σxy, m²; lower is better)")
    return artists


def save_uncertainty_boxes(
    rows: list[EpisodeRow], path: str | Path, planners: Sequence[str] = (), title: str = ""
) -> None:
    """One box plot of ``U`` per number of targets (`plot_uncertainty_boxes`), side by
    side with the y label on the first, written to ``path``."""
    counts = sorted({r.key.n_targets for r in rows})
    fig = new_figure(max(3.4 * len(counts), 5.0), 4.2)
    axes = fig.subplots(1, len(counts), squeeze=False)[0]
    for i, (ax, n) in enumerate(zip(axes, counts, strict=True)):
        plot_uncertainty_boxes(ax, rows, n, planners)
        ax.tick_params(axis="x", labelrotation=30)
        if i:
            ax.set_ylabel("")
    key = "box: middle half, line: median, ◇: mean, whiskers: 1.5 × IQR, circles: beyond"
    fig.suptitle(f"{title}\n{key}" if title else key)
    save_figure(fig, path)


def plot_trajectories(
    fig: Figure, records: list[EpisodeRecord], titles: list[str] | None = None
) -> None:
    """Missions side by side on ``fig`` (one panel per record, titled verbatim or by
    `mission_title`): equal axes, shared limits, one agent-time
    colour bar beside the last panel and one legend below (from the first panel).

    The figure gets the compressed layout engine (do not call ``tight_layout`` on it).
    """
    if not records or (titles is not None and len(records) != len(titles)):
        raise ValueError(
            f"need one title per record, got {len(records)} records and {len(titles or [])} titles"
        )
    fig.set_layout_engine("compressed")
    axes = fig.subplots(1, len(records), sharex=True, sharey=True, squeeze=False)[0]
    norm = Normalize(0.0, max(float(r.times[-1]) for r in records))
    drawn = [
        plot_mission(ax, r, norm=norm, legend=False) for ax, r in zip(axes, records, strict=True)
    ]
    low = [min(ax.dataLim.x0 for ax in axes), min(ax.dataLim.y0 for ax in axes)]
    high = [max(ax.dataLim.x1 for ax in axes), max(ax.dataLim.y1 for ax in axes)]
    pad = [0.03 * (h - lo) for lo, h in zip(low, high, strict=True)]
    for ax, title in zip(axes, titles or [ax.get_title() for ax in axes], strict=True):
        ax.set_title(title, fontsize=TITLE_SIZE, pad=TITLE_PAD)
        ax.set_aspect("equal", adjustable="box")
        ax.label_outer()
    axes[0].set_xlim(low[0] - pad[0], high[0] + pad[0])
    axes[0].set_ylim(low[1] - pad[1], high[1] + pad[1])
    colorbar_beside(fig, drawn[-1]["agent"], axes[-1], "agent time (s)")
    legend_below(
        fig, drawn[0]["legend_handles"], ncol=6, handler_map=drawn[0]["legend_handler_map"]
    )
    settle_layout(fig)
