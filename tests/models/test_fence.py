"""The fence's geometry: shortest free flights of known length around a square, a circle and a
concave operating area; straight flights where nothing blocks; random zones against an
independent visibility graph built with shapely; bad fences refused in one line."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse.csgraph import shortest_path
from shapely.geometry import LineString, Point

from hptrack.models.fence import (
    CIRCLE_SIDES,
    NODE_OFFSET,
    compile_fence,
    fenced_distance,
    fenced_path,
    free_space,
    point_free,
)

SQUARE = [[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]]
U_SHAPE = [[0, 0], [100, 0], [100, 100], [60, 100], [60, 20], [40, 20], [40, 100], [0, 100]]


def test_around_a_square_by_two_corners():
    fence = compile_fence(polygons=[SQUARE])
    length = fenced_distance(fence, (-20.0, 0.0), (20.0, 0.0))
    assert length == pytest.approx(20.0 + 2 * math.hypot(10.0, 10.0), abs=4 * NODE_OFFSET)
    path = fenced_path(fence, (-20.0, 0.0), (20.0, 0.0))
    assert len(path) == 4 and path[1][1] == path[2][1]  # along one side
    assert np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)) == pytest.approx(length)


def test_a_clear_flight_is_straight():
    fence = compile_fence(polygons=[SQUARE], circles=[[100.0, 0.0, 20.0]])
    assert fenced_distance(fence, (-20.0, 30.0), (50.0, 40.0)) == math.hypot(70.0, 10.0)
    assert fenced_path(fence, (-20.0, 30.0), (50.0, 40.0)).tolist() == [[-20, 30], [50, 40]]


def test_around_a_circle_within_its_polygons_excess():
    fence = compile_fence(circles=[[0.0, 0.0, 50.0]], margin=5.0)
    r, d = 55.0, 100.0  # tangent, arc, tangent around the circle grown by the margin
    exact = 2 * math.sqrt(d * d - r * r) + r * (math.pi - 2 * math.acos(r / d))
    length = fenced_distance(fence, (-d, 0.0), (d, 0.0))
    assert exact <= length <= exact * (1 / math.cos(math.pi / CIRCLE_SIDES))
    assert not point_free(fence, 0.0, 54.9) and point_free(fence, 0.0, 56.0)


def test_a_concave_operating_area_with_a_margin():
    fence = compile_fence(inclusion=U_SHAPE, margin=2.0)
    # up the left arm, round the inner corners (38, 18) and (62, 18), down the right arm
    expected = 2 * math.hypot(18.0, 62.0) + 24.0
    assert fenced_distance(fence, (20.0, 80.0), (80.0, 80.0)) == pytest.approx(
        expected, abs=4 * NODE_OFFSET
    )
    assert point_free(fence, 20.0, 80.0) and not point_free(fence, 50.0, 50.0)
    assert not point_free(fence, 1.0, 50.0) and not point_free(fence, 150.0, 50.0)


def test_a_hole_inside_the_area_is_forbidden():
    fence = compile_fence(inclusion=[[-50, -50], [50, -50], [50, 50], [-50, 50]], polygons=[SQUARE])
    assert not point_free(fence, 0.0, 0.0) and point_free(fence, 30.0, 0.0)
    assert not point_free(fence, 60.0, 0.0)


def _reference_distance(forbidden, a, b) -> float:
    """The shortest flight around the ``forbidden`` geometry, by shapely alone: a visibility
    graph over its corners moved `NODE_OFFSET` outside it, a leg free when it overlaps the
    forbidden space nowhere."""
    moved = forbidden.buffer(NODE_OFFSET, join_style="mitre")
    corners = [c for g in moved.geoms for c in g.exterior.coords[:-1]]
    points = [tuple(a), tuple(b), *corners]
    n = len(points)
    graph = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1, n):
            if forbidden.intersection(LineString([points[i], points[j]])).length <= 1e-9:
                graph[i, j] = graph[j, i] = math.dist(points[i], points[j])
    return float(graph[0, 1] or shortest_path(graph, directed=False)[0, 1])


@pytest.mark.parametrize("seed", range(4))
def test_random_zones_agree_with_an_independent_visibility_graph(seed):
    rng = np.random.default_rng(seed)
    circles = [[*rng.uniform(-300, 300, 2), rng.uniform(20, 80)] for _ in range(3)]
    circles.append([1000.0, 1000.0, 10.0])  # apart from the rest: a multipolygon
    margin = 5.0
    _, forbidden = free_space(None, [], circles, margin)
    fence = compile_fence(circles=circles, margin=margin)
    checked = 0
    while checked < 3:
        a, b = rng.uniform(-400, 400, (2, 2))
        if forbidden.contains(Point(a)) or forbidden.contains(Point(b)):
            continue
        checked += 1
        length = fenced_distance(fence, a, b)
        assert length >= math.dist(a, b) * (1 - 1e-12)
        assert length == pytest.approx(_reference_distance(forbidden, a, b), rel=1e-9)
        path = fenced_path(fence, a, b)
        for p, q in zip(path[:-1], path[1:], strict=True):  # every leg keeps out by the margin
            assert forbidden.distance(LineString([p, q])) >= 0.0
            assert not LineString([p, q]).crosses(forbidden.buffer(-1e-6))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"polygons": [[[0, 0], [10, 10], [10, 0], [0, 10]]]}, "exclusion 0: not a simple polygon"),
        ({"polygons": [[[0, 0], [10, 0]]]}, "exclusion 0"),
        ({"inclusion": [[0, 0], [10, 10], [10, 0], [0, 10]]}, "inclusion: not a simple"),
        ({"inclusion": [[0, 0], [10, 0], [10, 10], [0, 10]], "margin": 6.0}, "no free space"),
        (
            {
                "inclusion": [[0, 0], [100, 0], [100, 10], [0, 10]],
                "polygons": [[[40, -5], [60, -5], [60, 15], [40, 15]]],
            },
            "split the inclusion into 2 parts",
        ),
    ],
)
def test_bad_fences_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        compile_fence(**kwargs)


def _fenced_mission(**fence):
    from hptrack.interface import MissionSpec
    from hptrack.models.fence import FenceSpec

    return MissionSpec(process_noise=np.array([0.0]), target_ids=("t",), fence=FenceSpec(**fence))


def test_the_chance_of_a_find_loses_what_the_footprint_cannot_see():
    from hptrack.models.mission import visible_find

    cov = np.diag([100.0**2, 100.0**2, 1e-12, 1e-12])
    still = np.array([100.0, 0.0, 0.0, 0.0])
    # free space x < 50: the footprint (radius 50 m) sees up to x = 100, half of the belief
    wall = _fenced_mission(polygons=(((50.0, -1e5), (1e5, -1e5), (1e5, 1e5), (50.0, 1e5)),))
    half = visible_find(wall.record, still, 0.0, cov, 0.0, 0.8, 100)
    assert half == pytest.approx(0.8 * 0.5, abs=0.8 / 24)
    # far from every zone: exactly the open-space chance
    far = _fenced_mission(circles=((1e5, 1e5, 10.0),))
    assert visible_find(far.record, still, 0.0, cov, 0.0, 0.8, 100) == 0.8
    # deep inside a zone: nothing can be seen
    deep = _fenced_mission(circles=((100.0, 0.0, 5000.0),))
    assert visible_find(deep.record, still, 0.0, cov, 0.0, 0.8, 100) == 0.0
    # a belief that drives out of the wall's shadow is seen where the spiral sweeps it later
    leaving = np.array([100.0, 0.0, -2.0, 0.0])
    later = visible_find(wall.record, leaving, 0.0, cov, 0.0, 0.8, 200)
    assert later > half


def _wall_quadrature(vx: float, p: float, cutoff: int, hold: bool) -> float:
    """`visible_find`'s quadrature by hand for the belief of the test below (N(mean, 100^2 I),
    not growing, the mean at x = 100 m moving at ``vx`` m/s) behind the wall x >= 50 m (seen
    where x <= 100 m): rings of equal mass, each reached later by the hidden share of the time
    of the rings before it when ``hold``."""
    rings, angles, tau = 12, 24, 0.5
    scale = cutoff / math.log(1.0 - p)
    held, seen = 0.0, 0
    for k in range(rings):
        u = p * (k + 0.5) / rings
        steps = scale * math.log(1.0 - u) + held
        theta = 2.0 * math.pi * (np.arange(angles) + 0.5 * (k % 2)) / angles
        x = 100.0 + vx * steps * tau + 100.0 * math.sqrt(-2.0 * math.log(1.0 - u)) * np.cos(theta)
        ring = int(np.sum(x <= 100.0))
        seen += ring
        if hold:
            bounds = np.log(1.0 - p * np.array([k, k + 1]) / rings)
            held += (1.0 - ring / angles) * scale * (bounds[1] - bounds[0])
    return p * seen / (rings * angles)


def test_each_ring_is_reached_later_by_the_time_spent_over_the_hidden_part():
    from hptrack.models.mission import visible_find

    cov = np.diag([100.0**2, 100.0**2, 1e-12, 1e-12])
    wall = _fenced_mission(polygons=(((50.0, -1e5), (1e5, -1e5), (1e5, 1e5), (50.0, 1e5)),))
    leaving = np.array([100.0, 0.0, -2.0, 0.0])
    got = visible_find(wall.record, leaving, 0.0, cov, 0.0, 0.8, 200)
    assert got == pytest.approx(_wall_quadrature(-2.0, 0.8, 200, hold=True), rel=1e-12)
    assert got > _wall_quadrature(-2.0, 0.8, 200, hold=False)  # the belief has moved on
    still = np.array([100.0, 0.0, 0.0, 0.0])  # a belief that stays put: the holding is moot
    assert visible_find(wall.record, still, 0.0, cov, 0.0, 0.8, 200) == pytest.approx(
        _wall_quadrature(0.0, 0.8, 200, hold=False), rel=1e-12
    )
