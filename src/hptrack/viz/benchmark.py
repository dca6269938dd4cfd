"""Benchmark figures: box plots of ``U`` per planner for each number of targets, and missions
of several planners side by side."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure

from hptrack.sim.record import EpisodeRecord
from hptrack.viz.mission import plot_mission

if TYPE_CHECKING:
    from hptrack.experiments.store import EpisodeRow


def plot_uncertainty_boxes(
    ax: Axes, rows: list[EpisodeRow], n_targets: int, planners: Sequence[str] = ()
) -> dict:
    """Box plot of ``U`` per planner for ``n_targets`` targets on ``ax``: the planners of
    ``planners`` in that order, then any other in the order of ``rows``."""
    by_planner: dict[str, list[float]] = {p: [] for p in planners}
    for r in rows:
        if r.key.n_targets == n_targets:
            by_planner.setdefault(r.key.planner, []).append(r.uncertainty)
    names = [p for p, values in by_planner.items() if values]
    artists = ax.boxplot([by_planner[p] for p in names], tick_labels=names)
    ax.set_title(f"n = {n_targets}")
    ax.set_ylabel("U (sum of log det, lower is better)")
    return artists


def plot_trajectories(fig: Figure, records: list[EpisodeRecord], titles: list[str]) -> None:
    """Missions side by side on ``fig`` (one panel per record, titled verbatim): equal axes,
    shared limits, one agent-time colour bar and one legend below (from the first panel).

    The figure gets the compressed layout engine (do not call ``tight_layout`` on it).
    """
    if len(records) != len(titles) or not records:
        raise ValueError(
            f"need one title per record, got {len(records)} records and {len(titles)} titles"
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
    for ax, title in zip(axes, titles, strict=True):
        ax.set_title(title)
        ax.set_aspect("equal", adjustable="box")
        ax.label_outer()
    axes[0].set_xlim(low[0] - pad[0], high[0] + pad[0])
    axes[0].set_ylim(low[1] - pad[1], high[1] + pad[1])
    fig.colorbar(drawn[0]["agent"], ax=list(axes), label="agent time (s)", shrink=0.8)
    fig.legend(
        handles=drawn[0]["legend_handles"],
        loc="outside lower center",
        ncol=min(6, len(drawn[0]["legend_handles"])),
        fontsize="small",
    )
    fig.draw_without_rendering()  # the layout settles on the second pass; this is the first
