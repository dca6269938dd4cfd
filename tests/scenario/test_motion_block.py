"""The scenario's ``motion:`` block: omitted it means the paper's constant velocity (the same
record and the same episode as before), set it picks the beliefs' model and, without a
``truth_motion``, the truth's; bad values are one line naming the field."""

import numpy as np
import pytest

from hptrack.models.belief_motion import ConstantVelocity, OrnsteinUhlenbeckMotion
from hptrack.models.truth_motion import ConstantVelocityTruth, OrnsteinUhlenbeck, RandomWalk
from hptrack.registry import make_planner
from hptrack.scenario import ScenarioError, load_scenario, parse_scenario, save_scenario
from hptrack.sim.episode import run_episode

TARGET = {
    "id": "t1",
    "mean": [300.0, -200.0, 1.5, -2.0],
    "covariance": [[900, 100, 0, 0], [100, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]],
    "process_noise": 0.0003,
}
BASE = {"time_step": 0.5, "budget": 60.0, "seed": 3, "targets": [TARGET]}


def test_an_omitted_block_is_constant_velocity_with_the_files_noise_form():
    plain = parse_scenario(BASE)
    assert plain.motion is None
    assert plain.mission_spec().record.motion == ConstantVelocity(0.5)
    assert plain.truth_motion_model(np.random.default_rng(0)) == ConstantVelocityTruth()
    printed = parse_scenario({**BASE, "process_noise_form": "paper_text"})
    assert printed.mission_spec().record.motion == ConstantVelocity(1.0)
    spelled = parse_scenario({**BASE, "motion": {"model": "constant_velocity"}})
    assert spelled.mission_spec().record.motion == plain.mission_spec().record.motion
    first = run_episode(plain, make_planner("greedy"))
    second = run_episode(spelled, make_planner("greedy"))
    np.testing.assert_array_equal(first.agent_path, second.agent_path)
    assert first.uncertainty == second.uncertainty


def test_a_block_picks_the_beliefs_and_by_default_the_truths_model(tmp_path):
    scenario = parse_scenario({**BASE, "motion": {"model": "ornstein_uhlenbeck", "damping": 0.05}})
    assert scenario.mission_spec().record.motion == OrnsteinUhlenbeckMotion(0.05)
    assert scenario.truth_motion_model(np.random.default_rng(0)) == OrnsteinUhlenbeck(0.05)
    mismatched = parse_scenario(
        {
            **BASE,
            "motion": {"model": "ornstein_uhlenbeck"},
            "truth_motion": {"model": "random_walk"},
        }
    )
    assert mismatched.truth_motion_model(np.random.default_rng(0)) == RandomWalk(5.0)
    path = tmp_path / "ou.yaml"
    save_scenario(scenario, path)
    assert "motion:" in path.read_text()
    assert load_scenario(path).model_dump() == scenario.model_dump()
    record = run_episode(scenario, make_planner("mcts", {"iterations": 50}))
    assert np.isfinite(record.uncertainty)


@pytest.mark.parametrize(
    ("motion", "extra", "shown"),
    [
        ({"model": "ornstein_uhlenbeck", "damping": 0.0}, {}, "motion.ornstein_uhlenbeck.damping"),
        ({"model": "random_walk", "diffusion": -1.0}, {}, "motion.random_walk.diffusion"),
        ({"model": "coordinated_turn"}, {}, "coordinated_turn"),
        ({"model": "random_walk"}, {"process_noise_form": "paper_text"}, "process_noise_form"),
    ],
)
def test_bad_values_are_one_line_naming_the_field(motion, extra, shown):
    with pytest.raises(ScenarioError) as err:
        parse_scenario({**BASE, **extra, "motion": motion})
    message = str(err.value)
    assert "\n" not in message and shown in message, message
