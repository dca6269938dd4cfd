import numpy as np
import pytest
from textbook import H, joseph_update, kalman_gain, random_spd

from hptrack.models.beliefs import logdet_xy, position_logdet
from hptrack.models.measurement import (
    PositionMeasurementModel,
    check_noise_covariance,
    kalman_update,
    update_covariance,
)
from hptrack.models.motion import ConstantVelocityModel
from hptrack.scenario.random import random_prior

FULL_R = np.array([[12.0, 5.0], [5.0, 7.0]])
"""A measurement noise with correlated axes, m^2."""


def close(got, expected, rtol=1e-12):
    np.testing.assert_allclose(
        got, expected, rtol=rtol, atol=rtol * float(np.max(np.abs(expected)))
    )


def test_update_equals_textbook_kalman():
    sensor = PositionMeasurementModel.isotropic(2.0)
    cov, _ = random_prior(np.random.default_rng(3))
    cov[0, 2] = cov[2, 0] = 3.0
    mean = np.array([10.0, -5.0, 1.0, 2.0])
    z = np.array([14.0, -2.0])
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    r = 4.0 * np.eye(2)
    gain = cov @ h.T @ np.linalg.inv(h @ cov @ h.T + r)
    expected_mean = mean + gain @ (z - h @ mean)
    expected_cov = (np.eye(4) - gain @ h) @ cov
    got_mean, got_cov = sensor.update(mean[None], cov[None], z[None])
    np.testing.assert_allclose(got_mean[0], expected_mean, rtol=1e-12)
    np.testing.assert_allclose(got_cov[0], expected_cov, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_update_covariance_with_a_full_r_is_the_textbook_update(seed):
    cov = random_spd(np.random.default_rng(seed))
    joseph = joseph_update(cov, FULL_R)
    simple = (np.eye(4) - kalman_gain(cov, FULL_R) @ H) @ cov
    close(joseph, simple, rtol=1e-10)  # the reference agrees with itself
    out = np.full((4, 4), np.nan)
    update_covariance(cov, FULL_R, out)
    close(out, joseph, rtol=1e-11)
    np.testing.assert_array_equal(out, out.T)
    in_place = cov.copy()
    update_covariance(in_place, FULL_R, in_place)
    np.testing.assert_array_equal(in_place, out)


@pytest.mark.parametrize("seed", range(4))
def test_kalman_update_with_a_full_r_is_the_textbook_update(seed):
    rng = np.random.default_rng(100 + seed)
    cov = random_spd(rng)
    mean = rng.normal(size=4) * [300.0, 300.0, 2.0, 2.0]
    z = mean[:2] + rng.normal(size=2) * 20.0
    gain = kalman_gain(cov, FULL_R)
    mean_out, cov_out = np.empty(4), np.empty((4, 4))
    kalman_update(mean, cov, z, FULL_R, mean_out, cov_out)
    close(mean_out, mean + gain @ (z - H @ mean))
    close(cov_out, joseph_update(cov, FULL_R), rtol=1e-11)
    m, c = mean.copy(), cov.copy()
    kalman_update(m, c, z, FULL_R, m, c)  # in place
    np.testing.assert_array_equal(m, mean_out)
    np.testing.assert_array_equal(c, cov_out)


def test_measurement_model_with_a_full_r_updates_stacked_beliefs():
    rng = np.random.default_rng(8)
    sensor = PositionMeasurementModel(FULL_R, sensor_diameter=80.0)
    covs = np.stack([random_spd(rng) for _ in range(3)])
    means = rng.normal(size=(3, 4)) * 100.0
    z = means[:, :2] + rng.normal(size=(3, 2)) * 5.0
    got_m, got_c = sensor.update(means, covs, z)
    for i in range(3):
        close(got_m[i], means[i] + kalman_gain(covs[i], FULL_R) @ (z[i] - H @ means[i]))
        close(got_c[i], joseph_update(covs[i], FULL_R), rtol=1e-11)
    np.testing.assert_array_equal(sensor.noise_covariance, FULL_R)
    assert sensor.sensor_diameter == 80.0
    np.testing.assert_array_equal(
        PositionMeasurementModel.isotropic(3.0).noise_covariance, 9.0 * np.eye(2)
    )
    np.testing.assert_array_equal(PositionMeasurementModel().noise_covariance, 10.0 * np.eye(2))


def test_sampled_measurements_have_the_full_noise_covariance():
    r = np.array([[10.0, 6.0], [6.0, 5.0]])
    sensor = PositionMeasurementModel(r)
    truth = np.tile([[250.0, -80.0]], (200_000, 1))
    errors = sensor.sample(truth, np.random.default_rng(0)) - truth
    np.testing.assert_allclose(errors.mean(axis=0), 0.0, atol=0.03)
    # Standard error of each entry ~ sqrt((r_ii r_jj + r_ij^2) / N) <= 0.03 m^2; a wrong factor
    # (L' instead of L gives [[13.6, 2.2], [2.2, 1.4]], sqrt of the diagonal gives no
    # correlation) misses by more than 2 m^2.
    np.testing.assert_allclose(np.cov(errors.T), r, atol=0.15)
    factor = np.linalg.cholesky(r)
    assert not np.allclose(factor.T @ factor, r, atol=0.15)


@pytest.mark.parametrize(
    ("noise", "match"),
    [
        (np.array([[10.0, 1.0], [0.0, 10.0]]), "not symmetric"),
        (np.array([[10.0, 11.0], [11.0, 10.0]]), "not positive definite"),
        (np.array([[np.nan, 0.0], [0.0, 1.0]]), "finite 2x2"),
        (np.eye(3), "finite 2x2"),
    ],
)
def test_bad_noise_covariances_are_refused(noise, match):
    with pytest.raises(ValueError, match=match):
        check_noise_covariance(noise)
    with pytest.raises(ValueError, match=match):
        PositionMeasurementModel(noise)


def test_covariance_stays_spd_over_thousands_of_updates():
    rng = np.random.default_rng(1)
    cov, q = random_prior(rng)
    motion, sensor = ConstantVelocityModel(), PositionMeasurementModel()
    means, covs = np.zeros((1, 4)), cov[None]
    for k in range(5000):
        means, covs = motion.predict(means, covs, np.array([q]), 0.5)
        if k % 3:
            means, covs = sensor.update(means, covs, rng.normal(size=(1, 2)))
    c = covs[0]
    np.testing.assert_array_equal(c, c.T)
    assert np.linalg.eigvalsh(c).min() > 0
    # measured two steps in three: below one measurement's det R = 100 m^4, far from 0
    assert -3.0 < position_logdet(covs)[0] < np.log(10.0**2)


def test_footprint_boundary_is_inclusive():
    sensor = PositionMeasurementModel(sensor_diameter=100.0)
    pos = np.array([[50.0, 0.0], [50.0 + 1e-9, 0.0], [30.0, 40.0], [0.0, -50.1]])
    np.testing.assert_array_equal(sensor.in_footprint(np.zeros(2), pos), [True, False, True, False])


def test_uncertainty_is_sum_of_position_logdets():
    covs = np.array([np.diag([4.0, 9.0, 1.0, 1.0]), np.diag([1.0, 1.0, 5.0, 5.0])])
    covs[0, 0, 1] = covs[0, 1, 0] = 2.0
    assert np.sum(position_logdet(covs)) == np.log(36.0 - 4.0) + np.log(1.0)
    np.testing.assert_allclose(position_logdet(covs), [np.log(32.0), 0.0])


def test_logdet_kernel_matches_numpy():
    cov = random_spd(np.random.default_rng(4))
    sign, expected = np.linalg.slogdet(cov[:2, :2])
    assert sign > 0
    assert logdet_xy(cov[0, 0], cov[0, 1], cov[1, 1]) == pytest.approx(expected, rel=1e-13)


@pytest.mark.parametrize("seed", range(4))
def test_a_six_entry_state_takes_the_textbook_update(seed):
    """A state with accelerations ``[x, y, vx, vy, ax, ay]``: the update of any length is the
    textbook's (Joseph form), symmetric, the same in place, and agrees with the written-out 4-D
    update on the 4-D block of a state whose accelerations are uncorrelated."""
    rng = np.random.default_rng(200 + seed)
    a = rng.normal(size=(6, 6)) * [30.0, 30.0, 1.0, 1.0, 0.1, 0.1]
    cov = a @ a.T + np.diag([50.0, 50.0, 0.5, 0.5, 0.01, 0.01])
    mean = rng.normal(size=6) * [300.0, 300.0, 2.0, 2.0, 0.1, 0.1]
    z = mean[:2] + rng.normal(size=2) * 20.0
    h = np.hstack([np.eye(2), np.zeros((2, 4))])
    gain = cov @ h.T @ np.linalg.inv(h @ cov @ h.T + FULL_R)
    joseph = (np.eye(6) - gain @ h) @ cov @ (np.eye(6) - gain @ h).T + gain @ FULL_R @ gain.T
    mean_out, cov_out = np.empty(6), np.empty((6, 6))
    kalman_update(mean, cov, z, FULL_R, mean_out, cov_out)
    close(mean_out, mean + gain @ (z - h @ mean))
    close(cov_out, joseph, rtol=1e-10)
    np.testing.assert_array_equal(cov_out, cov_out.T)
    only_cov = np.empty((6, 6))
    update_covariance(cov, FULL_R, only_cov)
    np.testing.assert_array_equal(only_cov, cov_out)
    m, c = mean.copy(), cov.copy()
    kalman_update(m, c, z, FULL_R, m, c)
    np.testing.assert_array_equal(m, mean_out)
    np.testing.assert_array_equal(c, cov_out)
    block = cov.copy()
    block[4:, :4] = block[:4, 4:] = 0.0
    four = np.empty((4, 4))
    update_covariance(np.ascontiguousarray(block[:4, :4]), FULL_R, four)
    six = np.empty((6, 6))
    update_covariance(block, FULL_R, six)
    close(six[:4, :4], four, rtol=1e-12)
