"""The footprint sensor part of the mission record (paper Sec. III), through its compile-time
dispatch: the footprint's edge exactly, the update is the Kalman update with the record's ``R``,
a look that misses leaves the belief alone."""

import numba
import numpy as np
import pytest

from hptrack.interface import MissionSpec
from hptrack.models.measurement import PositionMeasurementModel, kalman_update
from hptrack.models.sensor import (
    FootprintSensor,
    measured_mask,
    sensor_measures,
    sensor_missed,
    sensor_reach,
    sensor_update,
    sensor_update_covariance,
)

R = np.array([[10.0, 2.0], [2.0, 12.0]])
SENSOR = FootprintSensor(100.0, R)


@numba.njit
def _look(sensor, agent, target, mean, cov, z, mean_out, cov_out, cov_only):
    seen = sensor_measures(sensor, agent[0], agent[1], target[0], target[1])
    if seen:
        sensor_update(sensor, mean, cov, z, mean_out, cov_out)
        sensor_update_covariance(sensor, cov, cov_only)
    else:
        sensor_missed(sensor, agent[0], agent[1], mean, cov)
    return seen, sensor_reach(sensor)


def _belief():
    mean = np.array([40.0, -10.0, 1.0, 2.0])
    cov = np.diag([400.0, 300.0, 1.0, 2.0])
    cov[0, 1] = cov[1, 0] = 50.0
    return mean, cov


@pytest.mark.parametrize(
    ("target", "seen"),
    [((30.0, 40.0), True), ((0.0, -50.0), True), ((30.0, 40.001), False), ((0.0, 0.0), True)],
)
def test_a_look_measures_exactly_the_targets_within_half_the_diameter(target, seen):
    mean, cov = _belief()
    mean_out, cov_out, cov_only = np.empty(4), np.empty((4, 4)), np.empty((4, 4))
    z = np.array([35.0, -5.0])
    got, reach = _look(
        SENSOR, np.zeros(2), np.array(target), mean, cov, z, mean_out, cov_out, cov_only
    )
    assert (got, reach) == (seen, 50.0)
    if seen:  # the update is the Kalman update with R, the covariance the same as the full one
        want_mean, want_cov = np.empty(4), np.empty((4, 4))
        kalman_update(mean, cov, z, R, want_mean, want_cov)
        np.testing.assert_array_equal(mean_out, want_mean)
        np.testing.assert_array_equal(cov_out, want_cov)
        np.testing.assert_array_equal(cov_only, want_cov)
    else:  # nothing is learnt from a miss
        np.testing.assert_array_equal(mean, _belief()[0])
        np.testing.assert_array_equal(cov, _belief()[1])


def test_the_numpy_faces_agree_with_the_kernel():
    rng = np.random.default_rng(3)
    points = rng.uniform(-80.0, 80.0, (500, 2))
    agent = np.array([5.0, -3.0])
    want = np.hypot(*(points - agent).T) <= 50.0  # an independent distance
    mask = measured_mask(SENSOR, agent, points)
    np.testing.assert_array_equal(mask, want)
    np.testing.assert_array_equal(
        PositionMeasurementModel(R, 100.0).in_footprint(agent, points), want
    )


def test_the_mission_record_holds_the_scenarios_sensor():
    spec = MissionSpec(sensor_diameter=80.0, measurement_noise=R)
    assert spec.record.sensor.diameter == 80.0
    np.testing.assert_array_equal(spec.record.sensor.measurement_noise, R)
    assert measured_mask(spec.record.sensor, np.zeros(2), [[40.0, 0.0], [40.01, 0.0]]).tolist() == [
        True,
        False,
    ]
