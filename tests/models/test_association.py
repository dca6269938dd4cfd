"""Association of detections without identity (`hptrack.models.association`): the gate exact on
toy cases, GNN and JPDA against Stone Soup's (``GNNWith2DAssignment`` and ``JPDA`` over a
``PDAHypothesiser`` with the same Pd, gate and clutter density) on the same tracks and
detections, and the combined update against its definition."""

from __future__ import annotations

import datetime
import math

import numpy as np
import pytest

from hptrack.models.association import (
    clusters,
    gate_threshold,
    gnn,
    innovations,
    jpda,
    log_likelihoods,
    log_weights,
    mahalanobis2,
    pda_update,
)

R = np.diag([10.0, 10.0])


def test_the_gate_is_the_chi_square_quantile_of_two_dof():
    # chi2_2 has the closed form -2 ln(1 - p)
    for p in (0.9, 0.99, 0.999):
        assert gate_threshold(p) == pytest.approx(-2.0 * math.log1p(-p), rel=1e-12)


def test_gating_and_the_likelihood_exact_on_a_toy_case():
    positions = np.array([[0.0, 0.0]])
    covs = np.array([[[30.0, 0.0], [0.0, 90.0]]])  # S = diag(40, 100)
    dets = np.array([[4.0, 0.0], [0.0, 10.0], [20.0, 0.0]])
    nu, s = innovations(positions, covs, R, dets)
    np.testing.assert_array_equal(s[0], [[40.0, 0.0], [0.0, 100.0]])
    d2 = mahalanobis2(nu, s)
    np.testing.assert_allclose(d2[0], [16.0 / 40.0, 1.0, 10.0], rtol=1e-14)
    gated = d2 <= gate_threshold(0.99)  # 9.2103...
    assert gated.tolist() == [[True, True, False]]
    ll = log_likelihoods(nu, s)
    want = -0.5 * d2[0] - math.log(2 * math.pi) - 0.5 * math.log(4000.0)
    np.testing.assert_allclose(ll[0], want, rtol=1e-14)


def test_gnn_and_jpda_on_a_toy_case_by_hand():
    # two beliefs, two detections, all gated: weights by hand
    w = np.log(np.array([[0.5, 4.0, 1.0], [0.5, 3.0, 0.1]]))
    # joint events (a, b): (0,0) .25, (1,0) 2, (2,0) .5, (0,1) 1.5, (0,2) .05, (1,2) .4, (2,1) 3
    assert gnn(w).tolist() == [1, 0]  # 3.0 beats 0.4 and 2
    total = 0.25 + 2 + 0.5 + 1.5 + 0.05 + 0.4 + 3
    beta = jpda(w)
    np.testing.assert_allclose(
        beta[0], np.array([0.25 + 1.5 + 0.05, 2 + 0.4, 0.5 + 3]) / total, rtol=1e-14
    )
    np.testing.assert_allclose(
        beta[1], np.array([0.25 + 2 + 0.5, 1.5 + 3, 0.05 + 0.4]) / total, rtol=1e-14
    )


def test_clusters_join_beliefs_that_share_a_detection():
    gated = np.array(
        [[True, False, False], [True, True, False], [False, True, False], [False, False, False]]
        + [[False, False, True]]
    )
    assert [c.tolist() for c in clusters(gated)] == [[0, 1, 2], [4]]


def test_pda_update_is_the_kalman_update_with_one_certain_detection():
    mean = np.array([1.0, 2.0, 0.5, -0.5])
    cov = np.diag([40.0, 50.0, 1.0, 2.0]) + 0.1
    z = np.array([[5.0, -3.0]])
    m, c = pda_update(mean, cov, R, z, np.array([0.0, 1.0]))
    h = np.zeros((2, 4))
    h[0, 0] = h[1, 1] = 1.0
    k = cov @ h.T @ np.linalg.inv(h @ cov @ h.T + R)
    np.testing.assert_allclose(m, mean + k @ (z[0] - mean[:2]), rtol=1e-13)
    np.testing.assert_allclose(c, (np.eye(4) - k @ h) @ cov, rtol=1e-12, atol=1e-12)
    # no detection: the prediction
    m0, c0 = pda_update(mean, cov, R, z, np.array([1.0, 0.0]))
    np.testing.assert_array_equal(m0, mean)
    np.testing.assert_allclose(c0, cov, rtol=1e-15)


# --- against Stone Soup ---------------------------------------------------------------------

T0 = datetime.datetime(2025, 1, 1)
PD, PG, CLUTTER = 0.8, 0.99, 1e-4


def _scene(seed: int, n: int = 4, k: int = 6):
    rng = np.random.default_rng(seed)
    means = np.column_stack(
        [rng.uniform(0, 60, n), rng.uniform(0, 60, n), rng.normal(0, 1, (n, 2))]
    )
    covs = np.empty((n, 4, 4))
    for i in range(n):
        a = rng.normal(size=(4, 4))
        covs[i] = a @ a.T + np.diag([60.0, 60.0, 1.0, 1.0])
    dets = rng.uniform(-10, 70, (k, 2))
    return means, covs, dets


def _ours(means, covs, dets):
    nu, s = innovations(means[:, :2], covs[:, :2, :2], R, dets)
    gated = mahalanobis2(nu, s) <= gate_threshold(PG)
    n = means.shape[0]
    return log_weights(
        log_likelihoods(nu, s), gated, np.full(n, PD), np.full(n, 1 - PD * PG), CLUTTER
    )


def _stonesoup(means, covs, dets, associator_name: str):
    pytest.importorskip("stonesoup")
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import (
        CombinedLinearGaussianTransitionModel,
        ConstantVelocity,
    )
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.types.track import Track
    from stonesoup.updater.kalman import KalmanUpdater

    order = [0, 2, 1, 3]  # Stone Soup's [x, vx, y, vy]
    model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=R)
    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.1)] * 2)
    hypothesiser = PDAHypothesiser(
        predictor=KalmanPredictor(transition),
        updater=KalmanUpdater(model),
        clutter_spatial_density=CLUTTER,
        prob_detect=PD,
        prob_gate=PG,
    )
    tracks = [
        Track([GaussianState(m[order], c[np.ix_(order, order)], timestamp=T0)])
        for m, c in zip(means, covs, strict=True)
    ]
    detections = [Detection(z, timestamp=T0, measurement_model=model) for z in dets]
    associator = (GNNWith2DAssignment if associator_name == "gnn" else JPDA)(hypothesiser)
    result = associator.associate(set(tracks), set(detections), T0)
    return tracks, detections, result


@pytest.mark.parametrize("seed", range(6))
def test_gnn_makes_stone_soups_assignments(seed):
    means, covs, dets = _scene(seed)
    tracks, detections, result = _stonesoup(means, covs, dets, "gnn")
    want = [detections.index(result[t].measurement) if result[t] else -1 for t in tracks]
    assert gnn(_ours(means, covs, dets)).tolist() == want
    assert seed > 0 or any(w >= 0 for w in want)


@pytest.mark.parametrize("seed", range(6))
def test_jpda_gives_stone_soups_weights(seed):
    means, covs, dets = _scene(seed)
    tracks, detections, result = _stonesoup(means, covs, dets, "jpda")
    beta = jpda(_ours(means, covs, dets))
    shared = 0
    for i, track in enumerate(tracks):
        want = np.zeros(len(detections) + 1)
        for hypothesis in result[track]:
            j = detections.index(hypothesis.measurement) + 1 if hypothesis else 0
            want[j] = float(hypothesis.probability)
        np.testing.assert_allclose(beta[i], want, rtol=0, atol=1e-9)
        shared += int(np.count_nonzero(want[1:]) > 0)
    assert shared >= 1


def test_a_cluster_beyond_the_enumeration_bound_is_weighed_belief_by_belief():
    rng = np.random.default_rng(5)
    w = rng.normal(size=(3, 61))  # 61^3 joint choices, above MAX_JOINT_EVENTS
    beta = jpda(w)
    want = np.exp(w - w.max(axis=1, keepdims=True))
    np.testing.assert_allclose(beta, want / want.sum(axis=1, keepdims=True), rtol=1e-13)
    small = jpda(w[:, :4])  # 4^3 choices: exact, the rows couple
    assert not np.allclose(small[0], np.exp(w[0, :4]) / np.exp(w[0, :4]).sum())
