"""Deep ADFQ (Jeong & Lee, IJCAI 2019): a network of Gaussian Q-value beliefs trained towards
the ADFQ posterior (`hptrack.learning.adfq`).

* Exploration: Thompson sampling, ``Q_a ~ N(mu_a, sigma_a^2)`` from the online network, then
  the argmax.
* Targets: for a replayed transition ``(s, a, r, s')`` the prior ``Q(s, a)`` and the next-state
  beliefs ``Q(s', .)`` come from the target network (a hard copy of the online network every
  ``target_update`` steps); the ADFQ posterior gives a target mean and variance.
* Loss: Huber on the mean error plus Huber on the log-sd error, weighted by the replay's
  importance weights; Adam, gradient norm clipped.
* Test policy: greedy on the means, with probability ``epsilon`` a uniformly random action.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from hptrack.learning.adfq import adfq_posterior
from hptrack.learning.network import HIDDEN, INIT_MEAN, INIT_SD, GaussianQNetwork
from hptrack.learning.replay import PrioritizedReplayBuffer, ReplayBuffer
from hptrack.learning.weights import describe, load_weights

POLICY_FORMAT = "hptrack-adfq-policy-1"
"""Tag of a policy file (`save_policy`)."""


@dataclass(frozen=True)
class AdfqConfig:
    """Deep ADFQ hyperparameters (the published values; ``noise`` is the observation noise
    variance of the Bellman target, 1 for target tracking)."""

    gamma: float = 0.99
    learning_rate: float = 1e-3
    batch_size: int = 32
    buffer_size: int = 200_000
    warmup_steps: int = 10_000
    target_update: int = 500
    grad_clip: float = 10.0
    noise: float = 1.0
    prioritized: bool = False
    alpha: float = 0.6
    beta_start: float = 0.4
    hidden: tuple[int, ...] = field(default=HIDDEN)
    init_mean: float = INIT_MEAN
    init_sd: float = INIT_SD

    def as_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["hidden"] = list(self.hidden)
        return out


def greedy_actions(mean: np.ndarray, epsilon: float, rng: np.random.Generator) -> np.ndarray:
    """Argmax of ``mean`` ``(B, A)`` per row; each row with probability ``epsilon`` takes a
    uniformly random action instead."""
    actions = mean.argmax(axis=1)
    if epsilon > 0.0:
        explore = rng.random(len(actions)) < epsilon
        actions = np.where(explore, rng.integers(0, mean.shape[1], len(actions)), actions)
    return actions


class AdfqAgent:
    """Online and target networks, optimiser and replay of one Deep ADFQ learner."""

    def __init__(self, obs_dim: int, n_actions: int, config: AdfqConfig | None = None) -> None:
        self.config = config = config or AdfqConfig()
        self.obs_dim, self.n_actions = obs_dim, n_actions
        self.online = GaussianQNetwork(
            obs_dim, n_actions, config.hidden, config.init_mean, config.init_sd
        )
        self.target = copy.deepcopy(self.online)
        self.target.requires_grad_(False)
        self.optimizer = torch.optim.Adam(
            self.online.parameters(), lr=config.learning_rate, foreach=True
        )
        self.replay = (
            PrioritizedReplayBuffer(config.buffer_size, obs_dim, config.alpha)
            if config.prioritized
            else ReplayBuffer(config.buffer_size, obs_dim)
        )
        self._huber = nn.HuberLoss(reduction="none")

    # --- acting ------------------------------------------------------------------------------
    @torch.no_grad()
    def beliefs(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Online means and standard deviations ``(B, A)`` of observations ``(B, d)``."""
        mean, log_sd = self.online(torch.as_tensor(obs, dtype=torch.float32))
        return mean.numpy().astype(np.float64), np.exp(log_sd.numpy().astype(np.float64))

    def thompson_action(self, obs: np.ndarray, rng: np.random.Generator) -> int:
        """One draw of every ``Q(s, a)`` from its belief, then the argmax."""
        mean, sd = self.beliefs(obs[None])
        return int(np.argmax(mean[0] + sd[0] * rng.standard_normal(self.n_actions)))

    # --- learning ----------------------------------------------------------------------------
    def remember(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> None:
        """Store a transition; ``terminal`` only for a true terminal state, never for the time
        limit."""
        self.replay.add(obs, action, reward, next_obs, terminal)

    def sync_target(self) -> None:
        """Hard copy of the online network into the target network."""
        self.target.load_state_dict(self.online.state_dict())

    @torch.no_grad()
    def posterior_targets(self, batch: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """ADFQ posterior mean and variance of ``Q(s, a)`` for a replayed batch, from the
        target network."""
        obs = torch.as_tensor(np.concatenate([batch["obs"], batch["next_obs"]]))
        mean, log_sd = self.target(obs)
        mean = mean.numpy().astype(np.float64)
        var = np.exp(2.0 * log_sd.numpy().astype(np.float64))
        b = len(batch["action"])
        rows = np.arange(b)
        return adfq_posterior(
            mean[rows, batch["action"]],
            var[rows, batch["action"]],
            mean[b:],
            var[b:],
            batch["reward"],
            self.config.gamma,
            batch["terminal"],
            noise=self.config.noise,
        )

    def train_step(self, rng: np.random.Generator, beta: float | None = None) -> dict[str, float]:
        """One gradient step on a replayed batch; ``beta`` is the importance exponent of
        prioritised replay. Returns the loss and its mean and log-sd parts."""
        cfg = self.config
        if cfg.prioritized:
            batch = self.replay.sample(
                cfg.batch_size, rng, cfg.beta_start if beta is None else beta
            )
        else:
            batch = self.replay.sample(cfg.batch_size, rng)
        target_mean, target_var = self.posterior_targets(batch)
        mean, log_sd = self.online(torch.as_tensor(batch["obs"]))
        action = torch.as_tensor(batch["action"])[:, None]
        mean = mean.gather(1, action)[:, 0]
        log_sd = log_sd.gather(1, action)[:, 0]
        mean_target = torch.as_tensor(target_mean, dtype=torch.float32)
        log_sd_target = torch.as_tensor(0.5 * np.log(target_var), dtype=torch.float32)
        mean_loss = self._huber(mean, mean_target)
        sd_loss = self._huber(log_sd, log_sd_target)
        weight = torch.as_tensor(batch["weight"], dtype=torch.float32)
        loss = (weight * (mean_loss + sd_loss)).mean()
        self.optimizer.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(self.online.parameters(), cfg.grad_clip)
        self.optimizer.step()
        if cfg.prioritized:
            self.replay.update_priorities(batch["index"], target_mean - mean.detach().numpy())
        return {
            "loss": loss.item(),
            "mean_loss": mean_loss.detach().mean().item(),
            "sd_loss": sd_loss.detach().mean().item(),
        }

    # --- saving ------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        """Networks and optimiser (the replay is saved separately: it is large)."""
        return {
            "online": self.online.state_dict(),
            "target": self.target.state_dict(),
            "optimizer": self.optimizer.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.online.load_state_dict(state["online"])
        self.target.load_state_dict(state["target"])
        self.optimizer.load_state_dict(state["optimizer"])


def save_policy(path: str, network: GaussianQNetwork, metadata: dict[str, Any]) -> None:
    """Write a trained network and what produced it (a small ``.pt`` file)."""
    torch.save(
        {
            "format": POLICY_FORMAT,
            "network": network.config(),
            "state_dict": network.state_dict(),
            "metadata": metadata,
        },
        path,
    )


def load_policy(path: str) -> tuple[GaussianQNetwork, dict[str, Any]]:
    """The network and metadata of a policy file written by `save_policy`, read as weights only
    (`hptrack.learning.weights.load_weights`).

    Raises:
        ValueError: the file is not such a policy, or its tensors do not fit its network
            (one line that names the file).
    """
    label = f"ADFQ model {path}"
    if describe(path) == "a stable-baselines3 model":
        raise ValueError(f"{label}: is a stable-baselines3 model: fly it with --planner sb3")
    data = load_weights(path, label)
    if not isinstance(data, dict) or data.get("format") != POLICY_FORMAT:
        raise ValueError(
            f"{label}: not an hptrack ADFQ policy file (best.pt of hptrack learn adfq)"
        )
    try:
        network = GaussianQNetwork.from_config(data["network"], data["state_dict"])
        network.load_state_dict(data["state_dict"])
    except (KeyError, TypeError, ValueError, RuntimeError):
        raise ValueError(
            f"{label}: its network description and tensors do not fit (a damaged or edited file)"
        ) from None
    network.eval()
    return network, data.get("metadata", {})


def set_torch_threads() -> None:
    """One intra-op thread: the network is too small to gain from more."""
    if torch.get_num_threads() != 1:
        torch.set_num_threads(1)
