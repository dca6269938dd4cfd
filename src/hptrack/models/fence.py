"""Where the UAV may fly: an operating area and no-fly zones as compiled geometry, with the
shortest flights around them (a visibility graph).

The paper flies in open space (Sec. III) and names structured spaces as future work. Here the
free space is the operating area (an inclusion polygon, optional), shrunk by a margin, minus
the no-fly zones (polygons and circles), each grown by the margin: one polygon with holes,
built once with shapely (``compile_fence``). A circle of radius ``r`` becomes the regular
`CIRCLE_SIDES`-gon around the circle of radius ``r + margin`` (its sides touch that circle), so
a flight that keeps out of the polygon keeps out of the circle by the margin, and is at most
``1 / cos(pi / CIRCLE_SIDES) - 1`` (0.5 %) longer than around the circle itself.

The shortest flight between two free points is straight when nothing blocks it, else it bends
only at the free space's corners (the visibility graph; de Berg et al., *Computational
Geometry*, ch. 15): the graph's node-to-node lengths are found once (``compile_fence``,
scipy's shortest paths); a query links its two ends to the nodes each can see
(`fenced_distance`). The nodes sit `NODE_OFFSET` m inside the free space from its corners, so a
flight between them never touches a boundary. The kernels are compiled (numba) for the hot
loops of the planners.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import NamedTuple

import numba
import numpy as np
from scipy.sparse.csgraph import shortest_path
from shapely.geometry import Polygon
from shapely.ops import unary_union

CIRCLE_SIDES = 32
"""Sides of the polygon that stands for a circular no-fly zone."""
NODE_OFFSET = 1e-3
"""How far inside the free space the graph's nodes sit from its corners, m."""


class FenceSpec(NamedTuple):
    """A fence as plain data (a scenario's ``fence:`` block; `compile_fence` builds it).

    Attributes:
        inclusion: the operating area's corners ``(x, y)``, m, or ``None`` (open space).
        polygons: the no-fly polygons, each its corners ``(x, y)``, m.
        circles: the no-fly circles ``(x, y, radius)``, m.
        margin: how far the UAV keeps from every boundary, m.
    """

    inclusion: tuple[tuple[float, float], ...] | None = None
    polygons: tuple[tuple[tuple[float, float], ...], ...] = ()
    circles: tuple[tuple[float, float, float], ...] = ()
    margin: float = 0.0

    def compiled(self) -> Fence:
        """The compiled `Fence` (`compile_fence`, built once per fence and shared)."""
        return _compiled(
            FenceSpec(
                None if self.inclusion is None else _corners(self.inclusion),
                tuple(_corners(ring) for ring in self.polygons),
                tuple((float(x), float(y), float(r)) for x, y, r in self.circles),
                float(self.margin),
            )
        )


class Fence(NamedTuple):
    """The free space as compiled geometry (module docstring).

    Attributes:
        bounded: whether an operating area bounds the free space (its outer ring).
        edges: ``(E, 4)`` the free space's boundary segments ``[x0, y0, x1, y1]``, m (the
            even-odd inside test counts crossings of all of them).
        nodes: ``(V, 2)`` the visibility graph's nodes (the corners, moved inside), m.
        lengths: ``(V, V)`` the shortest flight between two nodes, m (``inf``: none).
        first: ``(V, V)`` the node after ``i`` on the shortest flight from ``i`` to ``j``
            (``j`` itself when they see each other; ``-1``: no flight).
    """

    bounded: bool
    edges: np.ndarray
    nodes: np.ndarray
    lengths: np.ndarray
    first: np.ndarray


def circle_polygon(x: float, y: float, radius: float) -> Polygon:
    """The regular `CIRCLE_SIDES`-gon whose sides touch the circle of ``radius`` m at
    ``(x, y)`` from outside."""
    outer = radius / math.cos(math.pi / CIRCLE_SIDES)
    angles = 2 * math.pi * (np.arange(CIRCLE_SIDES) + 0.5) / CIRCLE_SIDES
    return Polygon(np.column_stack([x + outer * np.cos(angles), y + outer * np.sin(angles)]))


def free_space(
    inclusion: Sequence[Sequence[float]] | None,
    polygons: Sequence[Sequence[Sequence[float]]],
    circles: Sequence[Sequence[float]],
    margin: float,
):
    """The free space as a shapely geometry: the operating area shrunk by ``margin`` (m) minus
    the no-fly ``polygons`` and ``circles`` (``[x, y, radius]``) grown by it; without an
    operating area, the exclusions' union grown by the margin (the forbidden space) instead,
    as ``(False, forbidden)``. Returns ``(bounded, geometry)``.

    Raises:
        ValueError: a polygon that is not simple, or an operating area that the margin or the
            exclusions leave empty or split into parts.
    """
    zones = []
    for i, ring in enumerate(polygons):
        polygon = Polygon(ring) if len(ring) >= 3 else Polygon()
        if not polygon.is_valid or polygon.area <= 0:
            raise ValueError(f"exclusion {i}: not a simple polygon of 3 or more corners")
        zones.append(polygon.buffer(margin, join_style="mitre"))
    zones += [circle_polygon(x, y, r + margin) for x, y, r in circles]
    forbidden = unary_union(zones) if zones else Polygon()
    if inclusion is None:
        return False, forbidden
    area = Polygon(inclusion) if len(inclusion) >= 3 else Polygon()
    if not area.is_valid or area.area <= 0:
        raise ValueError("inclusion: not a simple polygon of 3 or more corners")
    free = area.buffer(-margin, join_style="mitre").difference(forbidden)
    if free.is_empty:
        raise ValueError("the margin and the exclusions leave no free space in the inclusion")
    if free.geom_type != "Polygon":
        raise ValueError(
            f"the exclusions split the inclusion into {len(free.geoms)} parts; the UAV must be "
            "able to fly from any free point to any other"
        )
    return True, free


def rings_of(geometry) -> list[np.ndarray]:
    """The rings (closed coordinate arrays) of a polygon or of a multipolygon's parts."""
    parts = getattr(geometry, "geoms", [geometry])
    out = []
    for part in parts:
        if part.is_empty:
            continue
        out.append(np.asarray(part.exterior.coords))
        out += [np.asarray(r.coords) for r in part.interiors]
    return out


def compile_fence(
    inclusion: Sequence[Sequence[float]] | None = None,
    polygons: Sequence[Sequence[Sequence[float]]] = (),
    circles: Sequence[Sequence[float]] = (),
    margin: float = 0.0,
) -> Fence:
    """The compiled `Fence` of an operating area (``inclusion``, corners ``[x, y]`` in m, or
    ``None`` for open space), no-fly ``polygons`` and ``circles`` (``[x, y, radius]``, m) and a
    ``margin`` (m) kept from every boundary (`free_space`)."""
    bounded, geometry = free_space(inclusion, polygons, circles, margin)
    rings = rings_of(geometry)
    edges = (
        np.concatenate([np.column_stack([r[:-1], r[1:]]) for r in rings])
        if rings
        else np.zeros((0, 4))
    )
    # the nodes: the corners moved NODE_OFFSET into the free space
    inside = geometry.buffer(-NODE_OFFSET if bounded else NODE_OFFSET, join_style="mitre")
    corners = np.concatenate([r[:-1] for r in rings_of(inside)]) if rings else np.zeros((0, 2))
    fence = Fence(bounded, edges, corners, np.zeros((0, 0)), np.zeros((0, 0), np.int64))
    free = np.array([point_free(fence, x, y) for x, y in corners], dtype=bool)
    corners = corners[free]
    sees = visibility(fence._replace(nodes=corners))
    gaps = np.linalg.norm(corners[:, None, :] - corners[None, :, :], axis=2)
    graph = np.where(sees, gaps, 0.0)
    lengths, predecessors = shortest_path(
        graph, method="D", directed=False, return_predecessors=True
    )
    return Fence(bounded, edges, corners, lengths, first_steps(predecessors))


@numba.njit(cache=True)
def first_steps(predecessors):
    """``first[i, j]``: the node after ``i`` on the shortest path from ``i`` to ``j`` (``-1``
    for ``i == j`` or no path), from scipy's ``predecessors`` (walked back from ``j`` along
    the tree rooted at ``i``)."""
    v = predecessors.shape[0]
    first = np.full((v, v), -1, dtype=np.int64)
    for i in range(v):
        for j in range(v):
            if i == j or predecessors[i, j] < 0:
                continue
            k = j
            while predecessors[i, k] != i:
                k = predecessors[i, k]
            first[i, j] = k
    return first


def _corners(ring) -> tuple[tuple[float, float], ...]:
    return tuple((float(x), float(y)) for x, y in ring)


@functools.lru_cache(maxsize=64)
def _compiled(spec: FenceSpec) -> Fence:
    fence = compile_fence(spec.inclusion, spec.polygons, spec.circles, spec.margin)
    for array in (fence.edges, fence.nodes, fence.lengths, fence.first):
        array.flags.writeable = False
    return fence


@numba.njit(cache=True, inline="always")
def _cross(ax, ay, bx, by, cx, cy):
    """The z component of ``(b - a) x (c - a)``."""
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)


@numba.njit(cache=True)
def segments_cross(ax, ay, bx, by, cx, cy, dx, dy):
    """Whether the segments ``ab`` and ``cd`` cross at a point inside both (touching at an end
    or running along each other does not count)."""
    d1 = _cross(cx, cy, dx, dy, ax, ay)
    d2 = _cross(cx, cy, dx, dy, bx, by)
    d3 = _cross(ax, ay, bx, by, cx, cy)
    d4 = _cross(ax, ay, bx, by, dx, dy)
    return ((d1 > 0.0 and d2 < 0.0) or (d1 < 0.0 and d2 > 0.0)) and (
        (d3 > 0.0 and d4 < 0.0) or (d3 < 0.0 and d4 > 0.0)
    )


@numba.njit(cache=True)
def point_free(fence, x, y):
    """Whether the UAV may be at ``(x, y)`` (m): the even-odd rule over the boundary's rings
    (inside the operating area's ring and no hole's, or, unbounded, inside no zone)."""
    crossings = 0
    for e in range(fence.edges.shape[0]):
        x0, y0, x1, y1 = fence.edges[e]
        if (y0 > y) != (y1 > y):
            if x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
                crossings += 1
    inside = crossings % 2 == 1
    return inside if fence.bounded else not inside


@numba.njit(cache=True)
def segment_free(fence, ax, ay, bx, by):
    """Whether the straight flight from ``(ax, ay)`` to ``(bx, by)`` (m) crosses no boundary and
    its midpoint is free (so a flight between two corners of one zone is not through it)."""
    for e in range(fence.edges.shape[0]):
        x0, y0, x1, y1 = fence.edges[e]
        if segments_cross(ax, ay, bx, by, x0, y0, x1, y1):
            return False
    return point_free(fence, 0.5 * (ax + bx), 0.5 * (ay + by))


@numba.njit(cache=True)
def visibility(fence):
    """``(V, V)`` whether each pair of the fence's nodes sees each other (`segment_free`)."""
    v = fence.nodes.shape[0]
    out = np.zeros((v, v), dtype=np.bool_)
    for i in range(v):
        for j in range(i + 1, v):
            ok = segment_free(
                fence, fence.nodes[i, 0], fence.nodes[i, 1], fence.nodes[j, 0], fence.nodes[j, 1]
            )
            out[i, j] = ok
            out[j, i] = ok
    return out


@numba.njit(cache=True)
def fenced_route(fence, ax, ay, bx, by):
    """The shortest flight from the free point ``(ax, ay)`` to ``(bx, by)`` (m) that stays in
    the free space: ``(length, wx, wy)``, its length (m; ``inf`` if none) and where it first
    heads (``(bx, by)`` itself when the way is straight, else the first corner not within
    `NODE_OFFSET` of the start)."""
    if segment_free(fence, ax, ay, bx, by):
        return math.hypot(bx - ax, by - ay), bx, by
    v = fence.nodes.shape[0]
    from_a = np.full(v, math.inf)
    to_b = np.full(v, math.inf)
    for i in range(v):
        nx, ny = fence.nodes[i, 0], fence.nodes[i, 1]
        if segment_free(fence, ax, ay, nx, ny):
            from_a[i] = math.hypot(nx - ax, ny - ay)
        if segment_free(fence, nx, ny, bx, by):
            to_b[i] = math.hypot(bx - nx, by - ny)
    best, first, last = math.inf, -1, -1
    for i in range(v):
        if from_a[i] == math.inf:
            continue
        for j in range(v):
            if to_b[j] == math.inf:
                continue
            length = from_a[i] + (0.0 if i == j else fence.lengths[i, j]) + to_b[j]
            if length < best:
                best, first, last = length, i, j
    if first < 0:
        return math.inf, ax, ay
    if from_a[first] > NODE_OFFSET:
        return best, fence.nodes[first, 0], fence.nodes[first, 1]
    # at the first corner already: head for the next one, or for the end
    if first == last:
        return best, bx, by
    after = fence.first[first, last]
    return best, fence.nodes[after, 0], fence.nodes[after, 1]


@numba.njit(cache=True)
def nearest_free(fence, x, y):
    """``(x, y)`` (m) if the UAV may be there, else the nearest point of the free space's
    boundary moved `NODE_OFFSET` into it."""
    if point_free(fence, x, y):
        return x, y
    best, px, py, nx, ny = math.inf, x, y, 0.0, 0.0
    for e in range(fence.edges.shape[0]):
        x0, y0, x1, y1 = fence.edges[e]
        ex, ey = x1 - x0, y1 - y0
        length2 = ex * ex + ey * ey
        s = 0.0 if length2 == 0.0 else min(max(((x - x0) * ex + (y - y0) * ey) / length2, 0.0), 1.0)
        cx, cy = x0 + s * ex, y0 + s * ey
        d = math.hypot(x - cx, y - cy)
        if d < best:
            scale = math.sqrt(length2) if length2 > 0.0 else 1.0
            best, px, py, nx, ny = d, cx, cy, -ey / scale, ex / scale
    for sign in (1.0, -1.0):
        qx, qy = px + sign * 2.0 * NODE_OFFSET * nx, py + sign * 2.0 * NODE_OFFSET * ny
        if point_free(fence, qx, qy):
            return qx, qy
    return px, py


@numba.njit(cache=True)
def sees(fence, x, y, radius):
    """Whether a footprint of ``radius`` (m) flown where the UAV may fly can cover ``(x, y)``:
    the point is free, or within ``radius`` of the free space's boundary."""
    if point_free(fence, x, y):
        return True
    r2 = radius * radius
    for e in range(fence.edges.shape[0]):
        x0, y0, x1, y1 = fence.edges[e]
        ex, ey = x1 - x0, y1 - y0
        length2 = ex * ex + ey * ey
        s = 0.0 if length2 == 0.0 else min(max(((x - x0) * ex + (y - y0) * ey) / length2, 0.0), 1.0)
        dx, dy = x - x0 - s * ex, y - y0 - s * ey
        if dx * dx + dy * dy <= r2:
            return True
    return False


def sight_gap(fence: Fence, start: Sequence[float], point: Sequence[float]) -> float:
    """How far ``point`` (m) is from the nearest free point, m, or ``inf`` when the UAV cannot
    fly there from ``start``."""
    fx, fy = nearest_free(fence, float(point[0]), float(point[1]))
    if not math.isfinite(fenced_route(fence, float(start[0]), float(start[1]), fx, fy)[0]):
        return math.inf
    return math.hypot(fx - point[0], fy - point[1])


def approach_length(
    fence: Fence, start: Sequence[float] | np.ndarray, point: Sequence[float] | np.ndarray
) -> float:
    """The length of the shortest free flight from ``start`` to ``point``'s nearest free point
    (``point`` itself when it is free; `nearest_free`), m; ``inf`` when there is none."""
    fx, fy = nearest_free(fence, float(point[0]), float(point[1]))
    return float(fenced_route(fence, float(start[0]), float(start[1]), fx, fy)[0])


def in_sight(fence: Fence, start: Sequence[float], point: Sequence[float], radius: float) -> bool:
    """Whether a footprint of ``radius`` m flown from ``start`` inside ``fence`` can cover
    ``point`` (`sight_gap`)."""
    return sight_gap(fence, start, point) <= radius


def fenced_distance(fence: Fence, a: Sequence[float], b: Sequence[float]) -> float:
    """The length of the shortest free flight from ``a`` to ``b`` (m; `fenced_route`)."""
    return float(fenced_route(fence, float(a[0]), float(a[1]), float(b[0]), float(b[1]))[0])


def fenced_path(fence: Fence, a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """The corners of the shortest free flight from ``a`` to ``b``: ``(k, 2)`` from ``a`` to
    ``b``, m (``a`` alone if there is none)."""
    path = [np.asarray(a, dtype=float)]
    here = path[0]
    target = np.asarray(b, dtype=float)
    for _ in range(fence.nodes.shape[0] + 1):
        length, wx, wy = fenced_route(fence, here[0], here[1], target[0], target[1])
        if not math.isfinite(length):
            break
        here = np.array([wx, wy])
        path.append(here)
        if wx == target[0] and wy == target[1]:
            break
    return np.array(path)
