"""``hptrack/TeamTracking-v0``: a team's steps, one action per UAV; a team whose second UAV
sees nothing flies the first UAV's episode exactly as ``Tracking-v0`` flies it alone; the
refusals."""

import gymnasium as gym
import numpy as np
import pytest

import hptrack.envs  # noqa: F401  (registers the environments)
from hptrack.envs import TeamTrackingEnv, TrackingEnv
from hptrack.interface import InputError
from hptrack.scenario.io import file_data, parse_scenario
from hptrack.scenario.random import random_scenario


def _far_team(seed: int):
    """The one-UAV random scenario of ``seed`` and the same with a second UAV 20 km away."""
    alone = random_scenario(3, seed=seed, homogeneous=True, budget=60.0)
    data = file_data(alone)
    agent = data.pop("agent")
    data["agents"] = [agent, {**agent, "position": [20000.0, 20000.0]}]
    return alone, parse_scenario(data, "far team")


def test_a_team_whose_second_uav_sees_nothing_flies_the_first_ones_episode_exactly():
    alone, team = _far_team(4)
    single, pair = TrackingEnv(n_targets=3), TeamTrackingEnv(n_targets=3)
    obs1, info1 = single.reset(options={"scenario": alone})
    obs2, info2 = pair.reset(options={"scenario": team})
    u_start = info2["U"]
    rng = np.random.default_rng(0)
    total, steps = 0.0, 0
    while True:
        np.testing.assert_array_equal(obs2.reshape(2, -1)[0], obs1)
        assert info2["U"] == info1["U"]
        assert info2["agents"].tolist()[1] == [20000.0, 20000.0]  # it hovers
        a = int(rng.integers(13))
        obs1, r1, _, done1, info1 = single.step(a)
        obs2, r2, term, done2, info2 = pair.step([a, 12])
        assert r2 == r1 and done2 == done1 and term is False
        total, steps = total + r2, steps + 1
        if done2:
            break
    assert steps == 120 and info2["gospa"] == info1["gospa"]
    assert total == pytest.approx(-(info2["U"] - u_start) / 3, rel=1e-12)


def test_every_uav_flies_its_own_action_at_its_own_speed():
    env = gym.make("hptrack/TeamTracking-v0", team=3, action_type="box", n_targets=2).unwrapped
    obs, info = env.reset(seed=3)
    assert obs.shape == (3 * env.layout.size,) and env.action_space.shape == (3, 2)
    rows = obs.reshape(3, -1)
    start = info["agents"].copy()
    step = env.world.mission.vehicle_mission(0).step_length
    _, _, _, _, info = env.step(np.array([[1.0, 0.0], [0.0, -1.0], [0.0, 0.0]]))
    np.testing.assert_allclose(info["agents"] - start, [[step, 0.0], [0.0, -step], [0.0, 0.0]])
    # each row of the observation is the one-UAV vector from that UAV's position
    np.testing.assert_array_equal(rows[1], rows[0])  # all start together
    env.reset(seed=3)
    u0, total = env.world.uncertainty, 0.0
    while not env.world.done:
        total += env.step(env.action_space.sample())[1]
    assert total == pytest.approx(-(env.world.uncertainty - u0) / 2, rel=1e-12, abs=1e-12)


def test_the_team_env_refuses_bad_teams_actions_and_scenarios_in_one_line():
    for team in (1, 17, 2.0, True):
        with pytest.raises(InputError, match="team must be an integer in 2..16"):
            TeamTrackingEnv(team=team)
    with pytest.raises(InputError, match="action_type"):
        TeamTrackingEnv(action_type="wheel")
    env = TeamTrackingEnv(n_targets=3)
    env.reset(seed=0)
    for action in ([1], [1, 2, 3], [1.0, 2.0], [[1, 2]], "ab", [1, 13]):
        with pytest.raises(ValueError, match="action"):
            env.step(action)
    with pytest.raises(InputError, match="flies 3 UAVs; this env flies a team of 2"):
        env.reset(options={"scenario": random_scenario(3, 0, team=3)})
