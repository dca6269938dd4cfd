"""A detection probability below one: the scenario's ``sensor.detection_probability`` (a number
or a range table, one-line errors), the sensor part it builds, the rule ``u < Pd(d)`` through the
dispatch, a simulator that draws it from a fifth stream (Pd = 1: the same episodes bit for bit as
without the field) and detects at the rate it says."""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import MissionSpec
from hptrack.models.sensor import (
    DetectingFootprintSensor,
    FootprintSensor,
    detection_table,
    measured_mask,
    pass_detection_factor,
    pass_probability,
    sensor_detects,
    sensor_draws,
    sensor_find_factor,
    table_probability,
)
from hptrack.scenario import parse_scenario, random_scenario
from hptrack.scenario.io import ScenarioError, file_data
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World

TABLE = [[0.0, 0.9], [20.0, 0.9], [40.0, 0.6]]


def _data(budget: float = 60.0, n: int = 3, seed: int = 4, **sensor) -> dict:
    data = file_data(random_scenario(n, seed=seed, budget=budget))
    if sensor:
        data["sensor"] = sensor
    return data


@numba.njit
def _dispatch(sensor, ax, ay, x, y, u):
    return sensor_draws(sensor), sensor_detects(sensor, ax, ay, x, y, u), sensor_find_factor(sensor)


def test_the_field_omitted_or_one_is_the_papers_sensor():
    plain = parse_scenario(_data())
    assert plain.sensor_spec().detection_probability == 1.0
    for value in (1, 1.0, [[0.0, 1.0]], [[0.0, 1.0], [30.0, 1.0]]):
        scenario = parse_scenario(_data(detection_probability=value))
        sensor = scenario.mission_spec().record.sensor
        assert type(sensor) is FootprintSensor
        assert _dispatch(sensor, 0.0, 0.0, 1.0, 1.0, 0.999) == (False, True, 1.0)
    # a file that leaves it at 1 is written without it
    assert "detection_probability" not in file_data(
        parse_scenario(_data(detection_probability=1.0))
    ).get("sensor", {})


def test_a_number_and_a_table_build_a_detecting_sensor():
    number = parse_scenario(_data(detection_probability=0.7))
    assert number.sensor_spec().detection_probability == 0.7
    sensor = number.mission_spec().record.sensor
    assert type(sensor) is DetectingFootprintSensor
    assert sensor.distances.tolist() == [0.0] and sensor.probabilities.tolist() == [0.7]
    assert _dispatch(sensor, 0.0, 0.0, 10.0, 0.0, 0.69)[:2] == (True, True)
    assert _dispatch(sensor, 0.0, 0.0, 10.0, 0.0, 0.7)[:2] == (True, False)
    table = parse_scenario(_data(detection_probability=TABLE))
    assert table.sensor_spec().detection_probability == tuple(map(tuple, TABLE))
    sensor = table.mission_spec().record.sensor
    # linear between rows, the last held to the edge; the rule at the distance from the centre
    for d, want in ((0.0, 0.9), (20.0, 0.9), (30.0, 0.75), (40.0, 0.6), (50.0, 0.6)):
        assert table_probability(sensor.distances, sensor.probabilities, d) == pytest.approx(want)
        assert _dispatch(sensor, 3.0, 4.0, 3.0, 4.0 + d, want - 1e-9)[1]
        assert not _dispatch(sensor, 3.0, 4.0, 3.0, 4.0 + d, want + 1e-9)[1]
    # the written file loads back to the same sensor
    again = parse_scenario(file_data(table))
    assert again.sensor_spec() == table.sensor_spec()


@pytest.mark.parametrize(
    ("value", "says"),
    [
        (1.5, "must be in (0, 1]"),
        (0.0, "must be in (0, 1]"),
        (True, "expected a number"),
        ("0.5", "expected a number"),
        ([], "no rows"),
        ([[5.0, 0.5]], "first distance must be 0"),
        ([[0.0, 0.5], [10.0, 0.4], [10.0, 0.3]], "increase strictly"),
        ([[0.0, 1.2]], "each Pd must be in [0, 1]"),
        ([[0.0, 0.5, 1.0]], "row 0 must be two numbers"),
        ([[0.0, 0.0]], "never detects"),
    ],
)
def test_a_bad_value_is_one_line_naming_the_field(value, says):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(_data(detection_probability=value))
    text = str(err.value)
    assert "\n" not in text and "sensor.detection_probability: " in text and says in text


def test_the_mission_spec_checks_it_too():
    with pytest.raises(ValueError, match="detection_probability: .*in \\(0, 1\\]"):
        MissionSpec(detection_probability=2.0)
    assert type(MissionSpec(detection_probability=0.5).record.sensor) is DetectingFootprintSensor


def _episode(data: dict, seed: int = 11):
    return run_episode(parse_scenario(data), GreedyPlanner(), seed=seed)


def test_pd_one_gives_the_same_episodes_bit_for_bit():
    for seed in (1, 5):
        plain = _episode(_data(budget=120.0), seed)
        one = _episode(_data(budget=120.0, detection_probability=1.0), seed)
        assert plain.detections.any()
        np.testing.assert_array_equal(plain.detections, one.detections)
        np.testing.assert_array_equal(plain.agent_paths, one.agent_paths)
        np.testing.assert_array_equal(plain.belief_means, one.belief_means)
        np.testing.assert_array_equal(plain.per_target_logdet, one.per_target_logdet)


def _inside(record, sensor) -> np.ndarray:
    """``(K+1, n)``: which targets were inside the footprint at each step."""
    return np.array(
        [
            measured_mask(sensor, record.agent_paths[k, 0], record.true_states[k, :, :2])
            for k in range(record.agent_paths.shape[0])
        ]
    )


def _cluster(**sensor) -> dict:
    """Four slow targets within 30 m of each other, the agent among them."""
    cov = [[100.0, 0, 0, 0], [0, 100.0, 0, 0], [0, 0, 0.5, 0], [0, 0, 0, 0.5]]
    starts = [(0.0, 0.0), (20.0, 0.0), (0.0, 20.0), (-20.0, -10.0)]
    targets = [
        {
            "id": f"t{i}",
            "mean": [x, y, 1.0, 0.0],
            "covariance": cov,
            "process_noise": 1e-6,
            "truth": [x, y, 1.0, 0.0],
        }
        for i, (x, y) in enumerate(starts)
    ]
    data = {"budget": 300.0, "seed": 3, "targets": targets}
    if sensor:
        data["sensor"] = sensor
    return data


def test_half_of_the_looks_inside_the_footprint_detect_at_pd_one_half():
    world = World(parse_scenario(_cluster(detection_probability=0.5)))
    sensor = world.mission.record.sensor
    looks = hits = 0
    while True:
        inside = measured_mask(sensor, world.agent, world.truth[:, :2])
        assert not np.any(world.seen & ~inside)  # only targets inside are detected
        looks += int(inside.sum())
        hits += int((world.seen & inside).sum())
        if world.done:
            break
        world.step(*world.truth[:, :2].mean(axis=0))
    assert looks > 1500
    rate, se = hits / looks, math.sqrt(0.25 / looks)
    assert abs(rate - 0.5) < 4.0 * se, (rate, se, looks)


def test_the_detection_stream_is_a_fifth_one():
    """The truth and the measurement noise of a detecting world are the plain world's: the
    first four streams are untouched (a missed look draws no measurement noise)."""
    plain = run_episode(parse_scenario(_cluster()), GreedyPlanner(), seed=2)
    half = run_episode(parse_scenario(_cluster(detection_probability=0.5)), GreedyPlanner(), 2)
    np.testing.assert_array_equal(plain.true_states[0], half.true_states[0])
    assert half.detections.sum() < plain.detections.sum()


def test_the_pass_factor_is_one_at_pd_one_and_follows_the_looks():
    certain = detection_table(1.0)
    assert pass_detection_factor(*certain, 100.0, 15.0) == 1.0
    # one look per pass (a step longer than the footprint): the factor is Pd itself
    assert pass_detection_factor(*detection_table(0.6), 100.0, 1000.0) == pytest.approx(0.6)
    # many looks per pass: a target near the line is all but surely detected
    offsets = np.array([0.0, 25.0, 49.0])
    p = pass_probability(*detection_table(0.5), 50.0, 15.0, offsets)
    assert p[0] == pytest.approx(1.0 - 0.5 ** (100.0 / 15.0), abs=0.01)
    assert p[0] > p[1] > p[2]
    # a continuum of looks detects surely where Pd > 0
    assert pass_detection_factor(*detection_table(0.5), 100.0, 1e-4) == pytest.approx(1.0)
