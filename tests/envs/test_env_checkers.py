"""Every environment passes Gymnasium's and stable-baselines3's checkers without a warning
(warnings are errors in this test suite)."""

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import hptrack.envs  # noqa: F401  (registers the environments)

CASES = [
    ("hptrack/Tracking-v0", {}),
    ("hptrack/Tracking-v0", {"action_type": "box", "n_targets": 2}),
    ("hptrack/Tracking-v0", {"n_targets": (2, 3), "max_targets": 4}),
    ("hptrack/SubtaskTracking-v0", {}),
    ("hptrack/SubtaskTracking-v0", {"n_targets": (1, 2), "max_targets": 3}),
    ("hptrack/TeamTracking-v0", {}),
    ("hptrack/TeamTracking-v0", {"team": 3, "action_type": "box", "n_targets": 2}),
    ("hptrack/TeamTracking-v0", {"n_targets": (2, 3), "max_targets": 4}),
]


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_gymnasium_checker(env_id, kwargs):
    check_env(gym.make(env_id, **kwargs).unwrapped)  # also renders through the spec


@pytest.mark.parametrize(("env_id", "kwargs"), CASES)
def test_stable_baselines3_checker(env_id, kwargs):
    sb3_check_env(gym.make(env_id, **kwargs).unwrapped, warn=True)


@pytest.mark.parametrize(
    "env_id", ["hptrack/Tracking-v0", "hptrack/SubtaskTracking-v0", "hptrack/TeamTracking-v0"]
)
def test_checkers_with_rendering_on(env_id):
    env = gym.make(env_id, n_targets=2, render_mode="rgb_array").unwrapped
    check_env(env)
    sb3_check_env(env, warn=True)
