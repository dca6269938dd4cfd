"""The scenario's ``sensor.negative_information``: off by default (the paper's records and
episodes bit for bit), one-line errors, the sensor part it selects, and a simulator whose
beliefs change only where a look missed."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import MissionSpec
from hptrack.models.sensor import (
    DetectingFootprintSensor,
    FootprintSensor,
    NegativeInformationSensor,
)
from hptrack.scenario import parse_scenario, random_scenario
from hptrack.scenario.io import ScenarioError, file_data
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World


def _data(n: int = 3, seed: int = 4, **sensor) -> dict:
    data = file_data(random_scenario(n, seed=seed, budget=60.0))
    if sensor:
        data["sensor"] = sensor
    return data


def test_off_by_default_and_written_only_when_on():
    plain = parse_scenario(_data())
    assert plain.sensor_spec().negative_information is False
    assert type(plain.mission_spec().record.sensor) is FootprintSensor
    off = parse_scenario(_data(detection_probability=0.7, negative_information=False))
    assert type(off.mission_spec().record.sensor) is DetectingFootprintSensor
    assert "negative_information" not in file_data(off)["sensor"]
    on = parse_scenario(_data(detection_probability=0.7, negative_information=True))
    sensor = on.mission_spec().record.sensor
    assert type(sensor) is NegativeInformationSensor
    assert sensor.probabilities.tolist() == [0.7]
    assert sensor.find_factor == off.mission_spec().record.sensor.find_factor
    assert file_data(on)["sensor"]["negative_information"] is True
    assert parse_scenario(file_data(on)).sensor_spec() == on.sensor_spec()
    # with the paper's certain detector too: a miss then says the target is not there
    certain = MissionSpec(negative_information=True).record.sensor
    assert type(certain) is NegativeInformationSensor and certain.find_factor == 1.0


@pytest.mark.parametrize("value", ["yes", 1, None])
def test_a_bad_value_is_one_line_naming_the_field(value):
    with pytest.raises(ScenarioError) as err:
        parse_scenario(_data(negative_information=value))
    text = str(err.value)
    assert "\n" not in text and "sensor.negative_information: " in text


@pytest.mark.parametrize("pd", [1.0, 0.7])
def test_false_gives_the_same_episodes_bit_for_bit(pd):
    plain = run_episode(parse_scenario(_data(detection_probability=pd)), GreedyPlanner(), 5)
    off = _data(detection_probability=pd, negative_information=False)
    again = run_episode(parse_scenario(off), GreedyPlanner(), 5)
    assert plain.detections.any()
    for name in ("detections", "agent_paths", "belief_means", "belief_covariances"):
        np.testing.assert_array_equal(getattr(plain, name), getattr(again, name))
    np.testing.assert_array_equal(plain.per_target_logdet, again.per_target_logdet)


def test_the_mission_spec_checks_it_too():
    with pytest.raises(ValueError, match="negative_information must be true or false"):
        MissionSpec(negative_information="yes")  # type: ignore[arg-type]


def _cluster(**sensor) -> dict:
    """Four slow targets within 30 m of each other, the agent beside them."""
    cov = [[400.0, 0, 0, 0], [0, 400.0, 0, 0], [0, 0, 0.5, 0], [0, 0, 0, 0.5]]
    starts = [(0.0, 0.0), (30.0, 0.0), (0.0, 30.0), (-30.0, -20.0)]
    targets = [
        {
            "id": f"t{i}",
            "mean": [x, y, 1.0, 0.0],
            "covariance": cov,
            "process_noise": 1e-4,
            "truth": [x + 5.0, y - 5.0, 1.0, 0.0],
        }
        for i, (x, y) in enumerate(starts)
    ]
    return {"budget": 120.0, "seed": 3, "targets": targets, "sensor": sensor}


def test_the_simulator_changes_beliefs_only_where_a_look_missed():
    off = World(parse_scenario(_cluster(detection_probability=0.7)))
    on = World(parse_scenario(_cluster(detection_probability=0.7, negative_information=True)))
    n = off.n_targets
    first_miss = np.full(n, -1)
    differed = np.zeros(n, dtype=bool)
    k = 0
    while True:
        # the same worlds: the same truths, looks and detections
        np.testing.assert_array_equal(off.truth, on.truth)
        np.testing.assert_array_equal(off.seen, on.seen)
        for i in range(n):
            if first_miss[i] < 0 and not on.seen[i]:
                first_miss[i] = k
            same = np.array_equal(off.means[i], on.means[i]) and np.array_equal(
                off.covariances[i], on.covariances[i]
            )
            if first_miss[i] < 0:
                assert same, (i, k)  # never missed yet: bit for bit the plain belief
            differed[i] |= not same
        if on.done:
            break
        waypoint = on.truth[:, :2].mean(axis=0) + [60.0 * np.cos(0.1 * k), 60.0 * np.sin(0.1 * k)]
        off.step(*waypoint)
        on.step(*waypoint)
        k += 1
    assert np.all(first_miss >= 0) and np.all(differed)
    assert on.uncertainty != off.uncertainty


def test_the_cli_refuses_a_bad_value_in_one_line_before_any_work(cli, tmp_path):
    data = _data(detection_probability=0.7, negative_information=True)
    data["sensor"]["negative_information"] = "yes"
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    cli("simulate", path).refused("sensor.negative_information: ")
