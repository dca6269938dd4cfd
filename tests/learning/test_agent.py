"""Deep ADFQ network and agent: initial beliefs, Thompson sampling, targets, learning."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import CHAIN_ID
from scipy.stats import norm

from hptrack.learning.adfq import adfq_posterior
from hptrack.learning.agent import AdfqAgent, AdfqConfig, greedy_actions, load_policy, save_policy
from hptrack.learning.network import SD_MAX, SD_MIN, GaussianQNetwork


def test_network_starts_with_the_same_broad_belief_for_every_action():
    torch.manual_seed(0)
    net = GaussianQNetwork(7, 13)
    mean, log_sd = net(torch.randn(5, 7))
    assert torch.allclose(mean, torch.ones(5, 13))
    assert torch.allclose(log_sd.exp(), torch.full((5, 13), 10.0))
    assert [m.out_features for m in net.body if isinstance(m, torch.nn.Linear)] == [64, 128, 64]


def test_standard_deviation_is_clipped():
    net = GaussianQNetwork(2, 3)
    with torch.no_grad():
        net.head.bias[3:] = torch.tensor([100.0, -100.0, 0.0])
    _, log_sd = net(torch.zeros(1, 2))
    np.testing.assert_allclose(log_sd.detach().exp().numpy()[0], [SD_MIN, SD_MAX, 1.0], rtol=1e-5)


def test_thompson_sampling_follows_the_beliefs():
    agent = AdfqAgent(2, 3, AdfqConfig(buffer_size=10))
    with torch.no_grad():
        agent.online.head.bias[:3] = torch.tensor([0.0, 0.5, -5.0])
        agent.online.head.bias[3:] = -torch.log(torch.tensor([1.0, 1.0, 1e-3]))
    rng = np.random.default_rng(0)
    actions = np.array([agent.thompson_action(np.zeros(2, np.float32), rng) for _ in range(1000)])
    p1 = norm.cdf(0.5 / np.sqrt(2.0))  # P(N(0.5, 1) > N(0, 1))
    assert np.mean(actions == 1) == pytest.approx(p1, abs=0.05)
    assert not np.any(actions == 2)


def test_greedy_actions_with_epsilon():
    mean = np.tile([0.0, 2.0, 1.0], (20_000, 1))
    assert np.all(greedy_actions(mean, 0.0, np.random.default_rng(0)) == 1)
    actions = greedy_actions(mean, 0.3, np.random.default_rng(1))
    assert np.mean(actions != 1) == pytest.approx(0.2, abs=0.01)  # 0.3 random, 2/3 of them off


def test_training_targets_are_the_posterior_of_the_target_network():
    agent = AdfqAgent(3, 4, AdfqConfig(buffer_size=10, noise=1.0))
    torch.manual_seed(1)
    with torch.no_grad():
        agent.target.head.weight.normal_()
    rng = np.random.default_rng(0)
    batch = {
        "obs": rng.normal(size=(5, 3)).astype(np.float32),
        "next_obs": rng.normal(size=(5, 3)).astype(np.float32),
        "action": np.array([0, 1, 2, 3, 0]),
        "reward": rng.normal(size=5),
        "terminal": np.zeros(5, bool),
    }
    mean, var = agent.posterior_targets(batch)
    with torch.no_grad():
        m0, s0 = agent.target(torch.as_tensor(batch["obs"]))
        m1, s1 = agent.target(torch.as_tensor(batch["next_obs"]))
    rows = np.arange(5)
    expected = adfq_posterior(
        m0.numpy()[rows, batch["action"]].astype(float),
        np.exp(2 * s0.numpy().astype(float))[rows, batch["action"]],
        m1.numpy().astype(float),
        np.exp(2 * s1.numpy().astype(float)),
        batch["reward"],
        0.99,
        noise=1.0,
    )
    np.testing.assert_allclose(mean, expected[0], rtol=1e-6)
    np.testing.assert_allclose(var, expected[1], rtol=1e-6)


@pytest.mark.parametrize("prioritized", [False, True])
def test_a_few_hundred_steps_lower_the_loss(prioritized):
    """On the chain, 300 gradient steps bring the loss well below its start."""
    torch.manual_seed(0)
    env = gym.make(CHAIN_ID)
    config = AdfqConfig(
        buffer_size=2000, warmup_steps=100, target_update=50, prioritized=prioritized
    )
    agent = AdfqAgent(env.observation_space.shape[0], env.action_space.n, config)
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    losses = []
    for step in range(1, 401):
        action = agent.thompson_action(obs, rng)
        next_obs, reward, terminated, truncated, _ = env.step(action)
        agent.remember(obs, action, reward, next_obs, terminated)
        obs = env.reset()[0] if terminated or truncated else next_obs
        if step > config.warmup_steps:
            losses.append(agent.train_step(rng, beta=0.4 + 0.6 * step / 400)["loss"])
            if step % config.target_update == 0:
                agent.sync_target()
    assert np.mean(losses[-50:]) < 0.25 * np.mean(losses[:20])


def test_policy_file_round_trip(tmp_path):
    torch.manual_seed(2)
    net = GaussianQNetwork(5, 13)
    with torch.no_grad():
        net.head.weight.normal_()
    save_policy(str(tmp_path / "p.pt"), net, {"step": 12})
    loaded, metadata = load_policy(str(tmp_path / "p.pt"))
    x = torch.randn(4, 5)
    assert torch.equal(loaded(x)[0], net(x)[0]) and metadata == {"step": 12}
    (tmp_path / "bad.pt").write_text("not a model")
    with pytest.raises(ValueError, match="bad.pt"):
        load_policy(str(tmp_path / "bad.pt"))
