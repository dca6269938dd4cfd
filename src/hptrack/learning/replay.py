"""Experience replay for Deep ADFQ: a uniform ring buffer over preallocated arrays, and
proportional prioritised replay (Schaul et al. 2016) on a sum tree as an option.

A transition that ends by the time limit is stored as non-terminal (``terminal`` False): its
next state still has a value. `ReplayBuffer.state_dict` / `load_state_dict` save
and restore the filled part, so that training resumes with the same memory.
"""

from __future__ import annotations

import numpy as np

PRIORITY_EPS = 1e-6
"""Added to every priority so that no transition is never replayed."""


class ReplayBuffer:
    """Uniform replay of ``(obs, action, reward, next_obs, terminal)``."""

    def __init__(self, capacity: int, obs_dim: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity}")
        self.capacity, self.obs_dim = capacity, obs_dim
        self.obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self.action = np.zeros(capacity, dtype=np.int64)
        self.reward = np.zeros(capacity, dtype=np.float64)
        self.terminal = np.zeros(capacity, dtype=bool)
        self.size = 0
        self.cursor = 0

    def __len__(self) -> int:
        return self.size

    def add(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> int:
        """Store one transition (overwriting the oldest when full); returns its slot."""
        slot = self.cursor
        self.obs[slot], self.next_obs[slot] = obs, next_obs
        self.action[slot], self.reward[slot], self.terminal[slot] = action, reward, terminal
        self.cursor = (slot + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)
        return slot

    def batch(self, index: np.ndarray) -> dict[str, np.ndarray]:
        """The transitions at ``index``."""
        return {
            "obs": self.obs[index],
            "action": self.action[index],
            "reward": self.reward[index],
            "next_obs": self.next_obs[index],
            "terminal": self.terminal[index],
            "index": index,
            "weight": np.ones(len(index)),
        }

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """``batch_size`` transitions drawn uniformly (with replacement); weights are 1."""
        return self.batch(rng.integers(0, self.size, size=batch_size))

    def state_dict(self) -> dict[str, np.ndarray]:
        """The filled part of the buffer and its cursor."""
        n = self.size
        return {
            "obs": self.obs[:n],
            "next_obs": self.next_obs[:n],
            "action": self.action[:n],
            "reward": self.reward[:n],
            "terminal": self.terminal[:n],
            "cursor": np.array(self.cursor),
        }

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        n = len(state["action"])
        if n > self.capacity or state["obs"].shape[1:] != (self.obs_dim,):
            raise ValueError(
                f"saved replay of {n} x {state['obs'].shape[1:]} does not fit "
                f"a buffer of {self.capacity} x ({self.obs_dim},)"
            )
        for name in ("obs", "next_obs", "action", "reward", "terminal"):
            getattr(self, name)[:n] = state[name]
        self.size, self.cursor = n, int(state["cursor"])


class PrioritizedReplayBuffer(ReplayBuffer):
    """Proportional prioritised replay: ``P(i) ~ p_i^alpha``, importance weights
    ``(N P(i))^-beta / max``; new transitions get the largest priority seen so far."""

    def __init__(self, capacity: int, obs_dim: int, alpha: float = 0.6) -> None:
        super().__init__(capacity, obs_dim)
        self.alpha = alpha
        self._leaves = max(2, 1 << (capacity - 1).bit_length())
        self.tree = np.zeros(2 * self._leaves)
        self.max_priority = 1.0

    def _set(self, slots: np.ndarray, values: np.ndarray) -> None:
        nodes = np.asarray(slots) + self._leaves
        self.tree[nodes] = values
        while nodes[0] > 1:
            nodes = np.unique(nodes // 2)
            self.tree[nodes] = self.tree[2 * nodes] + self.tree[2 * nodes + 1]

    def add(
        self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, terminal: bool
    ) -> int:
        slot = super().add(obs, action, reward, next_obs, terminal)
        self._set(np.array([slot]), np.array([self.max_priority**self.alpha]))
        return slot

    def _find(self, mass: np.ndarray) -> np.ndarray:
        node = np.ones(len(mass), dtype=np.int64)
        while node[0] < self._leaves:
            left = 2 * node
            go_right = mass > self.tree[left]
            mass = np.where(go_right, mass - self.tree[left], mass)
            node = np.where(go_right, left + 1, left)
        return np.minimum(node - self._leaves, self.size - 1)

    def sample(
        self, batch_size: int, rng: np.random.Generator, beta: float = 0.4
    ) -> dict[str, np.ndarray]:
        """Stratified proportional sample with importance weights (exponent ``beta``)."""
        total = self.tree[1]
        edges = np.linspace(0.0, total, batch_size + 1)
        index = self._find(rng.uniform(edges[:-1], edges[1:]))
        prob = self.tree[index + self._leaves] / total
        weight = (self.size * prob) ** -beta
        out = self.batch(index)
        out["weight"] = weight / weight.max()
        return out

    def update_priorities(self, index: np.ndarray, errors: np.ndarray) -> None:
        """Priorities ``|error| + eps`` of the replayed transitions."""
        priority = np.abs(errors) + PRIORITY_EPS
        self.max_priority = max(self.max_priority, float(priority.max()))
        self._set(index, priority**self.alpha)

    def state_dict(self) -> dict[str, np.ndarray]:
        state = super().state_dict()
        state["priority"] = self.tree[self._leaves : self._leaves + self.size].copy()
        state["max_priority"] = np.array(self.max_priority)
        return state

    def load_state_dict(self, state: dict[str, np.ndarray]) -> None:
        super().load_state_dict(state)
        self.tree[:] = 0.0
        if self.size:
            self._set(np.arange(self.size), state["priority"])
        self.max_priority = float(state["max_priority"])
