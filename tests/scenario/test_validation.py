"""Every invalid input is refused with an error naming the field and the value."""

import copy

import numpy as np
import pytest
import yaml

from hptrack.scenario import ScenarioError, load_scenario, parse_scenario, random_scenario

VALID = {
    "time_step": 0.5,
    "budget": 900.0,
    "seed": 7,
    "agent": {
        "position": [0.0, 0.0],
        "speed": 30.0,
        "sensor_diameter": 100.0,
        "measurement_noise_std": 3.1623,
    },
    "targets": [
        {
            "id": "t1",
            "mean": [250.0, -400.0, 1.5, -2.0],
            "covariance": [[900, 100, 0, 0], [100, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
            "process_noise": 0.0003,
            "truth": [260.0, -380.0, 1.4, -2.2],
        },
        {
            "id": "t2",
            "mean": [-250.0, 400.0, 0.0, 1.0],
            "covariance": [[900, 0, 0, 0], [0, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
            "process_noise": 0.0002,
        },
    ],
}


def with_change(path, value):
    data = copy.deepcopy(VALID)
    *parents, last = path
    node = data
    for p in parents:
        node = node[p]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return data


def test_valid_example_loads():
    scenario = parse_scenario(VALID)
    assert scenario.target_ids == ("t1", "t2")
    assert scenario.mission_spec().n_steps == 1800


CASES = [
    (("time_step",), 0.0, "time_step", "0.0"),
    (("time_step",), -0.5, "time_step", "-0.5"),
    (("budget",), -1.0, "budget", "-1.0"),
    (("budget",), float("nan"), "budget", "nan"),
    (("budget",), float("inf"), "budget", "inf"),
    (("agent", "speed"), 0.0, "agent.speed", "0.0"),
    (("agent", "sensor_diameter"), -100.0, "agent.sensor_diameter", "-100.0"),
    (("agent", "measurement_noise_std"), 0.0, "agent.measurement_noise_std", "0.0"),
    (("agent", "position"), [float("nan"), 0.0], "agent.position.0", "nan"),
    (("targets", 0, "process_noise"), -1e-4, "targets.0.process_noise", "-0.0001"),
    (("targets", 1, "mean"), [0.0, 0.0, 31.0, 0.0], "targets.1.mean", "31 m/s"),
    (("targets", 1, "mean"), [0.0, 0.0, 30.0, 0.0], "targets.1.mean", "30 m/s"),
    (("targets", 1, "id"), "t1", "targets.1.id", "'t1'"),
    (
        ("targets", 0, "covariance"),
        [[900, 100, 0, 0], [90, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
        "targets.0.covariance",
        "not symmetric",
    ),
    (
        ("targets", 0, "covariance"),
        [[900, 1000, 0, 0], [1000, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
        "targets.0.covariance",
        "not positive definite",
    ),
    (
        ("targets", 0, "covariance"),
        [[900, 0, 0, 0], [0, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.0]],
        "targets.0.covariance",
        "not positive definite",
    ),
    (("targets", 0, "truth"), [1.0, 2.0, float("inf"), 0.0], "targets.0.truth.2", "inf"),
    (("targets", 0, "mean"), [1.0, 2.0, 3.0], "targets.0.mean", "[1.0, 2.0, 3.0]"),
    (("targets",), [], "targets", "[]"),
    (("agent", "speed"), KeyError, None, None),  # a default exists: still valid
    (("targets", 0, "process_noise"), KeyError, "targets.0.process_noise", "Field required"),
    (("targets", 0, "colour"), "red", "targets.0.colour", "'red'"),
    (("budget",), 0.25, "budget", "0.25"),
]


@pytest.mark.parametrize(("path", "value", "field", "shown"), CASES)
def test_bad_field_is_named_with_its_value(path, value, field, shown):
    data = with_change(path, value)
    if field is None:
        parse_scenario(data)
        return
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    message = str(info.value)
    assert "\n" not in message
    assert field in message
    assert shown in message


def test_malformed_yaml_names_the_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("time_step: 0.5\nagent: [1, 2\n")
    with pytest.raises(ScenarioError, match=r"malformed YAML at line \d+"):
        load_scenario(path)


def test_top_level_must_be_a_mapping(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- 1\n- 2\n")
    with pytest.raises(ScenarioError, match="mapping"):
        load_scenario(path)


def test_missing_file(tmp_path):
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "nope.yaml")


def test_yaml_round_trip(tmp_path):
    from hptrack.scenario import save_scenario

    scenario = random_scenario(3, seed=11, homogeneous=True)
    save_scenario(scenario, tmp_path / "s.yaml")
    loaded = load_scenario(tmp_path / "s.yaml")
    assert loaded == scenario
    assert yaml.safe_load((tmp_path / "s.yaml").read_text())["seed"] == 11


def test_random_scenarios_follow_the_paper_distributions():
    covs, qs, means = [], [], []
    for seed in range(60):
        s = random_scenario(3, seed=seed)
        covs.append(s.covariances())
        qs.append(s.process_noise())
        means.append(s.means())
    covs, qs, means = np.concatenate(covs), np.concatenate(qs), np.concatenate(means)
    assert np.all((means[:, :2] >= -1000) & (means[:, :2] <= 1000))
    assert np.all(np.abs(means[:, 2:]) <= 3)
    var = covs[:, [0, 1], [0, 1]]
    assert np.all((var >= 500) & (var <= 2000))
    rho = covs[:, 0, 1] / np.sqrt(var[:, 0] * var[:, 1])
    assert np.all(np.abs(rho) <= 0.8) and rho.std() > 0.3
    assert np.all((covs[:, [2, 3], [2, 3]] >= 0.25) & (covs[:, [2, 3], [2, 3]] <= 0.5))
    assert np.all(covs[:, :2, 2:] == 0)
    assert np.all((qs >= 1e-4) & (qs <= 5e-4))


def test_homogeneous_shares_q_and_prior_but_not_means():
    s = random_scenario(4, seed=5, homogeneous=True)
    assert len(set(s.process_noise())) == 1
    assert np.all(s.covariances() == s.covariances()[0])
    assert len({t.mean for t in s.targets}) == 4
    h = random_scenario(4, seed=5)
    assert len(set(h.process_noise())) == 4


def test_same_seed_same_scenario():
    assert random_scenario(5, seed=9) == random_scenario(5, seed=9)
    assert random_scenario(5, seed=9) != random_scenario(5, seed=10)
