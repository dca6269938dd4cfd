"""Constant-velocity target motion with closed-form prediction over any duration (paper Sec. III,
Eq. (1)).

State ``[x, y, vx, vy]`` in m and m/s. One step of ``tau`` seconds applies
``F = [[I, tau I], [0, I]]`` and adds process noise ``Q = q [[a I, b I], [b I, c I]]``.

Two forms of ``Q`` are offered (``docs/model.md``):

* ``"continuous"`` (default): ``a, b, c = tau^3/3, tau^2/2, tau`` -- the discretised continuous
  white-noise acceleration model. After a duration ``T`` the accumulated noise is exactly
  ``q [[T^3/3, T^2/2], [T^2/2, T]]`` per axis, for any real ``T`` (not only whole steps).
* ``"paper_text"``: ``a, b, c = tau^3/3, tau^2/2, 1`` -- the form printed in the paper's Sec. V-A.

For any per-step blocks ``(a, b, c)`` the sum ``sum_{j<k} F^j Q F^j'`` is, per axis,
``q [[k a + 2 tau s1 b + tau^2 s2 c, k b + tau s1 c], [., k c]]`` with ``s1 = k(k-1)/2`` and
``s2 = k(k-1)(2k-1)/6`` (`noise_blocks`), so a prediction over any duration costs O(1).
A duration of ``T`` seconds is ``k = T / tau`` steps; fractional ``k`` is exact for the
continuous form and interpolates the printed one.

The compiled kernels are the one implementation of the prediction in the project; everything
else (the simulator, the tree search, the estimator, the baselines, the controller) calls them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np

ProcessNoiseForm = Literal["continuous", "paper_text"]


@numba.njit(cache=True, inline="always")
def noise_blocks(q: float, steps: float, tau: float, c_per_step: float) -> tuple:
    """Accumulated process noise after ``steps`` steps of ``tau`` s, per axis:
    ``(Qpp, Qpv, Qvv)``. ``c_per_step`` is the lower-right per-step block over ``q``."""
    k = steps
    s1 = k * (k - 1.0) / 2.0
    s2 = k * (k - 1.0) * (2.0 * k - 1.0) / 6.0
    a = tau**3 / 3.0
    b = tau**2 / 2.0
    qpp = q * (k * a + 2.0 * tau * s1 * b + tau * tau * s2 * c_per_step)
    qpv = q * (k * b + tau * s1 * c_per_step)
    qvv = q * k * c_per_step
    return qpp, qpv, qvv


@numba.njit(cache=True, inline="always")
def _position_block(cov, t, qpp):
    """``(sxx, sxy, syy)`` of ``F cov F'`` over ``t`` seconds plus the position noise ``qpp``."""
    sxx = cov[0, 0] + 2.0 * t * cov[0, 2] + t * t * cov[2, 2] + qpp
    syy = cov[1, 1] + 2.0 * t * cov[1, 3] + t * t * cov[3, 3] + qpp
    sxy = cov[0, 1] + t * (cov[0, 3] + cov[2, 1]) + t * t * cov[2, 3]
    return sxx, sxy, syy


@numba.njit(cache=True)
def position_covariance_after(
    cov: np.ndarray, q: float, steps: float, tau: float, c_per_step: float
) -> tuple:
    """2x2 position covariance ``(sxx, sxy, syy)`` after ``steps`` prediction steps, in m^2.

    ``cov`` is the 4x4 state covariance now. O(1) in ``steps`` (Eq. (1) in closed form).
    """
    qpp, _, _ = noise_blocks(q, steps, tau, c_per_step)
    return _position_block(cov, steps * tau, qpp)


@numba.njit(cache=True)
def predict_covariance(cov, q, steps, tau, c_per_step, out):
    """``out = F^k cov F^k' + sum_{j<k} F^j Q F^j'`` for ``k = steps`` (Eq. (1) in closed form,
    O(1) in ``k``, fractional ``k`` allowed). ``out`` may be ``cov`` (in place)."""
    t = steps * tau
    qpp, qpv, qvv = noise_blocks(q, float(steps), tau, c_per_step)
    sxx, sxy, syy = _position_block(cov, t, qpp)
    pv00 = cov[0, 2] + t * cov[2, 2] + qpv
    pv01 = cov[0, 3] + t * cov[2, 3]
    pv10 = cov[1, 2] + t * cov[3, 2]
    pv11 = cov[1, 3] + t * cov[3, 3] + qpv
    vv00 = cov[2, 2] + qvv
    vv01 = cov[2, 3]
    vv11 = cov[3, 3] + qvv
    out[0, 0] = sxx
    out[1, 1] = syy
    out[0, 1] = out[1, 0] = sxy
    out[0, 2] = out[2, 0] = pv00
    out[0, 3] = out[3, 0] = pv01
    out[1, 2] = out[2, 1] = pv10
    out[1, 3] = out[3, 1] = pv11
    out[2, 2] = vv00
    out[3, 3] = vv11
    out[2, 3] = out[3, 2] = vv01


@numba.njit(cache=True)
def position_polynomials(cov, q, tau, c_per_step):
    """`position_covariance_after` as polynomials in the step count ``k``:
    ``sxx = x0 + x1 k + x2 k^2 + x3 k^3``, ``syy`` likewise with ``y0, y1, y2, x3``,
    ``sxy = c0 + c1 k + c2 k^2`` (the estimator evaluates them by Horner's rule).

    The position noise of `noise_blocks`, ``q (k a + tau b (k^2 - k) + tau^2 c (2k^3 -
    3k^2 + k) / 6)`` (``a = tau^3/3``, ``b = tau^2/2``, ``c = c_per_step``), expanded in ``k``.
    Returns ``(x0, x1, x2, y0, y1, y2, c0, c1, c2, x3)``.
    """
    a = tau * tau * tau / 3.0
    b = tau * tau / 2.0
    c = c_per_step
    n1 = q * (a - tau * b + tau * tau * c / 6.0)
    n2 = q * (tau * b - tau * tau * c / 2.0)
    n3 = q * tau * tau * c / 3.0
    return (
        cov[0, 0],
        2.0 * tau * cov[0, 2] + n1,
        tau * tau * cov[2, 2] + n2,
        cov[1, 1],
        2.0 * tau * cov[1, 3] + n1,
        tau * tau * cov[3, 3] + n2,
        cov[0, 1],
        tau * (cov[0, 3] + cov[2, 1]),
        tau * tau * cov[2, 3],
        n3,
    )


@numba.njit(cache=True, inline="always")
def _position_blocks(poly, k):
    """``(sxx, syy, sxy)`` of ``Sigma^xy`` (m^2) after ``k`` steps from
    `position_polynomials`' ``poly``, by Horner's rule."""
    x3 = poly[9]
    sxx = poly[0] + k * (poly[1] + k * (poly[2] + k * x3))
    syy = poly[3] + k * (poly[4] + k * (poly[5] + k * x3))
    sxy = poly[6] + k * (poly[7] + k * poly[8])
    return sxx, syy, sxy


@numba.njit(cache=True, inline="always")
def position_det(poly, n):
    """``det Sigma^xy`` (m^4) after ``n`` steps from `position_polynomials`' ``poly``
    (its first ten entries)."""
    sxx, syy, sxy = _position_blocks(poly, n)
    return sxx * syy - sxy * sxy


@numba.njit(cache=True, inline="always")
def position_det_rate(poly, k):
    """``(det Sigma^xy, d det / dk)`` after ``k`` steps from `position_polynomials`'
    ``poly`` (m^4, m^4 per step)."""
    sxx, syy, sxy = _position_blocks(poly, k)
    x3 = poly[9]
    det_rate = (
        (poly[1] + k * (2.0 * poly[2] + 3.0 * k * x3)) * syy
        + sxx * (poly[4] + k * (2.0 * poly[5] + 3.0 * k * x3))
        - 2.0 * sxy * (poly[7] + 2.0 * k * poly[8])
    )
    return sxx * syy - sxy * sxy, det_rate


@numba.njit(cache=True, inline="always")
def mean_position_at(mean, elapsed):
    """``(x, y)`` of the belief mean ``[x, y, vx, vy]`` after ``elapsed`` seconds: ``p + v t``."""
    return mean[0] + mean[2] * elapsed, mean[1] + mean[3] * elapsed


@numba.njit(cache=True)
def fill_process_noise(q, steps, tau, c_per_step, out):
    """``out`` (4x4) = the accumulated process noise ``sum_{j<k} F^j Q F^j'``, ``k = steps``."""
    qpp, qpv, qvv = noise_blocks(q, float(steps), tau, c_per_step)
    for i in range(4):
        for j in range(4):
            out[i, j] = 0.0
    for i in range(2):
        out[i, i] = qpp
        out[i, 2 + i] = qpv
        out[2 + i, i] = qpv
        out[2 + i, 2 + i] = qvv


@numba.njit(cache=True)
def fill_transition(duration, out):
    """``out`` (4x4) = ``F`` over ``duration`` seconds, ``[[I, T I], [0, I]]``."""
    for i in range(4):
        for j in range(4):
            out[i, j] = 1.0 if i == j else 0.0
    out[0, 2] = duration
    out[1, 3] = duration


@numba.njit(cache=True)
def motion_noise_factors(tau, c_per_step):
    """Per-axis Cholesky factor ``[[l11, 0], [l21, l22]]`` of one step's ``Q`` at ``q = 1``."""
    a = tau**3 / 3.0
    b = tau**2 / 2.0
    l11 = math.sqrt(a)
    l21 = b / l11
    return l11, l21, math.sqrt(c_per_step - l21 * l21)


@numba.njit(cache=True, inline="always")
def advance_true_state(states, i, z, sqrt_q, l11, l21, l22, tau):
    """One step of the true motion of ``states[i]`` with unit normal draws ``z`` ordered
    ``[x, y, vx, vy]``: ``x <- F x + sqrt(q) L z`` (``L`` from `motion_noise_factors`)."""
    x, y, vx, vy = states[i, 0], states[i, 1], states[i, 2], states[i, 3]
    states[i, 0] = (x + tau * vx) + sqrt_q * (l11 * z[0])
    states[i, 1] = (y + tau * vy) + sqrt_q * (l11 * z[1])
    states[i, 2] = vx + sqrt_q * (l21 * z[0] + l22 * z[2])
    states[i, 3] = vy + sqrt_q * (l21 * z[1] + l22 * z[3])


@numba.njit(cache=True)
def _predict_stacked(means, covariances, q, steps, tau, c_per_step, out_means, out_covs):
    for i in range(means.shape[0]):
        t = steps[i] * tau
        x, y = mean_position_at(means[i], t)
        out_means[i, 0] = x
        out_means[i, 1] = y
        out_means[i, 2] = means[i, 2]
        out_means[i, 3] = means[i, 3]
        predict_covariance(covariances[i], q[i], steps[i], tau, c_per_step, out_covs[i])


@numba.njit(cache=True)
def _sample_stacked(states, z, sqrt_q, tau, c_per_step):
    l11, l21, l22 = motion_noise_factors(tau, c_per_step)
    for i in range(states.shape[0]):
        advance_true_state(states, i, z[i], sqrt_q[i], l11, l21, l22, tau)


@dataclass(frozen=True)
class ConstantVelocityModel:
    """Constant-velocity model of Eq. (1): the numpy face of the kernels above.

    Attributes:
        time_step: ``tau`` in s (the paper uses 0.5 s).
        process_noise_form: which ``Q`` to use (module docstring).
    """

    time_step: float = 0.5
    process_noise_form: ProcessNoiseForm = "continuous"

    state_size = 4
    """The length of its states ``[x, y, vx, vy]``."""

    @property
    def c_per_step(self) -> float:
        """Lower-right block of the per-step ``Q`` divided by ``q``."""
        return self.time_step if self.process_noise_form == "continuous" else 1.0

    def transition(self, duration: float | None = None) -> np.ndarray:
        """``F`` (4x4) over ``duration`` seconds (default one step)."""
        out = np.empty((4, 4))
        fill_transition(self.time_step if duration is None else float(duration), out)
        return out

    def process_noise(self, q: float, duration: float | None = None) -> np.ndarray:
        """Accumulated process noise (4x4) over ``duration`` seconds (default one step)."""
        steps = 1.0 if duration is None else float(duration) / self.time_step
        out = np.empty((4, 4))
        fill_process_noise(float(q), steps, self.time_step, self.c_per_step, out)
        return out

    def predict(
        self,
        means: np.ndarray,
        covariances: np.ndarray,
        q: np.ndarray | float,
        duration: np.ndarray | float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Predict stacked beliefs ``(n, 4)``, ``(n, 4, 4)`` over ``duration`` seconds in closed
        form (any non-negative duration, not only whole steps).

        ``q`` (m^2/s^3) and ``duration`` (s) may be scalars or one value per target.
        """
        means = np.ascontiguousarray(means, dtype=float)
        n = means.shape[0]
        q = np.ascontiguousarray(np.broadcast_to(np.asarray(q, dtype=float), (n,)))
        steps = np.ascontiguousarray(
            np.broadcast_to(np.asarray(duration, dtype=float) / self.time_step, (n,))
        )
        out_means = np.empty((n, 4))
        out_covs = np.empty((n, 4, 4))
        _predict_stacked(
            means,
            np.ascontiguousarray(covariances, dtype=float),
            q,
            steps,
            self.time_step,
            self.c_per_step,
            out_means,
            out_covs,
        )
        return out_means, out_covs

    def sample_motion(
        self, states: np.ndarray, q: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        """Propagate true states ``(n, 4)`` one step with ``w ~ N(0, Q_i)`` noise."""
        out = np.array(states, dtype=float)
        z = rng.standard_normal(out.shape)
        _sample_stacked(
            out, z, np.sqrt(np.asarray(q, dtype=float)), self.time_step, self.c_per_step
        )
        return out


def predicted_positions(means: np.ndarray, elapsed: np.ndarray | float) -> np.ndarray:
    """Open-loop positions ``p + v t`` of belief means ``(..., 4)`` after ``elapsed`` seconds
    (broadcast), m: the numpy face of `mean_position_at`."""
    means = np.asarray(means, dtype=float)
    elapsed = np.asarray(elapsed, dtype=float)
    return means[..., :2] + elapsed[..., None] * means[..., 2:]
