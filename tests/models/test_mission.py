"""The mission record (:mod:`hptrack.models.mission`): built and validated once, and the rules
on it."""

import math

import numpy as np
import pytest

from hptrack.interface import MissionSpec
from hptrack.models.mission import (
    MAX_TARGETS,
    follow_tables,
    mission_record,
    predict_covariance_on,
    reachable_before_budget,
    steps_left,
)
from hptrack.models.motion import ConstantVelocityModel
from hptrack.models.sensor import FootprintSensor
from hptrack.models.vehicle import HolonomicVehicle
from hptrack.scenario.random import random_scenario

R = np.array([[10.0, 1.0], [1.0, 12.0]])


def test_record_holds_the_derived_constants():
    rec = mission_record(0.5, 900.0, 30.0, 100.0, R, [3e-4, 1e-4])
    assert rec.time_step == 0.5
    assert rec.vehicle == HolonomicVehicle(speed=30.0, step_length=15.0)
    assert type(rec.sensor) is FootprintSensor and rec.sensor.diameter == 100.0
    np.testing.assert_array_equal(rec.sensor.measurement_noise, R)
    assert (rec.n_steps, rec.motion.velocity_variance_per_q) == (1800, 0.5)
    assert rec.process_noise.tolist() == [3e-4, 1e-4]
    assert (
        not rec.process_noise.flags.writeable and not rec.sensor.measurement_noise.flags.writeable
    )
    paper = mission_record(0.25, 10.0, 20.0, 80.0, R, [0.0], continuous_noise=False)
    assert (paper.n_steps, paper.motion.velocity_variance_per_q) == (40, 1.0)


def test_the_record_is_the_velocity_block_of_q_over_q():
    """The motion part's ``velocity_variance_per_q`` is what its name says: the velocity block
    of the per-step ``Q`` divided by ``q``, for both forms of ``Q``."""
    for form, continuous in (("continuous", True), ("paper_text", False)):
        q = 3e-4
        rec = mission_record(0.5, 900.0, 30.0, 100.0, R, [q], continuous)
        block = ConstantVelocityModel(0.5, form).process_noise(q)[2, 2]
        assert block / q == pytest.approx(rec.motion.velocity_variance_per_q, rel=1e-12)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"time_step": 0.0}, "time_step must be a positive"),
        ({"budget": math.inf}, "budget must be a positive"),
        ({"agent_speed": -1.0}, "agent_speed must be a positive"),
        ({"sensor_diameter": True}, "sensor_diameter must be a positive"),
        ({"measurement_noise": -np.eye(2)}, "positive definite"),
        ({"process_noise": [1e-4, -1e-4]}, "process_noise must be finite and >= 0"),
        ({"process_noise": np.full(MAX_TARGETS + 1, 1e-4)}, f"at most {MAX_TARGETS} targets"),
    ],
)
def test_record_validation(change, message):
    args = {
        "time_step": 0.5,
        "budget": 900.0,
        "agent_speed": 30.0,
        "sensor_diameter": 100.0,
        "measurement_noise": R,
        "process_noise": [1e-4],
    } | change
    with pytest.raises(ValueError, match=message):
        mission_record(**args)
    spec_args = {k: v for k, v in args.items()}
    with pytest.raises(ValueError, match=message):
        MissionSpec(**spec_args)


def test_mission_spec_builds_its_record_once_with_the_same_constants():
    spec = MissionSpec(time_step=0.25, budget=30.0, process_noise=[2e-4, 0.0])
    assert spec.record is spec.record
    assert spec.n_steps == spec.record.n_steps == 120
    assert spec.record.vehicle.step_length == spec.step_length
    assert spec.record.vehicle.speed == spec.agent_speed
    assert spec.record.sensor.diameter == spec.sensor_diameter
    assert spec.record.sensor.measurement_noise is spec.measurement_noise
    assert spec.record.process_noise is spec.process_noise


def test_steps_left_counts_whole_steps_with_the_rounding_slack():
    assert steps_left(0.5, 900.0) == 1800
    assert 0.3 / 0.1 < 3.0 and steps_left(0.1, 0.3) == 3  # 2.9999999999999996 steps
    assert steps_left(0.1, 0.29) == 2
    assert steps_left(0.5, 0.49) == 0
    scenario = random_scenario(2, seed=0)
    assert scenario.n_steps == steps_left(scenario.time_step, scenario.budget)
    assert scenario.n_steps == scenario.mission_spec().n_steps


def test_reachable_before_budget_is_strict():
    assert reachable_before_budget(0, 1) and reachable_before_budget(9, 10)
    assert not reachable_before_budget(10, 10)
    assert not reachable_before_budget(-1, 10)  # never intercepted


def test_follow_tables_for_a_mission_hold_for_any_shorter_horizon():
    """Tables built once for the mission's ``N`` agree with those of a shorter horizon on every
    entry the shorter one holds."""
    rec = mission_record(0.5, 900.0, 30.0, 100.0, R, [3e-4, 0.0, 1e-3])
    full, short = follow_tables(rec), follow_tables(rec, 40)
    assert full.a.shape[0] == 3 and short.length.max() <= 41
    for i in range(3):
        k = int(short.length[i])
        assert full.length[i] >= k
        for name in ("a", "g", "h"):
            np.testing.assert_array_equal(getattr(full, name)[i, :k], getattr(short, name)[i, :k])


def test_prediction_on_the_record_is_the_motion_model():
    rec = mission_record(0.5, 900.0, 30.0, 100.0, R, [3e-4])
    cov = np.diag([100.0, 200.0, 1.0, 2.0])
    out = np.empty((4, 4))
    predict_covariance_on(rec, cov, 3e-4, 7, out)
    _, expected = ConstantVelocityModel(0.5).predict(np.zeros((1, 4)), cov[None], 3e-4, 3.5)
    np.testing.assert_allclose(out, expected[0], rtol=1e-12)
