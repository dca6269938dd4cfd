"""A benchmark whose detector misses, and the planners told the paper's sensor ("blind")."""

import dataclasses

import numpy as np
import pytest

from hptrack.baselines.stationary import StationaryPlanner
from hptrack.experiments.benchmark import (
    BenchmarkConfig,
    planner_for,
    planner_mission_for,
    run_benchmark,
    scenario_for,
)
from hptrack.experiments.store import ResultStore
from hptrack.interface import InputError
from hptrack.models.sensor import DetectingFootprintSensor, FootprintSensor
from hptrack.registry import planner_settings
from hptrack.scenario import random_scenario
from hptrack.scenario.model import FootprintSensorSpec
from hptrack.sim.episode import run_episode


class Told(StationaryPlanner):
    """The stationary planner, remembering the mission it was told."""

    def reset(self, mission, observation, rng):
        self.told = mission
        super().reset(mission, observation, rng)


def missing(pd=0.5, n=3, seed=4):
    return random_scenario(
        n, seed, homogeneous=True, sensor=FootprintSensorSpec(detection_probability=pd)
    )


def test_the_planner_is_told_the_given_mission_and_the_world_stays_the_same():
    scenario = missing()
    world = scenario.mission_spec()
    paper = dataclasses.replace(world, detection_probability=1.0)
    known, blind = Told(), Told()
    a = run_episode(scenario, known)
    b = run_episode(scenario, blind, planner_mission=paper)
    assert known.told.detection_probability == 0.5 and blind.told.detection_probability == 1.0
    assert isinstance(known.told.record.sensor, DetectingFootprintSensor)
    assert isinstance(blind.told.record.sensor, FootprintSensor)
    np.testing.assert_array_equal(a.detections, b.detections)  # the world's detector, both
    assert a.uncertainty == b.uncertainty


def test_a_mission_of_other_targets_is_refused():
    other = random_scenario(4, 4, homogeneous=True).mission_spec()
    with pytest.raises(ValueError, match="planner_mission"):
        run_episode(missing(), StationaryPlanner(), planner_mission=other)


def config(**kw):
    planners = ("greedy", "mcts")
    settings = {
        p: planner_settings(p, {"iterations": 200} if p == "mcts" else None) for p in planners
    }
    return BenchmarkConfig(
        planners=planners, settings=settings, target_counts=(3,), scenarios=1, **kw
    )


def test_the_detection_probability_and_blindness_are_part_of_the_identity():
    known, blind = config(detection_probability=0.7), config(detection_probability=0.7, blind=True)
    assert known.setting == "homogeneous+pd:0.7"
    assert blind.setting == "homogeneous+pd:0.7+blind"
    assert config().setting == "homogeneous"
    k, b = known.keys()[1], blind.keys()[1]
    assert scenario_for(k) == scenario_for(b) == missing(0.7, 3, 0)
    assert planner_mission_for(k, scenario_for(k)) is None
    told = planner_mission_for(b, scenario_for(b))
    assert told.detection_probability == 1.0 and told.target_ids == scenario_for(b).target_ids


def test_a_blind_search_plans_with_the_paper_sensor_on_the_same_world(tmp_path):
    store = ResultStore(tmp_path / "r.db")
    run_benchmark(config(detection_probability=0.5), store)
    run_benchmark(config(detection_probability=0.5, blind=True), store)
    rows = {(r.key.planner, r.key.setting): r for r in store.rows()}
    store.close()
    greedy = [
        rows["greedy", s].uncertainty for s in ("homogeneous+pd:0.5", "homogeneous+pd:0.5+blind")
    ]
    assert greedy[0] == greedy[1]  # greedy never looks at the sensor's Pd
    assert rows["greedy", "homogeneous+pd:0.5"].detections > 0
    key = config(detection_probability=0.5, blind=True).keys()[1]
    planner = planner_for(key)
    scenario = scenario_for(key)
    short = scenario.model_copy(update={"budget": 5.0})
    run_episode(short, planner, planner_mission=planner_mission_for(key, short))
    assert isinstance(planner._record.sensor, FootprintSensor)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--blind"], "--blind needs a --detection-probability below 1"),
        (["--detection-probability", "1.5"], "--detection-probability must be in (0, 1], got 1.5"),
        (["--detection-probability", "0"], "--detection-probability must be in (0, 1], got 0.0"),
        (["--false-alarm-density", "1e-6"], "--false-alarm-density 1e-06 needs --unlabelled"),
        (["--detection-correlation-time", "2"], "--detection-correlation-time needs a --detec"),
        (
            ["--detection-probability", "0.7", "--detection-correlation-time", "-1"],
            "--detection-correlation-time must be between 0 and 3600 s, got -1.0",
        ),
        (
            ["--unlabelled", "--false-alarm-density", "-1"],
            "--false-alarm-density must be between 0 and 0.01 per m^2 per look, got -1.0",
        ),
    ],
)
def test_bad_sensing_options_are_one_line_errors(cli, tmp_path, args, message):
    db = tmp_path / "r.db"
    common = ["--targets", "2", "--scenarios", "1", "--planners", "greedy", "--db", db]
    cli("benchmark", *common, "--out", tmp_path / "o", *args).refused(message)
    assert not db.exists()


def test_detections_without_identity_and_clutter_are_part_of_the_identity():
    plain = config(detection_probability=0.7, labelled=False)
    clutter = config(detection_probability=0.7, labelled=False, false_alarm_density=1e-6)
    assert plain.setting == "homogeneous+pd:0.7+unlabelled"
    assert clutter.setting == "homogeneous+pd:0.7+unlabelled+clutter:1e-06"
    assert config(labelled=False).setting == "homogeneous+unlabelled"
    sensor = scenario_for(clutter.keys()[1]).sensor
    assert (sensor.detection_probability, sensor.labelled) == (0.7, False)
    assert sensor.false_alarm_density == 1e-6
    assert scenario_for(plain.keys()[1]).sensor.false_alarm_density == 0.0
    labelled = scenario_for(config(detection_probability=0.7).keys()[1])
    assert scenario_for(clutter.keys()[1]).targets == labelled.targets  # the same worlds


def test_held_draws_are_part_of_the_identity_and_reach_the_scenario():
    held = config(detection_probability=0.7, detection_correlation_time=2.0)
    assert held.setting == "homogeneous+pd:0.7+correlation:2.0"
    blind = config(detection_probability=0.7, detection_correlation_time=2.0, blind=True)
    assert blind.setting == "homogeneous+pd:0.7+correlation:2.0+blind"
    scenario = scenario_for(held.keys()[1])
    assert scenario.sensor.detection_correlation_time == 2.0
    assert scenario.mission_spec().record.sensor.hold_looks == 4
    told = planner_mission_for(blind.keys()[1], scenario_for(blind.keys()[1]))
    assert isinstance(told.record.sensor, FootprintSensor)


def test_an_unlabelled_benchmark_stores_its_tracking_metrics(tmp_path):
    store = ResultStore(tmp_path / "r.db")
    run_benchmark(config(labelled=False, false_alarm_density=1e-4), store)
    rows = store.rows()
    store.close()
    assert {r.key.setting for r in rows} == {"homogeneous+unlabelled+clutter:0.0001"}
    assert all(r.gospa_mean is not None and r.track_loss is not None for r in rows)
    tracking = [r.info["tracking"] for r in rows]  # the episode's tracking summary
    assert all(t["false_alarms_taken"] <= t["false_alarms"] <= t["reports"] for t in tracking)
    assert sum(t["false_alarms"] for t in tracking) > 0  # 1e-4 per m^2: a busy clutter


def test_a_config_refuses_blindness_without_misses_or_clutter():
    with pytest.raises(InputError, match="--blind"):
        config(blind=True)
    with pytest.raises(InputError, match="--blind"):
        config(blind=True, labelled=False)


def test_a_blind_planner_on_a_cluttered_world_is_told_no_false_alarms():
    blind = config(labelled=False, false_alarm_density=1e-6, blind=True)
    assert blind.setting == "homogeneous+blind+unlabelled+clutter:1e-06"
    key = blind.keys()[1]
    scenario = scenario_for(key)
    assert scenario.mission_spec().false_alarm_density == 1e-6
    told = planner_mission_for(key, scenario)
    assert (told.detection_probability, told.false_alarm_density) == (1.0, 0.0)


def test_the_library_benchmark_takes_the_sensing_options():
    from hptrack.experiments.benchmark import benchmark

    kw = {"target_counts": [2], "scenarios": 1, "homogeneous": False}
    known = benchmark(["greedy"], detection_probability=0.5, **kw)
    paper = benchmark(["greedy"], **kw)
    assert known["greedy"][2]["mean"] != paper["greedy"][2]["mean"]  # the detector misses
    with pytest.raises(InputError, match="--blind"):
        benchmark(["greedy"], blind=True, **kw)
