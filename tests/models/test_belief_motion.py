"""The beliefs' motion models against independent answers: Van Loan's matrix exponential for the
prediction, quadrature for the Ornstein-Uhlenbeck noise, finite differences for the estimator's
determinant rate, the Kalman recursion for the follow tables, sampled truths for the moments;
constant velocity reached through the mission record is its closed form bit for bit."""

import math

import numba
import numpy as np
import pytest
from scipy.integrate import quad
from scipy.linalg import expm

from hptrack.interface import MissionSpec
from hptrack.models.belief_motion import (
    SERIES_BELOW,
    BeliefMotion,
    ConstantVelocity,
    OrnsteinUhlenbeckMotion,
    RandomWalkMotion,
    ou_phi,
)
from hptrack.models.measurement import update_covariance
from hptrack.models.mission import (
    follow_tables,
    mission_record,
    position_covariance_on,
    position_det_on,
    position_det_rate_on,
    position_polynomials_on,
    predict_covariance_on,
)
from hptrack.models.motion import ConstantVelocityModel, position_covariance_after
from hptrack.models.riccati import WORK_SLOTS, measured_covariance
from hptrack.models.truth_motion import OrnsteinUhlenbeck, RandomWalk, sample_truth

TAU = 0.5
R = np.array([[10.0, 2.0], [2.0, 6.0]])


def van_loan(a2: np.ndarray, w2: np.ndarray, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """``F = expm(A T)`` and ``Q = int_0^T F(s) W F(s)' ds`` for per-axis ``A``, ``W`` on
    ``[x, y, vx, vy]`` (Van Loan, 1978)."""
    a, w = np.kron(a2, np.eye(2)), np.kron(w2, np.eye(2))
    m = np.zeros((8, 8))
    m[:4, :4], m[:4, 4:], m[4:, 4:] = a, w, -a.T
    e = expm(m * duration)
    f = e[:4, :4]
    return f, e[:4, 4:] @ f.T


def spd(seed: int) -> np.ndarray:
    low = np.random.default_rng(seed).standard_normal((4, 4))
    return low @ low.T + np.eye(4)


MEAN = np.array([120.0, -40.0, 3.0, -1.5])


@pytest.mark.parametrize("damping", [1e-3, 0.01, 0.3])
@pytest.mark.parametrize("duration", [0.5, 7.3, 40.0])
def test_ornstein_uhlenbeck_prediction_is_van_loans(damping, duration):
    q = 0.7
    f, noise = van_loan(np.array([[0.0, 1.0], [0.0, -damping]]), np.diag([0.0, q]), duration)
    cov = spd(1)
    means, covs = BeliefMotion(TAU, OrnsteinUhlenbeckMotion(damping)).predict(
        MEAN[None], cov[None], q, duration
    )
    # the reference's exponential of -A' grows as e^{K T}: its rounding sets the tolerance
    slack = 1e-15 * math.exp(2.0 * damping * duration)
    np.testing.assert_allclose(means[0], f @ MEAN, rtol=1e-12, atol=1e-12 + slack * 1e3)
    reference = f @ cov @ f.T + noise
    np.testing.assert_allclose(
        covs[0], reference, rtol=1e-10, atol=(1e-12 + slack) * abs(reference).max()
    )


def test_random_walk_prediction_is_van_loans():
    f, noise = van_loan(np.zeros((2, 2)), np.diag([5.0, 0.0]), 13.0)
    cov = spd(2)
    means, covs = BeliefMotion(TAU, RandomWalkMotion(5.0)).predict(MEAN[None], cov[None], 9.0, 13.0)
    np.testing.assert_array_equal(means[0], MEAN)  # the mean stays; q is not used
    np.testing.assert_allclose(covs[0], f @ cov @ f.T + noise, rtol=1e-13)


@pytest.mark.parametrize("u", [1e-6, 1e-3, 0.1, SERIES_BELOW * 0.999, SERIES_BELOW, 3.0])
def test_ou_phi_is_the_integral_of_the_squared_gain(u):
    """``phi(u) = int_0^u (1 - e^{-s})^2 ds`` (``d Q_xx / dt = g^2``), series or closed form."""
    reference, _ = quad(lambda s: (-math.expm1(-s)) ** 2, 0.0, u, epsabs=0.0, epsrel=2e-14)
    assert ou_phi(u) == pytest.approx(reference, rel=1e-12)


def test_constant_velocity_on_the_record_is_its_closed_form_bit_for_bit():
    cov = spd(3)
    for continuous in (True, False):
        mission = mission_record(TAU, 900.0, 30.0, 100.0, R, np.array([0.02]), continuous)
        assert mission.motion == ConstantVelocity(TAU if continuous else 1.0)
        c = mission.motion.velocity_variance_per_q
        out = np.empty((4, 4))
        _predict(mission, cov, 0.02, 37.5, out)
        model = ConstantVelocityModel(TAU, "continuous" if continuous else "paper_text")
        _, expected = model.predict(MEAN[None], cov[None], 0.02, 37.5 * TAU)
        np.testing.assert_array_equal(out, expected[0])
        assert _position(mission, cov, 0.02, 37.5) == position_covariance_after(
            cov, 0.02, 37.5, TAU, c
        )


@numba.njit
def _predict(mission, cov, q, steps, out):
    predict_covariance_on(mission, cov, q, steps, out)


@numba.njit
def _position(mission, cov, q, steps):
    return position_covariance_on(mission, cov, q, steps)


@numba.njit
def _det_terms(mission, cov, q, k, h):
    poly = position_polynomials_on(mission, cov, q)
    det, rate = position_det_rate_on(mission, poly, k)
    ahead = position_det_on(mission, poly, k + h)
    behind = position_det_on(mission, poly, k - h)
    sxx, sxy, syy = position_covariance_on(mission, cov, q, k)
    return det, rate, (ahead - behind) / (2.0 * h), sxx * syy - sxy * sxy


@pytest.mark.parametrize(
    "motion", [ConstantVelocity(TAU), RandomWalkMotion(3.0), OrnsteinUhlenbeckMotion(0.05)]
)
def test_the_estimators_determinant_and_its_rate_follow_the_covariance(motion):
    mission = mission_record(TAU, 900.0, 30.0, 100.0, R, np.array([0.5]), motion=motion)
    for k in (0.5, 37.0, 900.0):
        det, rate, slope, direct = _det_terms(mission, spd(4), 0.5, k, 1e-3)
        assert det == pytest.approx(direct, rel=1e-12)
        assert rate == pytest.approx(slope, rel=1e-6)


@pytest.mark.parametrize("motion", [RandomWalkMotion(3.0), OrnsteinUhlenbeckMotion(0.05)])
def test_follow_tables_are_the_kalman_recursion_of_the_motion(motion):
    """The posterior after ``j + 1`` measured steps, by the Riccati tables and by predicting and
    updating one step at a time with the motion's own prediction."""
    q = 0.4
    mission = mission_record(TAU, 60.0, 30.0, 100.0, R, np.array([q]), motion=motion)
    tables = follow_tables(mission)
    start = spd(5)
    predicted = np.empty((4, 4))
    _predict(mission, start, q, 1.0, predicted)
    explicit = np.empty((4, 4))
    update_covariance(predicted, R, explicit)
    work = np.empty((WORK_SLOTS, 4, 4))
    out = np.empty((4, 4))
    for j in range(40):
        measured_covariance(
            tables.a[0], tables.g[0], tables.h[0], tables.length[0], j, predicted, R, out, work
        )
        np.testing.assert_allclose(out, explicit, rtol=1e-8, atol=1e-9)
        nxt = np.empty((4, 4))
        _predict(mission, explicit, q, 1.0, nxt)
        update_covariance(nxt, R, explicit)


@pytest.mark.parametrize(
    ("truth", "motion"),
    [
        (OrnsteinUhlenbeck(0.05), OrnsteinUhlenbeckMotion(0.05)),
        (RandomWalk(2.0), RandomWalkMotion(2.0)),
    ],
)
def test_the_same_models_truth_samples_the_beliefs_prediction(truth, motion):
    """20 steps of the truth from one state: sampled mean and covariance against the belief's
    closed form (4 standard errors)."""
    q, runs, steps = 0.3, 40_000, 20
    mission = mission_record(TAU, 900.0, 30.0, 100.0, R, np.array([q]), motion=motion)
    states = np.repeat(MEAN[None], runs, axis=0)
    rng = np.random.default_rng(7)
    for _ in range(steps):
        states = sample_truth(truth, mission, states, np.full(runs, q), rng)
    means, covs = BeliefMotion(TAU, motion).predict(MEAN[None], np.zeros((1, 4, 4)), q, steps * TAU)
    sd = np.sqrt(np.diag(covs[0]))
    moving = sd > 0
    assert np.all(np.abs(states.mean(axis=0) - means[0])[moving] < 4 * sd[moving] / runs**0.5)
    sampled = np.cov(states.T)
    scale = np.sqrt(np.outer(np.diag(covs[0]), np.diag(covs[0])) + covs[0] ** 2)
    assert np.all(np.abs(sampled - covs[0]) <= 4 * scale / runs**0.5 + 1e-12)


def test_a_mission_spec_carries_its_belief_motion():
    spec = MissionSpec(
        process_noise=np.array([0.1]),
        target_ids=("a",),
        belief_motion=OrnsteinUhlenbeckMotion(0.02),
    )
    assert spec.record.motion == OrnsteinUhlenbeckMotion(0.02)
    assert spec.motion.part == OrnsteinUhlenbeckMotion(0.02) and not spec.motion.straight
    with pytest.raises(ValueError, match="no belief motion registered"):
        MissionSpec(process_noise=np.array([0.1]), target_ids=("a",), belief_motion=(1.0,))
