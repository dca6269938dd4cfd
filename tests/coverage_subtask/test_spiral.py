import math

import numpy as np
import pytest

from hptrack.coverage.spiral import ShiftingSpiral, ellipse_axes, spiral_phases

SPEED, TAU, W = 30.0, 0.5, 100.0


def rotated(var_major, var_minor, angle):
    c, s = math.cos(angle), math.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    return rot @ np.diag([var_major, var_minor]) @ rot.T


CASES = {
    "correlated": (rotated(9000.0, 2500.0, 0.7), np.array([2.0, -1.5])),
    "circle": (np.eye(2) * 4000.0, np.array([1.0, 2.0])),
    "thin ellipse": (rotated(20000.0, 2e-3, -1.1), np.array([-2.5, 0.5])),
    "at rest": (rotated(3000.0, 1500.0, 0.2), np.zeros(2)),
    "largest speed": (rotated(5000.0, 3000.0, 2.0), 0.99 * SPEED * np.array([0.6, 0.8])),
}


@pytest.fixture(params=list(CASES), scope="module")
def spiral(request):
    cov, velocity = CASES[request.param]
    return ShiftingSpiral(np.array([120.0, -340.0]), velocity, cov, SPEED, TAU, W)


def moving_frame(spiral, positions):
    """World positions to the frame moving with the mean, axes u1, u2."""
    k = np.arange(len(positions))[:, None]
    return (positions - spiral.centre - spiral.velocity * k * TAU) @ spiral.rotation


def test_every_step_is_speed_times_time_step(spiral):
    steps = np.hypot(*np.diff(spiral.positions(1500), axis=0).T)
    np.testing.assert_allclose(steps, SPEED * TAU, rtol=1e-6)


def test_starts_at_the_belief_centre(spiral):
    assert spiral.phases(1)[0] == 0.0
    np.testing.assert_array_equal(spiral.position(0), spiral.centre)


def test_world_path_is_the_static_spiral_in_the_moving_frame(spiral):
    positions = spiral.positions(400)
    np.testing.assert_allclose(
        moving_frame(spiral, positions), spiral.frame_positions(400), atol=1e-8
    )


def axis_crossings(frame, axis):
    """Coordinate along ``axis`` where the path crosses it on its positive side, in order."""
    other = 1 - axis
    a, b = frame[:-1], frame[1:]
    crossing = (
        (a[:, other] < 0) & (b[:, other] >= 0)
        if axis == 0
        else (a[:, other] >= 0) & (b[:, other] < 0)
    )
    frac = a[crossing, other] / (a[crossing, other] - b[crossing, other])
    return a[crossing, axis] + frac * (b[crossing, axis] - a[crossing, axis])


def test_consecutive_loops_are_at_most_w_apart_along_both_axes(spiral):
    # Exactly, on the static spiral of Eq. (3): theta = 2 pi n crosses u1, pi/2 + 2 pi n crosses u2.
    theta = np.arange(1, 8) * 2.0 * np.pi
    along_u1 = spiral.pitch * theta * spiral.semi_a
    along_u2 = spiral.pitch * (theta + np.pi / 2) * spiral.semi_b
    for crossings in (along_u1, along_u2):
        assert np.all(np.diff(crossings) <= W * (1 + 1e-12))
    np.testing.assert_allclose(np.diff(along_u1), W)  # b = w / (2 pi max(A, B))
    # On the flown path, seen from the frame moving with the mean: crossings interpolated
    # between steps (a 15 m chord shifts a crossing by at most ~0.3 m near the centre). A thin
    # ellipse turns back at its tips within one step, where interpolation means nothing; its
    # path is checked by test_world_path_is_the_static_spiral_in_the_moving_frame.
    if spiral.semi_b < 0.1 * spiral.semi_a:
        return
    frame = moving_frame(spiral, spiral.positions(6000))
    for axis in (0, 1):
        gaps = np.diff(axis_crossings(frame, axis))
        assert len(gaps) >= 2
        assert np.all(gaps > 0)
        assert np.all(gaps <= W * 1.01), gaps.max()


def f_gap(spiral, theta, theta_k):
    def frame(t):
        r = spiral.pitch * t
        return np.array([r * spiral.semi_a * np.cos(t), r * spiral.semi_b * np.sin(t)])

    shift = spiral.rotation.T @ spiral.velocity * TAU
    d = frame(theta) + shift[:, None] - frame(theta_k)[:, None]
    return np.sum(d * d, axis=0) - (SPEED * TAU) ** 2


def test_each_phase_is_the_smallest_root_above_the_last(spiral):
    theta = spiral.phases(300)
    assert np.all(np.diff(theta) > 0)
    for k in range(299):
        grid = np.linspace(theta[k], theta[k + 1], 200)[:-1]
        assert np.all(f_gap(spiral, grid, theta[k]) < 0)


def test_lazy_extension_matches_one_long_computation(spiral):
    cov, velocity = CASES["correlated"]
    fresh = ShiftingSpiral(np.array([120.0, -340.0]), velocity, cov, SPEED, TAU, W)
    fresh.positions(10)
    fresh.position(700)
    long = ShiftingSpiral(np.array([120.0, -340.0]), velocity, cov, SPEED, TAU, W)
    np.testing.assert_array_equal(fresh.positions(900), long.positions(900))


def test_axes_and_proper_rotation():
    a, b, rot = ellipse_axes(rotated(900.0, 100.0, 0.3))
    assert (a, b) == pytest.approx((30.0, 10.0))
    assert np.linalg.det(rot) == pytest.approx(1.0)
    np.testing.assert_allclose(abs(rot[:, 0] @ [math.cos(0.3), math.sin(0.3)]), 1.0)


@pytest.mark.parametrize(
    "cov, match",
    [
        (np.array([[100.0, 100.0], [100.0, 100.0]]), "not positive definite"),
        (np.array([[100.0, 0.0], [0.0, -5.0]]), "not positive definite"),
        (np.array([[100.0, 1.0], [0.0, 100.0]]), "not symmetric"),
        (np.array([[np.nan, 0.0], [0.0, 1.0]]), "finite 2x2"),
        (np.eye(3), "finite 2x2"),
    ],
)
def test_degenerate_covariances_are_rejected(cov, match):
    with pytest.raises(ValueError, match=match):
        ShiftingSpiral(np.zeros(2), np.zeros(2), cov, SPEED, TAU, W)


def test_target_not_slower_than_agent_is_rejected():
    with pytest.raises(ValueError, match="not below the agent speed"):
        ShiftingSpiral(np.zeros(2), np.array([30.0, 0.0]), np.eye(2), SPEED, TAU, W)


def test_kernel_stops_instead_of_looping_on_inconsistent_input():
    out = np.empty(5)
    # frame shift longer than a step: f(theta_k) >= 0, no root above can be bracketed
    assert spiral_phases(0.0, 1.0, 10.0, 5.0, np.full(5, 20.0), np.zeros(5), 15.0, out) == 0
    # a shift that grows past the step at the third step: two phases, then it stops
    shifts = np.array([1.0, 1.0, 20.0, 1.0, 1.0])
    assert spiral_phases(0.0, 1.0, 10.0, 5.0, shifts, np.zeros(5), 15.0, out) == 2


def test_negative_step_is_rejected(spiral):
    with pytest.raises(ValueError):
        spiral.position(-1)
