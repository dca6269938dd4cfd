"""The 6-D acceleration models (Singer's and constant acceleration), beliefs and truths, against
independent answers: Van Loan's matrix exponential (scipy in scaled coordinates, mpmath at 60
digits), finite differences for the determinant rate, sampled truths for the moments."""

import math

import mpmath as mp
import numba
import numpy as np
import pytest
from scipy.linalg import expm

from hptrack.models import belief_motion as bm
from hptrack.models.belief_motion import (
    SINGER_SERIES_BANDS,
    BeliefMotion,
    ConstantAccelerationMotion,
    ConstantVelocity,
    OrnsteinUhlenbeckMotion,
    RandomWalkMotion,
    SingerMotion,
    ca_axis_noise,
    ca_axis_transition,
    extended_prior,
    singer_axis_noise,
    singer_axis_transition,
)
from hptrack.models.mission import (
    mission_record,
    position_covariance_on,
    position_det_on,
    position_det_rate_on,
    position_polynomials_on,
    predict_covariance_on,
    predict_mean_on,
)
from hptrack.models.truth_motion import (
    ConstantAccelerationTruth,
    SingerTruth,
    sample_truth,
    truth_state_size,
)

TAU = 0.5
R = np.array([[10.0, 2.0], [2.0, 6.0]])
MEAN = np.array([120.0, -40.0, 3.0, -1.5, 0.2, -0.1])
DURATIONS = [0.01, 0.5, 10.0, 300.0, 900.0]
MOTIONS = [
    SingerMotion(1.0 / 60.0, 1.5),
    SingerMotion(0.1, 2.0),
    SingerMotion(1.0, 0.5),
    ConstantAccelerationMotion(0.3, 1.0),
]


def axis_model(motion) -> tuple[float, float]:
    """``(alpha, q)`` of ``A = [[0, 1, 0], [0, 0, 1], [0, 0, -alpha]]`` and the noise on the
    acceleration."""
    if isinstance(motion, SingerMotion):
        return motion.damping, 2.0 * motion.damping * motion.acceleration_std**2
    return 0.0, motion.jerk_intensity


def scipy_van_loan(alpha: float, q: float, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis ``F(T)`` and ``Q(T)`` from scipy's exponential of Van Loan's block matrix, in
    the coordinates ``[p / T'^2, v / T', a]`` over the unit time ``T'`` (every entry of order 1)
    and, when ``alpha T > 1``, at ``T' = T / 2^n`` doubled ``n`` times
    (``F(2t) = F(t)^2``, ``Q(2t) = F(t) Q(t) F(t)' + Q(t)``): the direct block grows as
    ``e^{alpha T}`` and its rounding would swamp ``Q``."""
    n = max(0, math.ceil(math.log2(alpha * duration))) if alpha * duration > 1.0 else 0
    t = duration / 2.0**n
    a = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -alpha * t]])
    block = np.zeros((6, 6))
    block[:3, :3], block[3:, 3:] = -a, a.T
    block[2, 5] = q * t
    e = expm(block)
    fs = e[3:, 3:].T
    qs = fs @ e[:3, 3:]
    # F is upper triangular: drop the rounding below the diagonal, which the doubling would
    # carry into the decayed entries
    assert np.all(np.abs(fs[np.tril_indices(3, -1)]) < 1e-14)
    fs = np.triu(fs)
    d = np.diag([t * t, t, 1.0])
    f, noise = d @ fs @ np.linalg.inv(d), d @ qs @ d
    for _ in range(n):
        f, noise = f @ f, f @ noise @ f.T + noise
    return f, noise


def mp_van_loan(alpha, q, duration) -> tuple[np.ndarray, np.ndarray]:
    """The same at 60 digits, directly (no scaling needed), rounded to floats at the end."""
    with mp.workdps(60):
        alpha, q, t = mp.mpf(alpha), mp.mpf(q), mp.mpf(duration)
        block = mp.zeros(6, 6)
        block[0, 1] = block[1, 2] = -t
        block[2, 2] = alpha * t
        block[4, 3] = block[5, 4] = t
        block[5, 5] = -alpha * t
        block[2, 5] = q * t
        e = mp.expm(block)
        f = e[3:6, 3:6].T
        noise = f * e[0:3, 3:6]
        return (
            np.array(f.tolist(), dtype=float),
            np.array(noise.tolist(), dtype=float),
        )


def upper(entries) -> np.ndarray:
    fpp, fpv, fpa, fvv, fva, faa = entries
    return np.array([[fpp, fpv, fpa], [0.0, fvv, fva], [0.0, 0.0, faa]])


def symmetric(entries) -> np.ndarray:
    pp, pv, pa, vv, va, aa = entries
    return np.array([[pp, pv, pa], [pv, vv, va], [pa, va, aa]])


def per_axis(motion, duration) -> tuple[np.ndarray, np.ndarray]:
    """The module's per-axis ``F`` and ``Q`` (at the model's intensity)."""
    alpha, q = axis_model(motion)
    if isinstance(motion, SingerMotion):
        f, noise = singer_axis_transition(alpha, duration), singer_axis_noise(alpha, duration)
    else:
        f, noise = ca_axis_transition(duration), ca_axis_noise(duration)
    return upper(f), q * symmetric(noise)


def full(axis_matrix: np.ndarray) -> np.ndarray:
    """The 6x6 of a per-axis 3x3 on ``[x, y, vx, vy, ax, ay]`` (index ``2 c + a``)."""
    return np.kron(axis_matrix, np.eye(2))


def spd6(seed: int) -> np.ndarray:
    low = np.random.default_rng(seed).standard_normal((6, 6))
    return low @ low.T + np.eye(6)


def mission_of(motion):
    return mission_record(TAU, 900.0, 30.0, 100.0, R, np.array([0.5]), motion=motion)


@pytest.mark.parametrize("motion", MOTIONS)
@pytest.mark.parametrize("duration", DURATIONS)
def test_per_axis_transition_and_noise_are_van_loans(motion, duration):
    f_ref, q_ref = scipy_van_loan(*axis_model(motion), duration)
    f, noise = per_axis(motion, duration)
    iu = np.triu_indices(3)
    np.testing.assert_allclose(f[iu], f_ref[iu], rtol=1e-10, atol=0.0)
    np.testing.assert_allclose(noise, q_ref, rtol=1e-10, atol=0.0)


BAND_EDGES = [top * (1.0 - 1e-9) for top in SINGER_SERIES_BANDS] + list(SINGER_SERIES_BANDS)


@pytest.mark.parametrize("damping", [1.0 / 60.0, 2.0])
@pytest.mark.parametrize("u", sorted([1e-6, 1e-4, 1e-3, 0.05, 0.3, 1.0, 3.0, 30.0] + BAND_EDGES))
def test_singer_keeps_its_digits_at_every_damping_time(damping, u):
    """Series below `SINGER_SERIES_BELOW` (each band's number of terms, both sides of each
    band's edge), closed forms above: every entry of ``F`` and ``Q`` to 1e-13 of a 60-digit Van
    Loan reference, from ``alpha T = 1e-6`` to 30."""
    duration = u / damping
    f_ref, q_ref = mp_van_loan(damping, 1.0, duration)
    f = upper(singer_axis_transition(damping, duration))
    noise = symmetric(singer_axis_noise(damping, duration))
    iu = np.triu_indices(3)
    np.testing.assert_allclose(f[iu], f_ref[iu], rtol=1e-13, atol=0.0)
    np.testing.assert_allclose(noise, q_ref, rtol=1e-13, atol=0.0)


@pytest.mark.parametrize("duration", [0.01, 0.5, 5.0])
def test_singer_becomes_constant_acceleration_as_the_damping_vanishes(duration):
    damping, std = 1e-7, 3.0
    f, noise = per_axis(SingerMotion(damping, std), duration)
    f_ca, noise_ca = per_axis(ConstantAccelerationMotion(2.0 * damping * std**2, std), duration)
    np.testing.assert_allclose(f, f_ca, rtol=1e-6, atol=0.0)
    np.testing.assert_allclose(noise, noise_ca, rtol=1e-6, atol=0.0)


@pytest.mark.parametrize("motion", MOTIONS)
@pytest.mark.parametrize("duration", [0.5, 37.0, 900.0])
def test_prediction_is_f_cov_f_plus_q(motion, duration):
    cov = spd6(1)
    f, noise = per_axis(motion, duration)
    big_f, big_q = full(f), full(noise)
    means, covs = BeliefMotion(TAU, motion).predict(MEAN[None], cov[None], 0.7, duration)
    np.testing.assert_allclose(means[0], big_f @ MEAN, rtol=1e-13, atol=1e-12)
    reference = big_f @ cov @ big_f.T + big_q
    np.testing.assert_allclose(covs[0], reference, rtol=1e-12, atol=1e-13 * abs(reference).max())
    np.testing.assert_allclose(
        BeliefMotion(TAU, motion).mean_positions(MEAN, [duration])[0], (big_f @ MEAN)[:2]
    )
    assert BeliefMotion(TAU, motion).state_size == 6
    assert not BeliefMotion(TAU, motion).straight


@numba.njit
def _predict_in_place(mission, cov, q, steps, mean, elapsed):
    predict_covariance_on(mission, cov, q, steps, cov)
    predict_mean_on(mission, mean, elapsed, mean)


@pytest.mark.parametrize("motion", MOTIONS)
def test_prediction_may_overwrite_its_input(motion):
    mission = mission_of(motion)
    cov, mean = spd6(2), MEAN.copy()
    expected_mean, expected_cov = BeliefMotion(TAU, motion).predict(
        mean[None], cov[None], 0.5, 13.0 * TAU
    )
    _predict_in_place(mission, cov, 0.5, 13.0, mean, 13.0 * TAU)
    np.testing.assert_array_equal(cov, expected_cov[0])
    np.testing.assert_array_equal(mean, expected_mean[0])


@numba.njit
def _position_terms(mission, cov, q, k, h):
    poly = position_polynomials_on(mission, cov, q)
    det, rate = position_det_rate_on(mission, poly, k)
    ahead = position_det_on(mission, poly, k + h)
    behind = position_det_on(mission, poly, k - h)
    return (
        position_covariance_on(mission, cov, q, k),
        position_det_on(mission, poly, k),
        det,
        rate,
        (ahead - behind) / (2.0 * h),
    )


@pytest.mark.parametrize("motion", MOTIONS)
@pytest.mark.parametrize("steps", [0.5, 37.0, 900.0])
def test_position_covariance_determinant_and_its_rate(motion, steps):
    """The position block without the 6x6, its determinant from the terms, and the exact rate
    against central differences in the step count."""
    mission = mission_of(motion)
    cov = spd6(3)
    (sxx, sxy, syy), det_only, det, rate, slope = _position_terms(
        mission, cov, 0.5, steps, 1e-4 * steps
    )
    _, covs = BeliefMotion(TAU, motion).predict(MEAN[None], cov[None], 0.5, steps * TAU)
    block = covs[0][:2, :2]
    np.testing.assert_allclose([sxx, sxy, syy], [block[0, 0], block[0, 1], block[1, 1]], 1e-12)
    assert det == det_only
    assert det == pytest.approx(np.linalg.det(block), rel=1e-11)
    assert rate == pytest.approx(slope, rel=1e-6)


@numba.njit
def _step(mission, q, f, qq):
    bm.step_matrices(mission.motion, mission.time_step, q, f, qq)


@pytest.mark.parametrize("motion", MOTIONS)
def test_step_matrices_are_van_loans_and_steps_compose(motion):
    mission = mission_of(motion)
    f, qq = np.full((6, 6), np.nan), np.full((6, 6), np.nan)
    _step(mission, 0.5, f, qq)
    f_ref, q_ref = scipy_van_loan(*axis_model(motion), TAU)
    np.testing.assert_allclose(f, full(f_ref), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(qq, full(q_ref), rtol=1e-10, atol=0.0)
    # two steps at once = one step twice
    face = BeliefMotion(TAU, motion)
    cov = spd6(4)
    m2, c2 = face.predict(MEAN[None], cov[None], 0.5, 2 * TAU)
    m1, c1 = face.predict(MEAN[None], cov[None], 0.5, TAU)
    m11, c11 = face.predict(m1, c1, 0.5, TAU)
    np.testing.assert_allclose(m11, m2, rtol=1e-12)
    np.testing.assert_allclose(c11, c2, rtol=1e-12)
    np.testing.assert_allclose(f @ cov @ f.T + qq, c1[0], rtol=1e-12)


def _within(sampled_cov, cov, n, width=4.0):
    """Every sampled covariance entry within ``width`` standard errors of ``cov``."""
    scale = np.sqrt(np.outer(np.diag(cov), np.diag(cov)) + cov**2)
    return np.all(np.abs(sampled_cov - cov) <= width * scale / n**0.5)


TRUTHS = [
    (SingerTruth(0.05, 1.5), SingerMotion(0.05, 1.5)),
    (SingerTruth(2.0, 0.7), SingerMotion(2.0, 0.7)),
    (ConstantAccelerationTruth(0.3, 1.0), ConstantAccelerationMotion(0.3, 1.0)),
]


@pytest.mark.parametrize(("truth", "motion"), TRUTHS)
def test_one_truth_step_samples_f_x_and_q(truth, motion):
    """200,000 draws of one step from one state: the mean within 5 standard errors of ``F x``,
    the covariance within 4 of ``Q`` (a ``Q`` 5 % off fails)."""
    n = 200_000
    assert truth_state_size(truth) == 6
    mission = mission_of(motion)
    states = sample_truth(truth, mission, np.repeat(MEAN[None], n, axis=0), np.zeros(n), rng(11))
    f, noise = per_axis(motion, TAU)
    big_f, big_q = full(f), full(noise)
    sd = np.sqrt(np.diag(big_q))
    assert np.all(np.abs(states.mean(axis=0) - big_f @ MEAN) < 5.0 * sd / n**0.5)
    sampled = np.cov(states.T)
    assert _within(sampled, big_q, n)
    assert not _within(sampled, 1.05 * big_q, n)
    assert not _within(sampled, 0.95 * big_q, n)


def rng(seed):
    return np.random.default_rng(seed)


@pytest.mark.parametrize(("truth", "motion"), TRUTHS)
def test_many_truth_steps_sample_the_beliefs_prediction(truth, motion):
    q, runs, steps = 0.3, 20_000, 40
    mission = mission_of(motion)
    states = np.repeat(MEAN[None], runs, axis=0)
    generator = rng(7)
    for _ in range(steps):
        states = sample_truth(truth, mission, states, np.full(runs, q), generator)
    means, covs = BeliefMotion(TAU, motion).predict(MEAN[None], np.zeros((1, 6, 6)), q, steps * TAU)
    sd = np.sqrt(np.diag(covs[0]))
    assert np.all(np.abs(states.mean(axis=0) - means[0]) < 4 * sd / runs**0.5)
    assert _within(np.cov(states.T), covs[0], runs)


def test_the_extended_prior_appends_an_uncorrelated_acceleration():
    mean4 = np.array([1.0, 2.0, 3.0, 4.0])
    cov4 = spd6(5)[:4, :4]
    for part in (ConstantVelocity(TAU), RandomWalkMotion(2.0), OrnsteinUhlenbeckMotion(0.1)):
        mean, cov = extended_prior(part, mean4, cov4)
        assert mean is mean4 and cov is cov4
    for part in (SingerMotion(0.05, 1.5), ConstantAccelerationMotion(0.3, 1.5)):
        mean, cov = extended_prior(part, mean4, cov4)
        assert mean.shape == (6,) and cov.shape == (6, 6)
        np.testing.assert_array_equal(mean, [1.0, 2.0, 3.0, 4.0, 0.0, 0.0])
        np.testing.assert_array_equal(cov[:4, :4], cov4)
        np.testing.assert_array_equal(cov[4:, :4], 0.0)
        np.testing.assert_array_equal(cov[:4, 4:], 0.0)
        np.testing.assert_array_equal(cov[4:, 4:], 2.25 * np.eye(2))
        stacked_mean, stacked_cov = extended_prior(part, mean4[None], cov4[None])
        np.testing.assert_array_equal(stacked_mean[0], mean)
        np.testing.assert_array_equal(stacked_cov[0], cov)
        six = extended_prior(part, mean, cov)
        assert six[0] is mean and six[1] is cov
    with pytest.raises(ValueError, match="no belief motion registered"):
        extended_prior((1.0,), mean4, cov4)
