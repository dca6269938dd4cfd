"""The fence (`hptrack.models.fence`) drawn on a map: no-fly zones filled, the operating area's
edge, and the margin the UAV keeps, dashed."""

from __future__ import annotations

from matplotlib.axes import Axes
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.patches import Polygon as PolygonPatch

from hptrack.models.fence import FenceSpec, circle_polygon, free_space, rings_of

ZONE_COLOR = (0.84, 0.15, 0.16)
"""No-fly zones' colour (filled lightly)."""


def _zone(ax: Axes, corners, zorder: float) -> None:
    ax.add_patch(
        PolygonPatch(
            corners,
            closed=True,
            facecolor=(*ZONE_COLOR, 0.18),
            edgecolor=ZONE_COLOR,
            lw=1.0,
            zorder=zorder,
        )
    )


def draw_fence(ax: Axes, fence: FenceSpec, zorder: float = 0.5) -> list:
    """Draw ``fence`` on ``ax`` under the mission; returns its legend entries."""
    for corners in fence.polygons:
        _zone(ax, corners, zorder)
    for x, y, radius in fence.circles:
        _zone(ax, list(circle_polygon(x, y, radius).exterior.coords), zorder)
    if fence.inclusion is not None:
        ax.add_patch(
            PolygonPatch(
                fence.inclusion, closed=True, fill=False, edgecolor="0.2", lw=1.2, zorder=zorder
            )
        )
    keys: list = []
    if fence.polygons or fence.circles:
        keys.append(Patch(facecolor=(*ZONE_COLOR, 0.18), edgecolor=ZONE_COLOR, label="no-fly zone"))
    if fence.inclusion is not None:
        keys.append(Line2D([], [], color="0.2", lw=1.2, label="operating area"))
    if fence.margin > 0:
        _, geometry = free_space(fence.inclusion, fence.polygons, fence.circles, fence.margin)
        for boundary in rings_of(geometry):
            ax.plot(
                boundary[:, 0], boundary[:, 1], color=ZONE_COLOR, lw=0.8, ls="--", zorder=zorder
            )
        keys.append(
            Line2D([], [], color=ZONE_COLOR, lw=0.8, ls="--", label=f"margin ({fence.margin:g} m)")
        )
    return keys
