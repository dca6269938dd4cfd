"""The layout of a target's state ``[x, y, vx, vy]`` (m, m/s; paper Sec. III): the one place
that indexes it. Every layer above the models reads a state's position and velocity through
these accessors (compiled ones for one state, numpy ones for stacked states ``(..., 4)``), so
that a motion model with another layout changes this module, not its readers.
"""

from __future__ import annotations

import numba
import numpy as np

POSITION = slice(0, 2)
"""Where a state's position ``(x, y)`` (m) lies."""
VELOCITY = slice(2, 4)
"""Where a state's velocity ``(vx, vy)`` (m/s) lies."""


@numba.njit(cache=True, inline="always")
def position_of(state):
    """``(x, y)`` of one state, m (compiled code)."""
    return state[0], state[1]


@numba.njit(cache=True, inline="always")
def velocity_of(state):
    """``(vx, vy)`` of one state, m/s (compiled code)."""
    return state[2], state[3]


@numba.njit(cache=True, inline="always")
def set_position(state, x, y):
    """Write the position ``(x, y)`` (m) of one state in place (compiled code)."""
    state[0] = x
    state[1] = y


@numba.njit(cache=True, inline="always")
def set_velocity(state, vx, vy):
    """Write the velocity ``(vx, vy)`` (m/s) of one state in place (compiled code)."""
    state[2] = vx
    state[3] = vy


@numba.njit(cache=True, inline="always")
def velocity_variance_of(covariance):
    """The mean of the two velocity variances of one state covariance, (m/s)^2 (compiled
    code)."""
    return 0.5 * (covariance[2, 2] + covariance[3, 3])


def positions(states: np.ndarray) -> np.ndarray:
    """The positions ``(..., 2)`` of stacked states ``(..., 4)``, m (a view)."""
    return states[..., POSITION]


def velocities(states: np.ndarray) -> np.ndarray:
    """The velocities ``(..., 2)`` of stacked states ``(..., 4)``, m/s (a view)."""
    return states[..., VELOCITY]


def speeds(states: np.ndarray) -> np.ndarray:
    """The speeds ``|v|`` of stacked states ``(..., 4)``, m/s."""
    v = velocities(np.asarray(states, dtype=float))
    return np.hypot(v[..., 0], v[..., 1])


def state_from(position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """Stacked states ``(..., 4)`` from positions and velocities ``(..., 2)``."""
    return np.concatenate([position, velocity], axis=-1)
