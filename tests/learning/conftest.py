"""A tiny Gymnasium problem for the learner's tests, and one torch thread."""

import os
import pickle
import zipfile

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


class Payload:
    """A pickled object whose unpickling creates the folder ``marker`` (a stand-in for any code a
    model file from somebody else could run when it is unpickled)."""

    def __init__(self, marker) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def payload_pickle(marker) -> bytes:
    """A pickle of a dict holding a :class:`Payload` (protocol 2, as ``torch.save`` writes)."""
    return pickle.dumps({"format": Payload(marker)}, protocol=2)


def ppo_zip_with(path, source, replace: dict[str, bytes]):
    """A copy of the stable-baselines3 zip ``source`` at ``path`` with members replaced."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(path, "w") as new:
        for name in old.namelist():
            new.writestr(name, replace.get(name, old.read(name)))
    return path


def refused_in_one_line(result, *needles) -> str:
    """Assert an exit code 2 with one error line holding ``needles`` and no traceback or
    warning; return the line."""
    assert result.code == 2, (result.code, result.out, result.err)
    lines = result.error_lines
    assert len(lines) == 1 and "Traceback" not in result.err, result.err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]
