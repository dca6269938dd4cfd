import numpy as np

from hptrack.models.beliefs import TargetBeliefs, position_logdet
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel
from hptrack.scenario.random import random_prior


def test_update_equals_textbook_kalman():
    sensor = PositionMeasurementModel(noise_std=2.0)
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


def test_covariance_stays_spd_over_thousands_of_updates():
    rng = np.random.default_rng(1)
    cov, q = random_prior(rng)
    beliefs = TargetBeliefs(np.zeros((1, 4)), cov[None], np.array([q]),
                            ConstantVelocityModel(), PositionMeasurementModel())
    for k in range(5000):
        beliefs.predict(1)
        if k % 3:
            beliefs.update(np.array([0]), rng.normal(size=(1, 2)))
    c = beliefs.covariances[0]
    np.testing.assert_array_equal(c, c.T)
    assert np.linalg.eigvalsh(c).min() > 0
    # measured two steps in three: below one measurement's det R = 100 m^4, far from 0
    assert -3.0 < beliefs.position_logdets()[0] < np.log(10.0**2)


def test_footprint_boundary_is_inclusive():
    sensor = PositionMeasurementModel(sensor_diameter=100.0)
    pos = np.array([[50.0, 0.0], [50.0 + 1e-9, 0.0], [30.0, 40.0], [0.0, -50.1]])
    np.testing.assert_array_equal(sensor.in_footprint(np.zeros(2), pos),
                                  [True, False, True, False])


def test_uncertainty_is_sum_of_position_logdets():
    covs = np.array([np.diag([4.0, 9.0, 1.0, 1.0]), np.diag([1.0, 1.0, 5.0, 5.0])])
    covs[0, 0, 1] = covs[0, 1, 0] = 2.0
    beliefs = TargetBeliefs(np.zeros((2, 4)), covs, np.zeros(2), ConstantVelocityModel(),
                            PositionMeasurementModel())
    assert beliefs.uncertainty() == np.log(36.0 - 4.0) + np.log(1.0)
    np.testing.assert_allclose(position_logdet(covs), [np.log(32.0), 0.0])
