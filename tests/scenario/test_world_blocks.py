"""The ``sensor:`` and ``vehicle:`` blocks of a scenario: their defaults are the paper's, a file
without them loads and means what it meant, the same facts written in the blocks or in the
``agent:`` block give the same mission bit for bit, and a fact given twice with two values is
one line, exit 2."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import InputError
from hptrack.scenario import load_scenario, parse_scenario, random_scenario, save_scenario
from hptrack.scenario.io import file_data
from hptrack.scenario.model import FootprintSensorSpec, HolonomicVehicleSpec
from hptrack.sim.episode import run_episode

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "src" / "hptrack" / "examples" / "paper-flight.yaml"


def _docs_scenario() -> dict:
    """The scenario file shown in ``docs/simulate.md`` (its first YAML block with targets)."""
    text = (REPO / "docs" / "simulate.md").read_text()
    blocks = re.findall(r"```yaml\n(.*?)```", text, flags=re.DOTALL)
    return next(yaml.safe_load(b) for b in blocks if "targets:" in b)


def _in_blocks(data: dict) -> dict:
    """The same facts moved from the ``agent:`` block into ``sensor:`` and ``vehicle:``."""
    agent = dict(data.get("agent", {}))
    vehicle = {"speed": agent.pop("speed")} if "speed" in agent else {}
    sensor = {}
    if "sensor_diameter" in agent:
        sensor["diameter"] = agent.pop("sensor_diameter")
    for name in ("measurement_noise_std", "measurement_noise_covariance"):
        if name in agent:
            sensor[name] = agent.pop(name)
    return {**data, "agent": agent, "sensor": sensor, "vehicle": vehicle}


def _facts(scenario) -> tuple:
    record = scenario.mission_spec().record
    return (
        record.vehicle,
        record.sensor.diameter,
        record.sensor.measurement_noise.tolist(),
        record.time_step,
        record.n_steps,
    )


def test_the_defaults_are_the_papers_world():
    assert HolonomicVehicleSpec().speed == 30.0
    sensor = FootprintSensorSpec()
    assert sensor.diameter == 100.0
    np.testing.assert_allclose(sensor.noise_covariance(), 10.0 * np.eye(2), rtol=1e-15)
    scenario = random_scenario(3, seed=2)
    assert scenario.sensor is None and scenario.vehicle is None
    record = scenario.mission_spec().record
    assert (record.vehicle.speed, record.vehicle.step_length, record.sensor.diameter) == (
        30.0,
        15.0,
        100.0,
    )


@pytest.mark.parametrize("source", ["example", "docs"])
def test_existing_files_mean_the_same_and_equal_their_blocks(source):
    data = yaml.safe_load(EXAMPLE.read_text()) if source == "example" else _docs_scenario()
    old = parse_scenario(data)
    agent = data["agent"]
    assert old.vehicle_spec().speed == agent["speed"]
    assert old.sensor_spec().diameter == agent["sensor_diameter"]
    assert old.sensor_spec().measurement_noise_std == agent["measurement_noise_std"]
    assert _facts(parse_scenario(_in_blocks(data))) == _facts(old)


def test_an_episode_is_the_same_whichever_block_holds_the_facts():
    data = yaml.safe_load(EXAMPLE.read_text())  # 8 m/s, a 20 m footprint, R = I
    by_agent = parse_scenario(data)
    by_blocks = parse_scenario(_in_blocks(data))
    assert by_blocks.sensor is not None and by_blocks.vehicle is not None
    a = run_episode(by_agent, GreedyPlanner())
    b = run_episode(by_blocks, GreedyPlanner())
    assert a.detections.any()  # the sensor and the speed matter to this episode
    np.testing.assert_array_equal(a.agent_path, b.agent_path)
    np.testing.assert_array_equal(a.detections, b.detections)
    np.testing.assert_array_equal(a.per_target_logdet, b.per_target_logdet)


def test_a_default_world_writes_no_block_and_a_block_holds_its_facts(tmp_path):
    plain = random_scenario(2, seed=1)
    assert {"sensor", "vehicle"}.isdisjoint(file_data(plain))
    assert {"speed", "sensor_diameter", "measurement_noise_std"} <= set(file_data(plain)["agent"])
    data = plain.model_dump(mode="json")
    data["agent"] = {"position": [5.0, 0.0]}
    data["sensor"] = {"diameter": 80.0, "measurement_noise_covariance": [[4.0, 1.0], [1.0, 9.0]]}
    data["vehicle"] = {"speed": 25.0}
    world = parse_scenario(data)
    path = tmp_path / "world.yaml"
    save_scenario(world, path)
    text = path.read_text()
    assert "sensor_diameter" not in text and re.search(r"^  speed: 25.0\s+# m/s$", text, re.M)
    assert re.search(r"^  model: footprint\s+# footprint: ", text, re.M)
    back = load_scenario(path)
    assert _facts(back) == _facts(world)
    assert back.agent.position == (5.0, 0.0)


@pytest.mark.parametrize(
    ("block", "needles"),
    [
        ({"vehicle": {"speed": 25.0}}, ["vehicle.speed 25 m/s and agent.speed 30 m/s disagree"]),
        ({"sensor": {"diameter": 80.0}}, ["sensor.diameter 80 m and agent.sensor_diameter 100 m"]),
        ({"sensor": {"measurement_noise_std": 2.0}}, ["the sensor's R", "the agent's R"]),
        ({"vehicle": {"model": "fixed_wing"}}, ["vehicle.model", "fixed_wing"]),
        ({"sensor": {"diameter": -1.0}}, ["sensor.diameter", "-1"]),
    ],
)
def test_a_fact_given_twice_or_a_bad_block_is_one_line_exit_2(cli, tmp_path, block, needles):
    data = random_scenario(2, seed=3).model_dump(mode="json")  # agent gives every fact
    path = tmp_path / "twice.yaml"
    path.write_text(yaml.safe_dump({**data, **block}))
    with pytest.raises(InputError) as err:
        load_scenario(path)
    assert "\n" not in str(err.value)
    cli("scenario", "check", path).refused(*needles)


def test_the_same_fact_in_both_places_is_accepted():
    data = random_scenario(2, seed=3).model_dump(mode="json")
    same = parse_scenario({**data, "vehicle": {"speed": 30.0}, "sensor": {"diameter": 100.0}})
    assert _facts(same) == _facts(parse_scenario(data))
