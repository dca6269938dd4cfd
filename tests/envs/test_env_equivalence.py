"""The environments' physics is the simulator's: driven with a planner's decisions they produce
the mission :func:`run_episode` produces with the same seed, to the last bit."""

import gymnasium as gym
import numpy as np
import pytest

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.envs import ObservationLayout, action_waypoint
from hptrack.planning.hierarchical import HierarchicalPlanner, MctsSettings
from hptrack.scenario import AgentSpec, Scenario, random_scenario
from hptrack.sim.episode import run_episode
from hptrack.subtasks import read_subtasks


class ReplayPlanner:
    """Flies a given list of waypoints."""

    name = "replay"

    def __init__(self, waypoints):
        self.waypoints = list(waypoints)

    def reset(self, mission, observation, rng):
        self._k = 0

    def act(self, observation):
        self._k += 1
        return self.waypoints[self._k - 1]

    def episode_info(self):
        return {}


def fly_greedy_in_box_env(scenario):
    """Tracking-v0 with Box actions following the greedy planner's waypoints."""
    env = gym.make(
        "hptrack/Tracking-v0", n_targets=len(scenario.targets), action_type="box"
    ).unwrapped
    env.reset(options={"scenario": scenario})
    world = env.world
    planner = GreedyPlanner()
    planner.reset(world.mission, world.observation(), np.random.default_rng(world.planner_seed))
    path, seen, truncated = [world.agent.copy()], [world.seen.copy()], False
    while not truncated:
        waypoint = planner.act(world.observation())
        action = (waypoint - world.agent) / world.mission.step_length
        action /= max(1.0, float(np.max(np.abs(action))))  # into the box, direction kept
        _, _, terminated, truncated, info = env.step(action)
        assert not terminated
        path.append(world.agent.copy())
        seen.append(world.seen.copy())
    return env, info, np.array(path), np.array(seen)


@pytest.mark.parametrize("seed", [2, 4])
def test_box_env_flown_by_greedy_is_the_simulator_bit_for_bit(seed):
    scenario = random_scenario(3, seed=seed, budget=300.0)
    record = run_episode(scenario, GreedyPlanner())
    env, info, path, seen = fly_greedy_in_box_env(scenario)
    assert record.detections.sum() > 25  # the test exercises many updates
    np.testing.assert_array_equal(seen, record.detections)
    np.testing.assert_array_equal(env.world.truth, record.true_states[-1])
    np.testing.assert_array_equal(env.world.means, record.belief_means[-1])
    np.testing.assert_array_equal(env.world.covariances, record.belief_covariances[-1])
    # the agent's positions differ only by the round-off of waypoint -> action -> waypoint
    np.testing.assert_allclose(path, record.agent_path, rtol=0, atol=1e-9)
    assert info["U"] == record.uncertainty
    np.testing.assert_array_equal(info["per_target_logdet"], record.per_target_logdet)


def test_full_measurement_noise_matches_the_simulator():
    """With a full ``R`` the simulator's ``e @ L.T`` (numpy matmul) and the kernel's explicit
    sum could differ in the last bit; U must agree to 1e-9."""
    agent = AgentSpec(measurement_noise_covariance=((12.0, 4.0), (4.0, 7.0)))
    scenario = random_scenario(3, seed=4, budget=300.0, agent=agent)
    record = run_episode(scenario, GreedyPlanner())
    _, info, _, seen = fly_greedy_in_box_env(scenario)
    assert record.detections.sum() > 25
    np.testing.assert_array_equal(seen, record.detections)
    assert info["U"] == pytest.approx(record.uncertainty, abs=1e-9)


def test_discrete_actions_replayed_in_the_simulator_give_the_same_mission():
    scenario = random_scenario(4, seed=7, budget=120.0)
    env = gym.make("hptrack/Tracking-v0", n_targets=4).unwrapped
    env.reset(options={"scenario": scenario})
    rng = np.random.default_rng(0)
    waypoints, truncated = [], False
    while not truncated:
        action = int(rng.integers(13))
        waypoints.append(np.array(env.waypoint(action)))
        _, _, _, truncated, info = env.step(action)
    record = run_episode(scenario, ReplayPlanner(waypoints))
    np.testing.assert_array_equal(env.world.agent, record.agent_path[-1])
    np.testing.assert_array_equal(env.world.covariances, record.belief_covariances[-1])
    assert info["U"] == record.uncertainty


def observation_policy(vector, layout):
    """A deterministic policy of the observation vector: head for the most uncertain target."""
    features = layout.target_features(vector)
    i = int(np.argmax(features[:, 4]))
    return int(round(np.degrees(np.arctan2(features[i, 1], features[i, 0])) / 30.0)) % 12


class VectorPolicyPlanner:
    """Flies :func:`observation_policy` in the simulator through the environments' encoding."""

    name = "vector-policy"

    def __init__(self, layout):
        self.layout = layout
        self.vectors = []

    def reset(self, mission, observation, rng):
        self.mission = mission

    def act(self, observation):
        vector = self.layout.encode_observation(observation, self.mission.budget)
        self.vectors.append(vector)
        action = observation_policy(vector, self.layout)
        return np.array(
            action_waypoint(
                "discrete", action, observation.agent_position, self.mission.step_length
            )
        )

    def episode_info(self):
        return {}


def test_a_policy_of_the_vector_flies_the_same_as_a_planner_in_the_simulator():
    """``encode_observation`` + ``action_waypoint`` turn a learned policy into a planner that
    sees the very vectors the environment gives (padded layout here)."""
    scenario = random_scenario(3, seed=8, budget=150.0)
    env = gym.make("hptrack/Tracking-v0", n_targets=3, max_targets=4).unwrapped
    vector, _ = env.reset(options={"scenario": scenario})
    vectors, truncated = [], False
    while not truncated:
        vectors.append(vector)
        vector, _, _, truncated, info = env.step(observation_policy(vector, env.layout))
    planner = VectorPolicyPlanner(ObservationLayout(4, True))
    record = run_episode(scenario, planner)
    np.testing.assert_array_equal(np.array(planner.vectors), np.array(vectors))
    assert info["U"] == record.uncertainty
    assert record.detections.sum() > 0


def lost_target_scenario():
    """Three targets; the second is far from its prior mean, so a coverage of it misses."""
    base = random_scenario(3, seed=5, budget=240.0)
    lost = base.targets[1].model_dump()
    lost["truth"] = (lost["mean"][0] + 1500.0, lost["mean"][1] - 1500.0, 0.0, 0.0)
    data = base.model_dump()
    data["targets"][1] = lost
    return Scenario.model_validate(data)


@pytest.mark.parametrize(
    "scenario",
    [random_scenario(3, seed=1, budget=200.0), lost_target_scenario()],
    ids=["random", "lost-target"],
)
def test_subtask_env_replaying_the_tree_search_gives_its_mission(scenario):
    """The hierarchical planner's sub-tasks (the paper's search, which pursues the lost target
    and misses it), chosen one by one in SubtaskTracking-v0, fly the same mission: same sub-task
    boundaries and outcomes, same U."""
    settings = MctsSettings(iterations=300, preset="paper")
    record = run_episode(scenario, HierarchicalPlanner(settings))
    n = len(scenario.targets)
    env = gym.make("hptrack/SubtaskTracking-v0", n_targets=n, max_targets=n + 1).unwrapped
    env.reset(options={"scenario": scenario})
    outcomes, truncated = [], False
    for entry in read_subtasks(record.info["subtasks"], record.target_ids):
        # pursue or follow the target; hover: a padding slot, step by step
        action = n if entry.kind == "hover" else entry.target
        _, _, _, truncated, info = env.step(action)
        while action == n and not truncated:
            _, _, _, truncated, info = env.step(action)
        sub = info["subtask"]
        assert sub["start_step"] == entry.start_step and sub["kind"] == entry.kind
        if entry.outcome is not None:
            assert (sub["outcome"], sub["end_step"]) == (entry.outcome, entry.end_step)
        outcomes.append(sub["outcome"])
    assert truncated
    assert info["U"] == record.uncertainty
    if scenario.targets[1].truth is not None:
        assert "missed" in outcomes


@pytest.mark.parametrize("every_step", [False, True])
def test_the_env_gives_the_records_gospa_and_track_loss(every_step):
    from hptrack.interface import InputError

    scenario = random_scenario(3, seed=5, budget=60.0)
    env = gym.make("hptrack/Tracking-v0", n_targets=3, gospa_every_step=every_step).unwrapped
    _, info = env.reset(options={"scenario": scenario})
    rng = np.random.default_rng(1)
    waypoints, gospas, truncated = [], [info.get("gospa")], False
    while not truncated:
        action = int(rng.integers(13))
        waypoints.append(np.array(env.waypoint(action)))
        _, _, _, truncated, info = env.step(action)
        gospas.append(info.get("gospa"))
    record = run_episode(scenario, ReplayPlanner(waypoints))
    _, history = record.gospa_history()
    assert info["gospa"] == history[-1] == record.metrics()["gospa_end"]
    np.testing.assert_array_equal(info["tracks_lost"], record.tracks_lost())
    if every_step:
        np.testing.assert_array_equal(gospas, history)
    else:
        assert gospas[:-1] == [None] * (len(history) - 1)
    with pytest.raises(InputError, match="gospa_every_step must be True or False, got 'yes'"):
        gym.make("hptrack/Tracking-v0", gospa_every_step="yes")
