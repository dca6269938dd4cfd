"""How the simulated targets truly move: the paper's constant velocity (Sec. III) and motions
that break it, so that a planner whose beliefs assume constant velocity can be measured against
targets that turn, wander or slow down.

A truth model is a ``NamedTuple`` class (its fields are its parameters, SI units) registered
with `register_truth_motion` and a compiled kernel ``advance(model, mission, truth, z,
sqrt_q)`` that moves every true state ``[x, y, vx, vy]`` of ``truth`` ``(n, 4)`` one step of
``tau`` in place, with the unit normals ``z`` ``(n, 4)`` (the simulator's motion stream, four per
target and step whatever the model) and ``sqrt_q`` ``(n,)`` the square roots of the targets'
noise intensities ``q`` (m^2/s^3). Compiled code calls `advance_truth`, dispatched at compile
time on the model's class. The models:

* `ConstantVelocityTruth` (the paper's and the default): ``x <- F x + sqrt(q) L z`` with the
  mission's ``F`` and ``Q`` (`hptrack.models.motion.advance_true_state`);
* `CoordinatedTurn`: each target turns at its own constant rate ``omega_i`` (rad/s,
  counter-clockwise positive): the velocity rotates by ``omega tau`` per step and the position
  follows the exact arc, plus the same noise as constant velocity. Known rates (one for all) or
  random ones (drawn once per target and mission);
* `RandomWalk`: the position diffuses, ``x <- x + sqrt(D tau) z``, the velocity stays 0;
  position variance ``D t`` per axis (``D`` in m^2/s);
* `OrnsteinUhlenbeck`: the velocity is pulled back to 0 at rate ``K`` (1/s) while driven by the
  target's ``q``: ``dv = -K v dt + sqrt(q) dW``, sampled exactly (the integrated
  Ornstein-Uhlenbeck process); as ``K -> 0`` it becomes constant velocity;
* `SingerTruth` and `ConstantAccelerationTruth`: true states ``[x, y, vx, vy, ax, ay]`` (6
  normals per target and step, ``z[i, 2 c + a]`` for component ``c`` of axis ``a``), sampled
  exactly per axis, ``[p, v, a] <- F [p, v, a] + L z`` with ``L`` the Cholesky factor of the
  per-axis ``Q(tau)`` of the belief models `hptrack.models.belief_motion.SingerMotion` and
  `hptrack.models.belief_motion.ConstantAccelerationMotion` (one formula in one place); their
  parameters carry the noise (``sqrt_q`` is not used).

Beliefs and planners still assume constant velocity: these models change the truth only.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numba
import numpy as np
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.models.belief_motion import (
    ca_axis_noise,
    ca_axis_transition,
    singer_axis_noise,
    singer_axis_transition,
)
from hptrack.models.mission import motion_noise_factors_on
from hptrack.models.motion import advance_true_state

_TRUTH_MODELS: dict[type, Callable] = {}
_TRUTH_STATE_SIZES: dict[type, int] = {}


def register_truth_motion(model_class: type, advance: Callable, state_size: int = 4) -> None:
    """Make ``advance`` (a compiled kernel, module docstring) the true motion of
    ``model_class``, whose true states have ``state_size`` entries (4: ``[x, y, vx, vy]``, 6:
    with ``[ax, ay]``; the kernel takes that many unit normals per target and step)."""
    _TRUTH_MODELS[model_class] = advance
    _TRUTH_STATE_SIZES[model_class] = state_size


def truth_state_size(model: tuple) -> int:
    """The length of a true state under ``model`` (4 or 6).

    Raises:
        ValueError: ``model`` is not a registered truth motion.
    """
    if type(model) not in _TRUTH_STATE_SIZES:
        raise ValueError(f"no truth motion registered for {model!r}")
    return _TRUTH_STATE_SIZES[type(model)]


def advance_truth(model, mission, truth, z, sqrt_q):
    """The registered ``advance`` of ``model``'s class (compiled code only)."""
    raise NotImplementedError


@overload(advance_truth)
def _advance_truth(model, mission, truth, z, sqrt_q):
    return registered(_TRUTH_MODELS, model, "truth motion").py_func


class ConstantVelocityTruth(NamedTuple):
    """The paper's constant-velocity motion with the mission's process noise."""


class CoordinatedTurn(NamedTuple):
    """Constant turn rates, one per target.

    Attributes:
        rates: ``(n,)`` turn rates ``omega_i``, rad/s (counter-clockwise positive).
    """

    rates: np.ndarray


class RandomWalk(NamedTuple):
    """A diffusing position with no velocity.

    Attributes:
        diffusion: ``D``, the position variance gained per second on each axis, m^2/s.
    """

    diffusion: float


class OrnsteinUhlenbeck(NamedTuple):
    """A velocity pulled back to rest.

    Attributes:
        damping: ``K``, the rate at which the velocity decays, 1/s.
    """

    damping: float


@numba.njit(cache=True)
def advance_constant_velocity(model, mission, truth, z, sqrt_q):
    """`ConstantVelocityTruth`'s step (the simulator's true motion of the paper)."""
    l11, l21, l22 = motion_noise_factors_on(mission)
    tau = mission.time_step
    for i in range(truth.shape[0]):
        advance_true_state(truth, i, z[i], sqrt_q[i], l11, l21, l22, tau)


@numba.njit(cache=True)
def turn_step(x, y, vx, vy, omega, tau):
    """``(x, y, vx, vy)`` after ``tau`` s of a noise-free turn at ``omega`` rad/s (a straight
    line when ``omega = 0``)."""
    angle = omega * tau
    c, s = math.cos(angle), math.sin(angle)
    if abs(angle) < 1e-12:
        along, across = tau, 0.0
    else:
        along, across = s / omega, (1.0 - c) / omega
    return (
        x + along * vx - across * vy,
        y + across * vx + along * vy,
        c * vx - s * vy,
        s * vx + c * vy,
    )


@numba.njit(cache=True)
def advance_coordinated_turn(model, mission, truth, z, sqrt_q):
    """`CoordinatedTurn`'s step: the exact turn, then constant velocity's per-step noise."""
    l11, l21, l22 = motion_noise_factors_on(mission)
    tau = mission.time_step
    for i in range(truth.shape[0]):
        x, y, vx, vy = turn_step(
            truth[i, 0], truth[i, 1], truth[i, 2], truth[i, 3], model.rates[i], tau
        )
        r = sqrt_q[i]
        truth[i, 0] = x + r * (l11 * z[i, 0])
        truth[i, 1] = y + r * (l11 * z[i, 1])
        truth[i, 2] = vx + r * (l21 * z[i, 0] + l22 * z[i, 2])
        truth[i, 3] = vy + r * (l21 * z[i, 1] + l22 * z[i, 3])


@numba.njit(cache=True)
def advance_random_walk(model, mission, truth, z, sqrt_q):
    """`RandomWalk`'s step (uses the first two normals of each target)."""
    spread = math.sqrt(model.diffusion * mission.time_step)
    for i in range(truth.shape[0]):
        truth[i, 0] += spread * z[i, 0]
        truth[i, 1] += spread * z[i, 1]
        truth[i, 2] = 0.0
        truth[i, 3] = 0.0


@numba.njit(cache=True)
def ou_step_factors(damping, tau):
    """The exact one-step transition of the integrated Ornstein-Uhlenbeck velocity, per axis:
    ``(decay, gain, l11, l21, l22)`` with ``v <- decay v``, ``x <- x + gain v`` and the
    Cholesky factor of the noise covariance at ``q = 1``,
    ``[[tau - 2 g + h, g - h], [g - h, K h]] / K^2`` where ``g = (1 - e^{-K tau}) / K`` and
    ``h = (1 - e^{-2 K tau}) / (2 K)``."""
    k = damping
    decay = math.exp(-k * tau)
    g = -math.expm1(-k * tau) / k
    h = -math.expm1(-2.0 * k * tau) / (2.0 * k)
    qxx = (tau - 2.0 * g + h) / (k * k)
    qxv = (g - h) / k
    qvv = h
    l11 = math.sqrt(qxx)
    l21 = qxv / l11
    return decay, g, l11, l21, math.sqrt(max(qvv - l21 * l21, 0.0))


@numba.njit(cache=True)
def advance_ornstein_uhlenbeck(model, mission, truth, z, sqrt_q):
    """`OrnsteinUhlenbeck`'s step, exact for any ``tau``."""
    decay, gain, l11, l21, l22 = ou_step_factors(model.damping, mission.time_step)
    for i in range(truth.shape[0]):
        r = sqrt_q[i]
        vx, vy = truth[i, 2], truth[i, 3]
        truth[i, 0] += gain * vx + r * (l11 * z[i, 0])
        truth[i, 1] += gain * vy + r * (l11 * z[i, 1])
        truth[i, 2] = decay * vx + r * (l21 * z[i, 0] + l22 * z[i, 2])
        truth[i, 3] = decay * vy + r * (l21 * z[i, 1] + l22 * z[i, 3])


class SingerTruth(NamedTuple):
    """Singer's acceleration (`hptrack.models.belief_motion.SingerMotion`), 6-D true states.

    Attributes:
        damping: ``alpha``, the rate at which the acceleration decays, 1/s (> 0).
        acceleration_std: ``sigma_m``, the stationary std of each acceleration component,
            m/s^2.
    """

    damping: float
    acceleration_std: float


class ConstantAccelerationTruth(NamedTuple):
    """White jerk (`hptrack.models.belief_motion.ConstantAccelerationMotion`), 6-D true states.

    Attributes:
        jerk_intensity: ``j``, the acceleration variance gained per second on each axis,
            m^2/s^5.
        acceleration_std: the prior std of each acceleration component, m/s^2 (not used by
            the step).
    """

    jerk_intensity: float
    acceleration_std: float


@numba.njit(cache=True)
def cholesky3(noise, scale):
    """The lower Cholesky factor ``(l11, l21, l22, l31, l32, l33)`` of ``scale`` times the
    symmetric 3x3 ``noise = (q11, q12, q13, q22, q23, q33)`` (a pivot that rounds below 0
    counts as 0)."""
    q11, q12, q13, q22, q23, q33 = noise
    l11 = math.sqrt(max(q11, 0.0))
    l21 = q12 / l11 if l11 > 0.0 else 0.0
    l31 = q13 / l11 if l11 > 0.0 else 0.0
    l22 = math.sqrt(max(q22 - l21 * l21, 0.0))
    l32 = (q23 - l31 * l21) / l22 if l22 > 0.0 else 0.0
    l33 = math.sqrt(max(q33 - l31 * l31 - l32 * l32, 0.0))
    r = math.sqrt(scale)
    return r * l11, r * l21, r * l22, r * l31, r * l32, r * l33


@numba.njit(cache=True)
def advance_linear3(f, factor, truth, z):
    """``[p, v, a] <- F [p, v, a] + L z`` per axis of every 6-D state of ``truth``, with the
    per-axis upper-triangular ``F = f = (f_pp, f_pv, f_pa, f_vv, f_va, f_aa)`` and the
    Cholesky factor ``L = factor = (l11, l21, l22, l31, l32, l33)``."""
    fpp, fpv, fpa, fvv, fva, faa = f
    l11, l21, l22, l31, l32, l33 = factor
    for i in range(truth.shape[0]):
        for axis in range(2):
            p, v, a = truth[i, axis], truth[i, 2 + axis], truth[i, 4 + axis]
            z0, z1, z2 = z[i, axis], z[i, 2 + axis], z[i, 4 + axis]
            truth[i, axis] = fpp * p + fpv * v + fpa * a + l11 * z0
            truth[i, 2 + axis] = fvv * v + fva * a + l21 * z0 + l22 * z1
            truth[i, 4 + axis] = faa * a + l31 * z0 + l32 * z1 + l33 * z2


@numba.njit(cache=True)
def advance_singer(model, mission, truth, z, sqrt_q):
    """`SingerTruth`'s step, exact for any ``tau`` (``sqrt_q`` not used)."""
    tau = mission.time_step
    intensity = 2.0 * model.damping * model.acceleration_std * model.acceleration_std
    factor = cholesky3(singer_axis_noise(model.damping, tau), intensity)
    advance_linear3(singer_axis_transition(model.damping, tau), factor, truth, z)


@numba.njit(cache=True)
def advance_constant_acceleration(model, mission, truth, z, sqrt_q):
    """`ConstantAccelerationTruth`'s step, exact for any ``tau`` (``sqrt_q`` not used)."""
    tau = mission.time_step
    factor = cholesky3(ca_axis_noise(tau), model.jerk_intensity)
    advance_linear3(ca_axis_transition(tau), factor, truth, z)


register_truth_motion(ConstantVelocityTruth, advance_constant_velocity)
register_truth_motion(CoordinatedTurn, advance_coordinated_turn)
register_truth_motion(RandomWalk, advance_random_walk)
register_truth_motion(OrnsteinUhlenbeck, advance_ornstein_uhlenbeck)
register_truth_motion(SingerTruth, advance_singer, 6)
register_truth_motion(ConstantAccelerationTruth, advance_constant_acceleration, 6)


@numba.njit(cache=True)
def _advance(model, mission, truth, z, sqrt_q):
    advance_truth(model, mission, truth, z, sqrt_q)


def sample_truth(
    model: tuple,
    mission,
    states: np.ndarray,
    q: np.ndarray,
    rng: np.random.Generator,
) -> np.ndarray:
    """True states ``(n, d)`` one step of ``model`` after ``states`` (``d`` = 4, or 6 for the
    acceleration models), drawing ``(n, d)`` unit normals from ``rng`` (the numpy face of
    `advance_truth`; ``mission`` the record, ``q`` the intensities, m^2/s^3)."""
    out = np.array(states, dtype=float)
    z = rng.standard_normal(out.shape)
    _advance(model, mission, out, z, np.sqrt(np.asarray(q, dtype=float)))
    return out
