"""The observation vector of the environments: the belief state scaled to O(1), flat float32.

Per target slot, six features (`FEATURES`):

* ``dx, dy``: belief mean minus agent position, per axis, / 1000 m;
* ``vx, vy``: belief mean velocity / 3 m/s;
* ``logdet``: ``(log det Sigma^xy - 14) / 10`` (``log m^4``);
* ``measured``: 1 if the target was measured at this step, else 0;

then the fraction of the budget left, then (only with padding) a mask of ``max_targets`` entries,
1 for a real target and 0 for a padding slot (whose six features are 0). Every continuous feature
is clipped to ``[-FEATURE_BOUND, FEATURE_BOUND]`` (10 km, 30 m/s, ``log det`` in [-86, 114]),
so the space has finite bounds; flags, fraction and mask lie in [0, 1].
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from hptrack.interface import Observation
from hptrack.models.beliefs import logdet_xy
from hptrack.models.state import position_of, velocity_of

FEATURES = ("dx", "dy", "vx", "vy", "logdet", "measured")
"""The per-target features, in order."""
N_FEATURES = len(FEATURES)
POSITION_SCALE_M = 1000.0
VELOCITY_SCALE_MPS = 3.0
LOGDET_OFFSET = 14.0
LOGDET_SCALE = 10.0
FEATURE_BOUND = 10.0
"""Bound of every scaled continuous feature (values beyond it are clipped)."""


@numba.njit(cache=True, inline="always")
def _clip(value, bound):
    return min(max(value, -bound), bound)


@numba.njit(cache=True)
def encode(agent, means, logdets, seen, budget_fraction, n_slots, masked, out):
    """Fill ``out`` (float32, `ObservationLayout.size`) from the beliefs ``means`` ``(n,
    4)``, per-target ``logdets`` ``(n,)``, measurement flags ``seen`` ``(n,)`` and the fraction of
    the budget left; slots ``n .. n_slots - 1`` are padding."""
    b = FEATURE_BOUND
    n = means.shape[0]
    for i in range(n_slots):
        k = N_FEATURES * i
        if i < n:
            x, y = position_of(means[i])
            vx, vy = velocity_of(means[i])
            out[k] = _clip((x - agent[0]) / POSITION_SCALE_M, b)
            out[k + 1] = _clip((y - agent[1]) / POSITION_SCALE_M, b)
            out[k + 2] = _clip(vx / VELOCITY_SCALE_MPS, b)
            out[k + 3] = _clip(vy / VELOCITY_SCALE_MPS, b)
            out[k + 4] = _clip((logdets[i] - LOGDET_OFFSET) / LOGDET_SCALE, b)
            out[k + 5] = 1.0 if seen[i] else 0.0
        else:
            for j in range(N_FEATURES):
                out[k + j] = 0.0
    k = N_FEATURES * n_slots
    out[k] = min(max(budget_fraction, 0.0), 1.0)
    if masked:
        for i in range(n_slots):
            out[k + 1 + i] = 1.0 if i < n else 0.0


@numba.njit(cache=True)
def position_logdets(covs, out):
    """``out[i] = log det Sigma^xy_i`` of covariances ``(n, 4, 4)`` (the simulator's kernel)."""
    for i in range(covs.shape[0]):
        out[i] = logdet_xy(covs[i, 0, 0], covs[i, 0, 1], covs[i, 1, 1])


@dataclass(frozen=True)
class ObservationLayout:
    """Where everything lies in the observation vector.

    Attributes:
        n_slots: target slots (``n``, or ``max_targets`` with padding).
        masked: whether a mask of ``n_slots`` entries ends the vector.
    """

    n_slots: int
    masked: bool

    @property
    def size(self) -> int:
        """Length of the vector."""
        return N_FEATURES * self.n_slots + 1 + (self.n_slots if self.masked else 0)

    @property
    def budget_index(self) -> int:
        """Index of the fraction of the budget left."""
        return N_FEATURES * self.n_slots

    def target_features(self, observation: np.ndarray) -> np.ndarray:
        """``(..., n_slots, 6)`` view of the per-target features of observations ``(..., size)``."""
        return observation[..., : self.budget_index].reshape(
            *observation.shape[:-1], self.n_slots, N_FEATURES
        )

    def mask(self, observation: np.ndarray) -> np.ndarray:
        """``(..., n_slots)`` bool: which slots hold a real target."""
        if not self.masked:
            return np.ones((*observation.shape[:-1], self.n_slots), dtype=bool)
        return observation[..., self.budget_index + 1 :] > 0.5

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)`` float32 arrays of the observation space."""
        per_target_low = np.array([-FEATURE_BOUND] * (N_FEATURES - 1) + [0.0])
        per_target_high = np.array([FEATURE_BOUND] * (N_FEATURES - 1) + [1.0])
        tail = 1 + (self.n_slots if self.masked else 0)
        low = np.concatenate([np.tile(per_target_low, self.n_slots), np.zeros(tail)])
        high = np.concatenate([np.tile(per_target_high, self.n_slots), np.ones(tail)])
        return low.astype(np.float32), high.astype(np.float32)

    def encode(
        self,
        agent: np.ndarray,
        means: np.ndarray,
        logdets: np.ndarray,
        seen: np.ndarray,
        budget_fraction: float,
    ) -> np.ndarray:
        """A new observation vector (module docstring)."""
        if means.shape[0] > self.n_slots:
            raise ValueError(f"{means.shape[0]} targets do not fit in {self.n_slots} slots")
        out = np.empty(self.size, dtype=np.float32)
        encode(agent, means, logdets, seen, float(budget_fraction), self.n_slots, self.masked, out)
        return out

    def encode_observation(self, observation: Observation, budget: float) -> np.ndarray:
        """The vector of a planner's `Observation` of a mission of
        ``budget`` s: the one the environment returns in the same state (to fly a learned
        policy as a planner in the simulator)."""
        covs = np.ascontiguousarray(observation.covariances, dtype=float)
        logdets = np.empty(covs.shape[0])
        position_logdets(covs, logdets)
        return self.encode(
            np.asarray(observation.agent_position, dtype=float),
            np.ascontiguousarray(observation.means, dtype=float),
            logdets,
            np.asarray(observation.detected, dtype=bool),
            observation.remaining_budget / budget,
        )
