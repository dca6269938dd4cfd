"""Learned policies on Tracking-v0 and as planners in the simulator."""

import gymnasium as gym
import numpy as np
import pytest
import torch

import hptrack.envs  # noqa: F401  (registers the environments)
from hptrack.envs.tracking import HOVER
from hptrack.interface import InputError
from hptrack.learning.agent import save_policy
from hptrack.learning.network import GaussianQNetwork
from hptrack.learning.policy_planner import AdfqPlanner, AdfqSettings, Sb3Planner, Sb3Settings
from hptrack.learning.train import network_policy, run_validation, tracking_task
from hptrack.scenario import TargetSpec, random_scenario
from hptrack.sim.episode import run_episode

N_ACTIONS = 13


def _hover_network(n_targets):
    net = GaussianQNetwork(6 * n_targets + 1, N_ACTIONS)
    with torch.no_grad():
        net.head.bias[HOVER] = 2.0
    return net


def _far_scenario(seed):
    """Two targets whose priors lie over 500 m from the agent's start (never seen hovering)."""
    scenario = random_scenario(2, seed)
    targets = [
        t.model_copy(update={"mean": (900.0, -800.0 + 1600.0 * i, *t.mean[2:])})
        for i, t in enumerate(scenario.targets)
    ]
    return scenario.model_copy(update={"targets": targets})


def test_a_policy_that_never_detects_scores_the_never_observed_u(tmp_path):
    """Hovering at the start, the env's final U and the simulator's equal the scenario's
    closed-form never-observed U (1e-9 relative: 1800 one-step predictions against one)."""
    scenario = _far_scenario(4)
    net = _hover_network(2)
    env = gym.make("hptrack/Tracking-v0", n_targets=2)
    obs, info = env.reset(options={"scenario": scenario})
    detections = 0
    for _ in range(scenario.n_steps):
        with torch.no_grad():
            action = int(net(torch.as_tensor(obs[None]))[0].argmax())
        obs, _, terminated, truncated, info = env.step(action)
        detections += int(info["detected"].sum())
    assert truncated and not terminated and detections == 0
    expected = scenario.never_observed_uncertainty()
    assert info["U"] == pytest.approx(expected, rel=1e-9)
    assert info["never_observed_U"] == pytest.approx(expected, rel=1e-12)

    save_policy(str(tmp_path / "hover.pt"), net, {})
    planner = AdfqPlanner(AdfqSettings(model=str(tmp_path / "hover.pt"), epsilon=0.0))
    record = run_episode(scenario, planner)
    assert record.detections.sum() == 0
    assert record.uncertainty == pytest.approx(expected, rel=1e-9)
    assert record.info["action_counts"][HOVER] == scenario.n_steps


def test_validation_scores_are_the_env_scores():
    task = tracking_task(2, validation_scenarios=2)
    results = run_validation(network_policy(_hover_network(2), 0.0, np.random.default_rng(0)), task)
    for kwargs, result in zip(task.validation, results, strict=True):
        scenario = kwargs["options"]["scenario"]
        assert result["never_observed_U"] == pytest.approx(
            scenario.never_observed_uncertainty(), rel=1e-12
        )
        assert result["U"] <= result["never_observed_U"] + 1e-9


def _near_scenario():
    """A target at the agent's start and one 300 m away: a moving policy measures them."""
    scenario = random_scenario(2, 11)
    cov = scenario.targets[0].covariance
    targets = [
        TargetSpec(id="a", mean=(20.0, 0.0, 1.0, 0.0), covariance=cov, process_noise=1e-4),
        TargetSpec(id="b", mean=(300.0, 100.0, -1.0, 0.5), covariance=cov, process_noise=3e-4),
    ]
    return scenario.model_copy(update={"targets": targets})


def test_the_planner_sees_what_the_env_observes(tmp_path):
    """A random network flown by the planner in the simulator and by the env: identical
    observation vectors at every step, so identical actions and the same U."""
    torch.manual_seed(5)
    net = GaussianQNetwork(13, N_ACTIONS)
    with torch.no_grad():
        net.head.weight.normal_(0.0, 1.0)
    path = tmp_path / "random.pt"
    save_policy(str(path), net, {"step": 0})
    scenario = _near_scenario()

    seen = []

    class Recording(AdfqPlanner):
        def encode(self, observation):
            vector = super().encode(observation)
            seen.append(vector)
            return vector

    record = run_episode(scenario, Recording(AdfqSettings(model=str(path), epsilon=0.0)))

    env = gym.make("hptrack/Tracking-v0", n_targets=2)
    obs, _ = env.reset(options={"scenario": scenario})
    env_obs = []
    done = False
    while not done:
        env_obs.append(obs)
        with torch.no_grad():
            action = int(net(torch.as_tensor(obs[None]))[0].argmax())
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    np.testing.assert_allclose(np.array(seen), np.array(env_obs), atol=1e-6)
    assert record.detections.sum() > 0
    assert record.uncertainty == pytest.approx(info["U"], rel=1e-9)
    assert len(set(np.flatnonzero(record.info["action_counts"]))) > 1


def test_epsilon_draws_come_from_the_planner_generator(tmp_path):
    save_policy(str(tmp_path / "hover.pt"), _hover_network(2), {})
    settings = AdfqSettings(model=str(tmp_path / "hover.pt"), epsilon=0.5)
    scenario = _far_scenario(2).model_copy(update={"budget": 300.0})
    a = run_episode(scenario, AdfqPlanner(settings))
    b = run_episode(scenario, AdfqPlanner(settings))
    counts = a.info["action_counts"]
    assert counts == b.info["action_counts"]
    assert counts[HOVER] == pytest.approx(scenario.n_steps * (0.5 + 0.5 / 13), rel=0.1)


def test_bad_models_are_one_line_input_errors(tmp_path):
    planner = AdfqPlanner(AdfqSettings(model=str(tmp_path / "missing.pt")))
    scenario = random_scenario(2, 0)
    with pytest.raises(InputError, match="missing.pt"):
        run_episode(scenario, planner)
    save_policy(str(tmp_path / "n3.pt"), _hover_network(3), {})
    with pytest.raises(InputError, match="takes 19 inputs"):
        run_episode(scenario, AdfqPlanner(AdfqSettings(model=str(tmp_path / "n3.pt"))))
    with pytest.raises(InputError, match="epsilon"):
        AdfqSettings.from_options("adfq", {"epsilon": 2})


def test_sb3_planner_flies_a_ppo_model_like_the_env(tmp_path):
    from stable_baselines3 import PPO

    env = gym.make("hptrack/Tracking-v0", n_targets=2)
    model = PPO("MlpPolicy", env, n_steps=60, batch_size=60, seed=1, device="cpu")
    model.save(str(tmp_path / "ppo.zip"))
    scenario = _near_scenario().model_copy(update={"budget": 150.0})
    record = run_episode(scenario, Sb3Planner(Sb3Settings(model=str(tmp_path / "ppo.zip"))))
    obs, _ = env.reset(options={"scenario": scenario})
    done = False
    while not done:
        action = int(model.predict(obs, deterministic=True)[0])
        obs, _, terminated, truncated, info = env.step(action)
        done = terminated or truncated
    assert record.uncertainty == pytest.approx(info["U"], rel=1e-9)
    sampled = run_episode(
        scenario, Sb3Planner(Sb3Settings(model=str(tmp_path / "ppo.zip"), deterministic=False))
    )
    again = run_episode(
        scenario, Sb3Planner(Sb3Settings(model=str(tmp_path / "ppo.zip"), deterministic=False))
    )
    assert sampled.info["action_counts"] == again.info["action_counts"]


@pytest.mark.parametrize("n_targets", [2, 3, 4, 5, 6])
def test_shipped_adfq_models_fit_their_missions(n_targets):
    """Each shipped model loads, takes the n-target observation and was selected on the
    heterogeneous validation scenarios; the planner picks it without a model option."""
    from hptrack.learning.agent import load_policy
    from hptrack.learning.policy_planner import packaged_model

    network, metadata = load_policy(str(packaged_model("adfq", n_targets)))
    assert network.obs_dim == 6 * n_targets + 1 and network.n_actions == N_ACTIONS
    assert metadata["task"]["n_targets"] == n_targets
    assert metadata["task"]["setting"] == "heterogeneous"
    scenario = random_scenario(n_targets, 0).model_copy(update={"budget": 5.0})
    record = run_episode(scenario, AdfqPlanner())
    assert record.info["model_file"] == str(packaged_model("adfq", n_targets))


@pytest.mark.parametrize("n_targets", [2, 6])
def test_shipped_ppo_models_fit_their_missions(n_targets):
    from hptrack.learning.policy_planner import packaged_model

    scenario = random_scenario(n_targets, 0).model_copy(update={"budget": 5.0})
    record = run_episode(scenario, Sb3Planner())
    assert record.info["model_file"] == str(packaged_model("sb3", n_targets))
