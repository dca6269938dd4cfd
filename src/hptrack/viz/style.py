"""One style for every hptrack figure (missions, flight replays, the envs' ``render()``, coverage,
benchmark, learning curves): figures with matplotlib's constrained layout, legends below the
plots (never over an axis label, a tick label or a colour bar), colour bars beside their plot
and exactly as tall as it, the same fonts, grid and resolution.

Figures are built without pyplot (`matplotlib.figure.Figure` with an Agg canvas), so
library code never touches global plotting state.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colorbar import Colorbar
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.legend_handler import HandlerBase

DPI = 130
"""Resolution of the written figures, dots per inch."""

LEGEND_STYLE = {"fontsize": "small", "frameon": False, "columnspacing": 1.2, "handletextpad": 0.5}
"""Keyword arguments of every legend."""

GRID_STYLE = {"alpha": 0.3, "lw": 0.6}
"""Keyword arguments of every grid."""

TITLE_SIZE, TITLE_PAD = "medium", 9.0
"""Font size of axes titles (figure titles are one step larger) and their gap above the plot,
points (clear of a colour bar's top tick label when a long title overhangs the plot)."""

COLORBAR_GAP, COLORBAR_WIDTH = 0.03, 0.035
"""Gap between a plot and its colour bar and the bar's width, fractions of the plot's width."""


def new_figure(width_in: float, height_in: float, dpi: int = DPI) -> Figure:
    """A figure of ``width_in`` x ``height_in`` inches with the constrained layout (which keeps
    legends placed ``"outside"`` and colour bars clear of the plots) and an Agg canvas."""
    fig = Figure(figsize=(width_in, height_in), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def legend_below(
    fig: Figure,
    handles: Sequence[Artist],
    ncol: int,
    handler_map: Mapping[Any, HandlerBase] | None = None,
) -> Legend:
    """The figure's legend, centred below all its plots (``handler_map``: how to draw the
    keys of some handles, by handle or by type, as in `matplotlib.figure.Figure.legend`)."""
    return fig.legend(
        handles=list(handles),
        loc="outside lower center",
        ncol=max(1, min(ncol, len(handles))),
        handler_map=dict(handler_map or {}),
        **LEGEND_STYLE,
    )


def colorbar_beside(fig: Figure, mappable: ScalarMappable, ax: Axes, label: str) -> Colorbar:
    """A colour bar on the right of ``ax``, exactly as tall as the plot (also when an equal
    aspect shrinks the plot inside the space the layout gave it)."""
    cax = ax.inset_axes((1.0 + COLORBAR_GAP, 0.0, COLORBAR_WIDTH, 1.0))
    return fig.colorbar(mappable, cax=cax, label=label)


def style_axes(ax: Axes, title: str | None = None, grid: bool = True) -> None:
    """The shared look of a plot: its title (if given) and a light grid under the data."""
    if title is not None:
        ax.set_title(title, fontsize=TITLE_SIZE, pad=TITLE_PAD)
    if grid:
        ax.grid(**GRID_STYLE)
        ax.set_axisbelow(True)


def settle_layout(fig: Figure) -> None:
    """Lay ``fig`` out once without rendering: the constrained layout of a first draw sizes
    the margins by tick labels that change as the plots take their size (a long y tick label
    or a colour bar's label can then fall off the figure); the next draw, the one shown or
    written, settles on the labels it draws."""
    fig.draw_without_rendering()


def save_figure(fig: Figure, path: str | Path, dpi: int = DPI) -> None:
    """Write ``fig`` (PNG, PDF or SVG by the suffix) at ``dpi``, its layout settled first
    (`settle_layout`)."""
    settle_layout(fig)
    fig.savefig(path, dpi=dpi)
