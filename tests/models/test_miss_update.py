"""The miss update (`hptrack.models.miss_update`): the moment-matched belief after a look that
saw nothing against a Monte Carlo of the truncated belief (10^6 samples, fixed seed), the closed
form for a disc centred on the mean, and the regression of the rest of the state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.models.miss_update import (
    MASS_FLOOR,
    centred_miss_scale,
    condition_covariance,
    miss_update,
    scale_position_covariance,
)
from hptrack.models.sensor import detection_table

RADIUS = 50.0
COV = np.array(
    [
        [900.0, 300.0, 50.0, 10.0],
        [300.0, 400.0, -20.0, 30.0],
        [50.0, -20.0, 25.0, 2.0],
        [10.0, 30.0, 2.0, 16.0],
    ]
)
MEAN = np.array([10.0, -20.0, 3.0, 1.0])
NARROW = np.array(
    [
        [60.0, -25.0, 4.0, 0.0, 0.5, 0.0],
        [-25.0, 90.0, 0.0, 3.0, 0.0, 0.2],
        [4.0, 0.0, 2.0, 0.0, 0.1, 0.0],
        [0.0, 3.0, 0.0, 2.0, 0.0, 0.1],
        [0.5, 0.0, 0.1, 0.0, 0.05, 0.0],
        [0.0, 0.2, 0.0, 0.1, 0.0, 0.05],
    ]
)  # a 6-D belief (with accelerations) narrower than the footprint
DETECTORS = {
    "pd1": detection_table(1.0),
    "pd07": detection_table(0.7),
    "table": detection_table([[0.0, 0.9], [20.0, 0.8], [40.0, 0.55]]),
}
CASES = {
    # name: (mean, cov, agent position)
    "centred": (MEAN, COV, (10.0, -20.0)),
    "offset inside": (MEAN, COV, (30.0, 10.0)),
    "mean just outside": (MEAN, COV, (60.0, -40.0)),
    "mean a radius outside": (MEAN, COV, (-40.0, 30.0)),
    "narrow, disc over a flank": (np.array([0.0, 0.0, 1.0, -1.0, 0.0, 0.0]), NARROW, (40.0, 20.0)),
    "narrow, disc beside": (np.array([0.0, 0.0, 1.0, -1.0, 0.0, 0.0]), NARROW, (0.0, 60.0)),
}


def _monte_carlo(mean, cov, agent, detector, n=10**6, seed=7):
    """Mean and covariance of the prior's samples weighted by ``1 - Pd(d) 1[d <= R]``."""
    rng = np.random.default_rng(seed)
    x = rng.multivariate_normal(mean, cov, size=n, method="cholesky")
    d = np.hypot(x[:, 0] - agent[0], x[:, 1] - agent[1])
    distances, probabilities = detector
    w = 1.0 - np.interp(d, distances, probabilities) * (d <= RADIUS)
    m = w @ x / w.sum()
    c = ((x - m).T * w) @ (x - m) / w.sum()
    return m, c


def _updated(mean, cov, agent, detector):
    m, c = mean.copy(), cov.copy()
    miss_update(m, c, agent[0], agent[1], RADIUS, *detector)
    return m, c


@pytest.mark.parametrize("detector", sorted(DETECTORS))
@pytest.mark.parametrize("case", sorted(CASES))
def test_the_miss_update_is_within_two_percent_of_a_monte_carlo(case, detector):
    mean, cov, agent = CASES[case]
    m, c = _updated(mean, cov, agent, DETECTORS[detector])
    want_m, want_c = _monte_carlo(mean, cov, agent, DETECTORS[detector])
    sd = np.sqrt(np.diag(want_c))
    # the mean within 2 % of a standard deviation, each covariance entry within 2 % of the
    # product of the standard deviations (the variances within 2 %)
    assert np.max(np.abs(m - want_m) / sd) < 0.02
    assert np.max(np.abs(c - want_c) / np.outer(sd, sd)) < 0.02
    np.testing.assert_array_equal(c, c.T)


def test_the_cases_move_the_belief_by_more_than_the_tolerance():
    """The checks above would fail a miss that did nothing: each case changes the belief."""
    for mean, cov, agent in CASES.values():
        m, c = _updated(mean, cov, agent, DETECTORS["pd07"])
        sd = np.sqrt(np.diag(cov))
        moved = max(np.max(np.abs(m - mean) / sd), np.max(np.abs(c - cov) / np.outer(sd, sd)))
        assert moved > 0.05


@pytest.mark.parametrize("p", [1.0, 0.7, 0.3])
@pytest.mark.parametrize("sigma", [20.0, 40.0, 80.0])
def test_the_closed_form_matches_the_quadrature_on_a_centred_circle(p, sigma):
    cov = np.diag([sigma**2, sigma**2, 4.0, 4.0])
    cov[0, 2] = cov[2, 0] = 0.5 * sigma
    mean = np.array([5.0, -3.0, 1.0, 2.0])
    m, c = _updated(mean, cov, (5.0, -3.0), detection_table(p))
    a = 0.5 * (RADIUS / sigma) ** 2
    scale = centred_miss_scale(a, p)
    np.testing.assert_allclose(m, mean, atol=1e-9 * sigma)
    np.testing.assert_allclose(np.diag(c)[:2], scale * sigma**2, rtol=1e-4)
    want = cov.copy()
    scale_position_covariance(want, scale)
    np.testing.assert_allclose(c, want, rtol=1e-4, atol=1e-9 * sigma**2)


def test_the_closed_form_in_numbers():
    assert centred_miss_scale(0.5, 1.0) == pytest.approx(1.5)  # 1 + a at p = 1
    assert centred_miss_scale(2.0, 1.0) == pytest.approx(3.0)
    assert centred_miss_scale(2.0, 0.0) == 1.0  # a sensor that never detects tells nothing
    # p = 0.5, a = 1: [2 - 0.5 (2 - 4/e)] / (2 (1 - 0.5 (1 - 1/e)))
    e = math.exp(-1.0)
    assert centred_miss_scale(1.0, 0.5) == pytest.approx((1.0 + 2.0 * e) / (1.0 + e))
    # the floor: a certain detector over nearly all the mass leaves the belief as it was
    t = math.exp(-50.0)
    want = (102.0 * t + 2.0 * MASS_FLOOR) / (2.0 * (t + MASS_FLOOR))
    assert centred_miss_scale(50.0, 1.0) == pytest.approx(want) and want == pytest.approx(1.0)
    assert centred_miss_scale(10.0, 1.0) == pytest.approx(11.0, rel=1e-3)  # e^-10 >> 1e-9


def test_the_rest_of_the_state_follows_the_regression():
    """``P_vp -> K C``, ``P_vv -> P_vv + K (C - P_pp) K'`` with ``K = P_vp P_pp^-1``."""
    c_new = np.array([[500.0, 100.0], [100.0, 250.0]])
    out = COV.copy()
    condition_covariance(out, c_new[0, 0], c_new[0, 1], c_new[1, 1])
    s, b = COV[:2, :2], COV[2:, :2]
    k = b @ np.linalg.inv(s)
    np.testing.assert_allclose(out[:2, :2], c_new)
    np.testing.assert_allclose(out[2:, :2], k @ c_new)
    np.testing.assert_allclose(out[2:, 2:], COV[2:, 2:] + k @ (c_new - s) @ k.T)
    np.testing.assert_array_equal(out, out.T)


def test_a_disc_far_away_changes_nothing_and_a_disc_over_everything_is_floored():
    m, c = _updated(MEAN, COV, (2000.0, 0.0), DETECTORS["pd1"])
    np.testing.assert_array_equal(m, MEAN)
    np.testing.assert_array_equal(c, COV)
    tiny = np.diag([1.0, 1.0, 0.1, 0.1])
    m, c = _updated(np.zeros(4), tiny, (0.0, 0.0), DETECTORS["pd1"])  # 50 sigma inside
    np.testing.assert_allclose(m, 0.0, atol=1e-12)
    np.testing.assert_allclose(c, tiny, rtol=1e-6)
