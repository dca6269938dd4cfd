"""Environment actions and reset options: a wrong type is refused in one line (never
truncated), a huge Box action flies at full speed (never a nan position), and every step of a
fuzzed action sequence keeps the agent, the reward and the observation finite."""

import os

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import hptrack.envs  # noqa: F401  (registers the environments)

FUZZ = settings.get_profile(os.environ.get("HPTRACK_FUZZ", "fuzz-ci"))


@pytest.fixture(scope="module")
def discrete():
    env = gym.make("hptrack/Tracking-v0", n_targets=2).unwrapped
    yield env
    env.close()


@pytest.fixture(scope="module")
def box():
    env = gym.make("hptrack/Tracking-v0", n_targets=2, action_type="box").unwrapped
    yield env
    env.close()


@pytest.fixture(scope="module")
def subtask():
    env = gym.make("hptrack/SubtaskTracking-v0", n_targets=2).unwrapped
    yield env
    env.close()


@pytest.mark.parametrize("action", [1.7, "3", True, 13, -1, None, [1, 2], np.float64(2.0)])
def test_discrete_actions_must_be_integers(discrete, subtask, action):
    for env in (discrete, subtask):
        env.reset(seed=0)
        with pytest.raises(ValueError, match="action must be an integer") as err:
            env.step(action)
        assert "\n" not in str(err.value)


def test_numpy_integer_actions_are_accepted(discrete):
    discrete.reset(seed=0)
    for action in (np.int64(3), np.array(3), np.array([3], dtype=np.int32)):
        discrete.step(action)


def test_a_huge_box_action_flies_at_full_speed(box):
    box.reset(seed=0)
    start = box.world.agent.copy()
    box.step(np.array([1e308, 1e308]))
    moved = box.world.agent - start
    assert np.all(np.isfinite(box.world.agent))
    np.testing.assert_allclose(np.hypot(*moved), box.world.mission.step_length, rtol=1e-9)
    np.testing.assert_allclose(moved[0], moved[1], rtol=1e-9)
    for bad in ([np.inf, 0.0], [np.nan, 0.0], "ab", [1.0]):
        with pytest.raises(ValueError, match="2 finite numbers"):
            box.step(bad)


@pytest.mark.parametrize(
    "action", [["1", "0"], np.array(["1", "0"]), [True, False], np.array([True, False]), [1, True]]
)
def test_text_and_boolean_box_actions_are_refused(box, action):
    """numpy would turn them into numbers; a Box action is numbers only."""
    box.reset(seed=0)
    with pytest.raises(ValueError, match="action must be 2 finite numbers"):
        box.step(action)
    box.step([1, 0.5])  # plain numbers still fly


@pytest.mark.parametrize("seed", [1.5, -1, 2**63, True, "3"])
def test_reset_seeds_are_non_negative_integers(discrete, seed):
    with pytest.raises(ValueError, match="reset seed must be an integer") as err:
        discrete.reset(seed=seed)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match=r'reset options\["seed"\]'):
        discrete.reset(options={"seed": seed})


ACTIONS = st.one_of(
    st.integers(-3, 15),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.text(max_size=3),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=3),
    st.tuples(st.floats(-1e308, 1e308), st.floats(-1e308, 1e308)).map(np.array),
)


@FUZZ
@given(actions=st.lists(ACTIONS, min_size=1, max_size=8), seed=st.integers(0, 2**63 - 1))
def test_fuzz_actions_keep_every_step_finite(discrete, box, actions, seed):
    for env in (discrete, box):
        env.reset(seed=seed)
        for action in actions:
            try:
                _, reward, *_ = env.step(action)
            except ValueError as err:
                assert "\n" not in str(err) and len(str(err)) < 300
                continue
            assert np.isfinite(reward) and np.all(np.isfinite(env.world.agent))
