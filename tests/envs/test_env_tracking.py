"""Tracking-v0: registration, actions, observation, reward, episodes, reset options, render."""

import math
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import hptrack.envs  # noqa: F401  (registers the environments)
from hptrack.envs import HOVER, SubtaskTrackingEnv, TrackingEnv
from hptrack.interface import InputError
from hptrack.scenario import Scenario, TargetSpec, random_scenario

COV = (
    (900.0, 100.0, 0.0, 0.0),
    (100.0, 800.0, 0.0, 0.0),
    (0.0, 0.0, 0.3, 0.0),
    (0.0, 0.0, 0.0, 0.4),
)


def far_scenario(budget=60.0):
    """Two targets 5 km away: never measured by an agent that stays near the start."""
    targets = [
        TargetSpec(
            id=f"t{i}",
            mean=(5000.0 + 1000 * i, 0.0, 1.0, 0.5),
            covariance=COV,
            process_noise=2e-4 * (i + 1),
        )
        for i in range(2)
    ]
    return Scenario(seed=3, targets=targets, budget=budget)


@pytest.mark.parametrize(
    ("env_id", "cls"),
    [
        ("hptrack/Tracking-v0", TrackingEnv),
        ("hptrack.envs:Tracking-v0", TrackingEnv),
        ("hptrack/SubtaskTracking-v0", SubtaskTrackingEnv),
        ("hptrack.envs:SubtaskTracking-v0", SubtaskTrackingEnv),
    ],
)
def test_both_ids_make_the_environment_with_its_options(env_id, cls):
    env = gym.make(env_id, n_targets=6, setting="homogeneous")
    assert isinstance(env.unwrapped, cls)
    _, info = env.reset(seed=1)
    assert env.unwrapped.n_targets == 6
    assert len(set(env.unwrapped.scenario.process_noise())) == 1  # homogeneous: one q


def test_module_colon_id_works_in_a_fresh_process_without_the_import():
    code = (
        "import gymnasium as gym; "
        "print(type(gym.make('hptrack.envs:SubtaskTracking-v0').unwrapped).__name__)"
    )
    out = subprocess.run(
        [sys.executable, "-W", "error", "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "SubtaskTrackingEnv"


def test_default_spaces():
    env = gym.make("hptrack/Tracking-v0")
    assert env.action_space == gym.spaces.Discrete(13)
    assert env.observation_space.shape == (4 * 6 + 1,)
    assert env.observation_space.dtype == np.float32
    assert np.all(np.isfinite(env.observation_space.low))
    assert np.all(np.isfinite(env.observation_space.high))
    box = gym.make("hptrack/Tracking-v0", action_type="box")
    assert box.action_space == gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)


def test_random_scenario_comes_from_the_env_generator():
    env = TrackingEnv(n_targets=3)
    obs_a, info_a = env.reset(seed=11)
    rng = np.random.default_rng(11)  # what Env.reset(seed=11) seeds
    n = int(rng.integers(3, 4))
    expected = random_scenario(n, seed=int(rng.integers(2**63)))
    assert env.scenario == expected
    assert info_a["never_observed_U"] == pytest.approx(expected.never_observed_uncertainty())
    obs_b, _ = env.reset(seed=11)
    np.testing.assert_array_equal(obs_a, obs_b)
    obs_c, _ = env.reset()
    assert env.scenario != expected  # the next episode draws a new scenario


@pytest.mark.parametrize("action", range(12))
def test_discrete_headings_fly_at_full_speed(action):
    env = TrackingEnv(n_targets=2)
    env.reset(options={"scenario": far_scenario()})
    start = env.world.agent.copy()
    env.step(action)
    step = 30.0 * 0.5
    angle = math.radians(30.0 * action)
    np.testing.assert_allclose(
        env.world.agent - start, [step * math.cos(angle), step * math.sin(angle)], atol=1e-12
    )


def test_hover_stays():
    env = TrackingEnv(n_targets=2)
    env.reset(options={"scenario": far_scenario()})
    start = env.world.agent.copy()
    env.step(HOVER)
    np.testing.assert_array_equal(env.world.agent, start)


@pytest.mark.parametrize(
    ("action", "displacement"),
    [
        ((1.0, 0.0), (15.0, 0.0)),
        ((0.5, -0.2), (7.5, -3.0)),
        ((1.0, 1.0), (15.0 / math.sqrt(2), 15.0 / math.sqrt(2))),  # capped at the top speed
        ((0.0, 0.0), (0.0, 0.0)),
    ],
)
def test_box_action_is_a_velocity_fraction(action, displacement):
    env = TrackingEnv(n_targets=2, action_type="box")
    env.reset(options={"scenario": far_scenario()})
    start = env.world.agent.copy()
    env.step(np.array(action, dtype=np.float32))
    np.testing.assert_allclose(env.world.agent - start, displacement, atol=1e-6)


def test_observation_encodes_the_beliefs():
    env = TrackingEnv(n_targets=4)
    obs, _ = env.reset(seed=5)
    for _ in range(30):
        obs, *_ = env.step(3)  # heading 90 degrees
    w = env.world
    features = env.layout.target_features(obs)
    np.testing.assert_allclose(features[:, 0], (w.means[:, 0] - w.agent[0]) / 1000, rtol=1e-6)
    np.testing.assert_allclose(features[:, 1], (w.means[:, 1] - w.agent[1]) / 1000, rtol=1e-6)
    np.testing.assert_allclose(features[:, 2:4], w.means[:, 2:] / 3, rtol=1e-6)
    p = w.covariances[:, :2, :2]
    logdet = np.log(np.linalg.det(p))
    np.testing.assert_allclose(features[:, 4], (logdet - 14) / 10, rtol=1e-5)
    np.testing.assert_array_equal(features[:, 5], w.seen.astype(np.float32))
    assert obs[-1] == pytest.approx(1.0 - 30 / 1800)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)


def test_observation_is_clipped_to_its_bounds():
    targets = [
        TargetSpec(
            id="far", mean=(50_000.0, -50_000.0, 1.0, 0.5), covariance=COV, process_noise=2e-4
        )
    ]
    env = TrackingEnv(n_targets=1)
    obs, _ = env.reset(options={"scenario": Scenario(targets=targets, budget=10.0)})
    np.testing.assert_array_equal(obs[:2], [10.0, -10.0])
    assert env.observation_space.contains(obs)


def test_padding_and_mask_with_a_variable_number_of_targets():
    env = TrackingEnv(n_targets=(2, 4), max_targets=5)
    assert env.observation_space.shape == (5 * 6 + 1 + 5,)
    seen_n = set()
    for seed in range(12):
        obs, _ = env.reset(seed=seed)
        n = env.n_targets
        seen_n.add(n)
        np.testing.assert_array_equal(env.layout.mask(obs), np.arange(5) < n)
        np.testing.assert_array_equal(env.layout.target_features(obs)[n:], 0.0)
        assert env.observation_space.contains(obs)
    assert seen_n == {2, 3, 4}


def test_rewards_sum_to_minus_the_change_of_u_and_the_budget_truncates():
    env = TrackingEnv(n_targets=3)
    scenario = random_scenario(3, seed=2, budget=60.0)
    _, info = env.reset(options={"scenario": scenario})
    u0, total, steps, truncated = info["U"], 0.0, 0, False
    rng = np.random.default_rng(1)
    while not truncated:
        u_before = info["U"]
        _, reward, terminated, truncated, info = env.step(int(rng.integers(13)))
        assert not terminated
        assert reward == pytest.approx(-(info["U"] - u_before) / 3, abs=1e-12)
        total += reward
        steps += 1
    assert steps == 120
    assert total == pytest.approx(-(info["U"] - u0) / 3, abs=1e-9)
    assert info["U"] == pytest.approx(info["per_target_logdet"].sum(), abs=1e-12)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(0)


def test_a_policy_that_detects_nothing_scores_the_never_observed_u():
    env = TrackingEnv(n_targets=2)
    _, info = env.reset(options={"scenario": far_scenario(budget=300.0)})
    truncated = False
    while not truncated:
        _, _, _, truncated, info = env.step(HOVER)
    assert info["U"] == pytest.approx(info["never_observed_U"], rel=1e-10)
    assert info["never_observed_U"] == far_scenario(300.0).never_observed_uncertainty()


def test_scenario_option_uses_its_seed_unless_overridden():
    env = TrackingEnv(n_targets=3)
    scenario = random_scenario(3, seed=9)
    env.reset(options={"scenario": scenario})
    truth = env.world.truth.copy()
    env.reset(seed=123, options={"scenario": scenario})
    np.testing.assert_array_equal(env.world.truth, truth)
    env.reset(options={"scenario": scenario, "seed": 10})
    assert not np.array_equal(env.world.truth, truth)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_targets": 0}, "n_targets"),
        ({"n_targets": (2, 4)}, "max_targets"),
        ({"n_targets": 4, "max_targets": 3}, "max_targets"),
        ({"n_targets": 257}, "n_targets must be between 1 and 256"),
        ({"n_targets": (2, 300), "max_targets": 300}, "n_targets must be between 1 and 256"),
        (
            {"n_targets": 2, "max_targets": 10**9},
            "max_targets must be an int from n_targets 2 to 256",
        ),
        ({"setting": "mixed"}, "setting"),
        ({"action_type": "polar"}, "action_type"),
        ({"render_mode": "human"}, "render_mode"),
    ],
)
def test_bad_options_are_one_line_input_errors(kwargs, match):
    with pytest.raises(InputError, match=match):
        TrackingEnv(**kwargs)


def test_bad_reset_options_are_input_errors():
    env = TrackingEnv(n_targets=3)
    with pytest.raises(InputError, match="unknown 'budget'"):
        env.reset(options={"budget": 10})
    with pytest.raises(InputError, match="2 targets"):
        env.reset(options={"scenario": far_scenario()})


def test_bad_actions_raise():
    env = TrackingEnv(n_targets=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="0..12"):
        env.step(13)
    box = TrackingEnv(n_targets=2, action_type="box")
    box.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        box.step(np.array([np.nan, 0.0]))


def test_render_draws_the_mission_so_far():
    env = TrackingEnv(n_targets=2, render_mode="rgb_array")
    env.reset(seed=0)
    for _ in range(20):
        env.step(0)
    record = env.episode_record()
    assert record.agent_path.shape == (21, 2)
    np.testing.assert_array_equal(record.agent_path[-1], env.world.agent)
    image = env.render()
    assert image.shape == (640, 640, 3) and image.dtype == np.uint8
    assert image.min() < 100 and image.max() == 255  # something is drawn on white
    assert TrackingEnv(n_targets=2).render() is None
