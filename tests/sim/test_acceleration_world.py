"""Targets that accelerate (Singer, constant acceleration): the 6-D state ``[x, y, vx, vy, ax,
ay]`` goes through the scenario, the simulator, the planners and the records; a 4-D belief
flies against a 6-D truth and the other way round; nothing of the 4-D world changes."""

import numpy as np
import pytest

from hptrack.baselines.clairvoyant import ClairvoyantPlanner
from hptrack.models.belief_motion import BeliefMotion, SingerMotion
from hptrack.models.mission import state_size
from hptrack.models.truth_motion import ConstantAccelerationTruth, SingerTruth
from hptrack.registry import make_planner
from hptrack.scenario import ScenarioError, parse_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World, initial_true_states

TARGETS = [
    {
        "id": f"t{i}",
        "mean": [300.0 * (i + 1), -200.0 + 150 * i, 1.5, -2.0],
        "covariance": [[900, 100, 0, 0], [100, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
        "process_noise": 0.01,
    }
    for i in range(3)
]
BASE = {"time_step": 0.5, "budget": 120.0, "seed": 4, "targets": TARGETS}
SINGER = {"model": "singer", "damping": 0.05, "acceleration_std": 0.05}
CA = {"model": "constant_acceleration", "jerk_intensity": 1e-5, "acceleration_std": 0.02}


@pytest.mark.parametrize("motion", [SINGER, CA])
def test_the_priors_gain_zero_accelerations_with_the_models_spread(motion):
    scenario = parse_scenario({**BASE, "motion": motion})
    means, covs = scenario.means(), scenario.covariances()
    assert means.shape == (3, 6) and covs.shape == (3, 6, 6)
    np.testing.assert_array_equal(means[:, :4], parse_scenario(BASE).means())
    np.testing.assert_array_equal(covs[:, :4, :4], parse_scenario(BASE).covariances())
    np.testing.assert_array_equal(means[:, 4:], 0.0)
    for c in covs:
        np.testing.assert_array_equal(c[4:, 4:], motion["acceleration_std"] ** 2 * np.eye(2))
        np.testing.assert_array_equal(c[:4, 4:], 0.0)
    assert state_size(scenario.mission_spec().record) == 6


def test_the_true_accelerations_are_drawn_after_every_position_and_velocity():
    plain = parse_scenario(BASE)
    singer = parse_scenario({**BASE, "truth_motion": SINGER})
    a = initial_true_states(plain, np.random.default_rng(9))
    b = initial_true_states(singer, np.random.default_rng(9))
    assert a.shape == (3, 4) and b.shape == (3, 6)
    np.testing.assert_array_equal(a, b[:, :4])
    rng = np.random.default_rng(9)
    initial_true_states(plain, rng)
    np.testing.assert_array_equal(b[:, 4:], 0.05 * rng.standard_normal((3, 2)))


@pytest.mark.parametrize("motion", [SINGER, CA])
@pytest.mark.parametrize("planner", ["mcts", "greedy", "clairvoyant"])
def test_a_mission_of_accelerating_targets_is_planned_and_recorded(motion, planner):
    scenario = parse_scenario({**BASE, "motion": motion})
    settings = {"iterations": 200} if planner == "mcts" else None
    record = run_episode(scenario, make_planner(planner, settings))
    k = scenario.n_steps + 1
    assert record.true_states.shape == (k, 3, 6)
    assert record.belief_means.shape[1:] == (3, 6)
    assert record.belief_covariances.shape[1:] == (3, 6, 6)
    assert np.isfinite(record.uncertainty)
    assert record.detections.any()
    again = run_episode(scenario, make_planner(planner, settings))
    assert again.uncertainty == record.uncertainty  # deterministic


def test_the_truth_moves_by_the_model_and_the_beliefs_follow_it():
    """The simulator's truth under Singer's model: over many seeds the true velocity change in
    one step has the model's mean and spread (``F`` and ``Q`` of the belief motion)."""
    scenario = parse_scenario({**BASE, "motion": SINGER, "budget": 0.5})
    motion = BeliefMotion(0.5, SingerMotion(0.05, 0.05))
    starts, ends = [], []
    for seed in range(400):
        world = World(scenario, seed)
        starts.append(world.truth.copy())
        world.step(0.0, 0.0)
        ends.append(world.truth.copy())
    start, end = np.concatenate(starts), np.concatenate(ends)
    f = np.empty((6, 6))
    q = np.empty((6, 6))
    from hptrack.models.mission import _step_matrices_on

    _step_matrices_on(scenario.mission_spec().record, 0.0, f, q)
    residual = end - start @ f.T
    sd = np.sqrt(np.diag(q))
    # 1200 draws per entry: the mean within 5 standard errors, the spread within 15 %
    assert np.all(np.abs(residual.mean(axis=0)) < 5 * sd / np.sqrt(len(residual)))
    np.testing.assert_allclose(residual.std(axis=0), sd, rtol=0.15)
    assert motion.state_size == 6


def test_constant_velocity_beliefs_fly_against_accelerating_targets_and_back():
    cv_on_singer = parse_scenario({**BASE, "truth_motion": SINGER})
    record = run_episode(cv_on_singer, make_planner("greedy"))
    assert record.true_states.shape[2] == 6 and record.belief_means.shape[2] == 4
    singer_on_cv = parse_scenario(
        {**BASE, "motion": SINGER, "truth_motion": {"model": "constant_velocity"}}
    )
    record = run_episode(singer_on_cv, make_planner("greedy"))
    assert record.true_states.shape[2] == 4 and record.belief_means.shape[2] == 6
    world = World(parse_scenario({**BASE, "truth_motion": CA}))
    assert world.truth_motion == ConstantAccelerationTruth(1e-5, 0.02)
    assert World(parse_scenario({**BASE, "motion": SINGER})).truth_motion == SingerTruth(0.05, 0.05)
    assert isinstance(make_planner("clairvoyant"), ClairvoyantPlanner)


@pytest.mark.parametrize(
    ("motion", "shown"),
    [
        ({**SINGER, "damping": 0.0}, "motion.singer.damping"),
        ({**SINGER, "acceleration_std": -1.0}, "motion.singer.acceleration_std"),
        ({**CA, "jerk_intensity": -1e-6}, "motion.constant_acceleration.jerk_intensity"),
        ({**CA, "spin": 1.0}, "spin"),
    ],
)
def test_bad_values_are_one_line_naming_the_field(motion, shown):
    with pytest.raises(ScenarioError) as err:
        parse_scenario({**BASE, "motion": motion})
    message = str(err.value)
    assert "\n" not in message and shown in message, message
