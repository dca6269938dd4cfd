"""A tiny Gymnasium problem for the learner's tests, and one torch thread."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces

CHAIN_ID = "hptrack-test/Chain-v0"


class ChainEnv(gym.Env):
    """A corridor of ``length`` cells, actions left / stay / right, reward 1 in the last cell,
    truncated after ``horizon`` steps; ``info["U"]`` is minus the return (lower is better)."""

    def __init__(self, length: int = 5, horizon: int = 20) -> None:
        self.length, self.horizon = length, horizon
        self.observation_space = spaces.Box(0.0, 1.0, (length + 1,), dtype=np.float32)
        self.action_space = spaces.Discrete(3)

    def _obs(self) -> np.ndarray:
        obs = np.zeros(self.length + 1, dtype=np.float32)
        obs[self.cell] = 1.0
        obs[-1] = 1.0 - self.t / self.horizon
        return obs

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.cell = int(self.np_random.integers(0, self.length - 1))
        self.t, self.total = 0, 0.0
        return self._obs(), {"U": -self.total}

    def step(self, action):
        self.cell = int(np.clip(self.cell + int(action) - 1, 0, self.length - 1))
        self.t += 1
        reward = 1.0 if self.cell == self.length - 1 else 0.0
        self.total += reward
        return self._obs(), reward, False, self.t >= self.horizon, {"U": -self.total}


if CHAIN_ID not in gym.registry:
    gym.register(id=CHAIN_ID, entry_point=ChainEnv)


@pytest.fixture(autouse=True)
def _one_thread():
    torch.set_num_threads(1)
