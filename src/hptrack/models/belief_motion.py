"""How the beliefs assume the targets move: the motion part of the mission record (paper Sec. III,
Eq. (1), and models beyond it).

A belief motion is a ``NamedTuple`` class (its fields are its parameters, SI units) registered
with `register_motion` and a `MotionKernels` record of compiled kernels; compiled code reaches
them through the functions below (`mean_position`, `predict_covariance`, ...), dispatched at
compile time on the class of the mission's ``motion`` (`hptrack.models.mission` offers each on
the record: `predict_covariance_on`, ...). Every model keeps the state ``[x, y, vx, vy]`` with
the two axes independent and alike, so one step over ``T`` seconds is, per axis,
``F(T) = [[f_pp, f_pv], [f_vp, f_vv]] = expm(A T)`` and the accumulated noise
``Q(T) = [[q_pp, q_pv], [q_pv, q_vv]]`` (Van Loan's integral, in closed form per model). The
models:

* `ConstantVelocity` (the paper's and the default): ``A = [[0, 1], [0, 0]]``, noise ``q`` on the
  velocity; its own closed forms (`hptrack.models.motion`), the estimator's polynomials in the
  step count included. ``velocity_variance_per_q`` is the velocity block of one step's ``Q``
  over ``q``: ``tau`` (the continuous form) or 1 (the paper's printed one).
* `RandomWalkMotion`: the position diffuses, ``Q(T) = [[D T, 0], [0, 0]]`` with ``D`` m^2/s,
  ``F = I`` (the velocity is carried but moves nothing; the targets' ``q`` is not used). Its
  position covariance is linear in the step count, so the estimator's polynomials hold.
* `OrnsteinUhlenbeckMotion`: the velocity decays at ``K`` 1/s while driven by ``q``,
  ``A = [[0, 1], [0, -K]]``: ``f_pv = g = (1 - e^{-KT}) / K``, ``f_vv = e^{-KT}``,
  ``Q(T) = q [[phi(KT) / K^3, g^2 / 2, ...], [., (1 - e^{-2KT}) / (2K)]]`` with
  ``phi(u) = u - 2 (1 - e^{-u}) + (1 - e^{-2u}) / 2`` (`ou_axis_noise`). Its position
  covariance is a polynomial in ``g`` plus ``q phi / K^3``, evaluated by the same entries.

The models other than constant velocity share one linear-Gaussian path (`linear_predict`),
given their per-axis ``F(T)`` and ``Q(T)``. Under random walk and Ornstein-Uhlenbeck the mean's
speed never exceeds its speed now (the intercept of `hptrack.coverage.intercept` relies on it).

Two models carry the acceleration too, the state ``[x, y, vx, vy, ax, ay]`` (m, m/s, m/s^2;
component ``c`` of axis ``a`` at ``2 c + a``), per axis ``[p, v, a]`` with
``A = [[0, 1, 0], [0, 0, 1], [0, 0, -alpha]]`` and white noise of intensity ``q`` on the
acceleration, so ``F(T) = [[1, T, f_pa], [0, 1, f_va], [0, 0, f_aa]]`` and
``d Q_ij / dT = q f_i3(T) f_j3(T)``. They share a second, 3-component path (`linear3_predict`,
`linear3_position`, `linear3_mean`, `fill_linear3_step`), and their priors grow from the
scenarios' 4-D ones by `extended_prior`:

* `SingerMotion` (Singer, 1970): ``da = -alpha a dt + dW`` with ``q = 2 alpha sigma_m^2``
  (``sigma_m`` the stationary std of the acceleration). With ``u = alpha T``,
  ``E1 = 1 - e^{-u}``, ``E2 = 1 - e^{-2u}``: ``f_pa = (u - E1) / alpha^2``,
  ``f_va = E1 / alpha``, ``f_aa = e^{-u}``; ``Q = q [[(u^3/3 - u^2 + u - 2 u e^{-u} + E2/2) /
  alpha^5, (u^2/2 - u + E1 + u e^{-u} - E2/2) / alpha^4, (E2/2 - u e^{-u}) / alpha^3],
  [., phi(u) / alpha^3, E1^2 / (2 alpha^2)], [., ., E2 / (2 alpha)]]`` (`singer_axis_noise`;
  below ``u = 1.5`` the cancelling entries are power series in ``u``). As ``alpha -> 0`` it
  becomes constant acceleration with ``j = q``.
* `ConstantAccelerationMotion` (Bar-Shalom's Wiener-process acceleration model, white jerk of
  intensity ``j``): ``alpha = 0``, ``F = [[1, T, T^2/2], [0, 1, T], [0, 0, 1]]``,
  ``Q = j [[T^5/20, T^4/8, T^3/6], [T^4/8, T^3/3, T^2/2], [T^3/6, T^2/2, T]]``.

Their position covariance is a polynomial in ``T`` and ``f_pa(T)`` plus ``Q_pp(T)``
(`accel_position_terms`, nineteen numbers).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple

import numba
import numpy as np
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.models import motion as cv
from hptrack.models.state import set_position, set_velocity


class MotionKernels(NamedTuple):
    """The compiled kernels of one belief motion (``motion`` is the part, ``tau`` the time
    step in s, ``steps`` a real number of steps):

    Attributes:
        mean_state: ``(motion, tau, mean, elapsed) -> (x, y, vx, vy)``, the predicted mean
            after ``elapsed`` s.
        predict_covariance: ``(motion, tau, cov, q, steps, out)``, ``out = F cov F' + Q``
            (``out`` may be ``cov``).
        position_covariance: ``(motion, tau, cov, q, steps) -> (sxx, sxy, syy)``.
        position_terms: ``(motion, tau, cov, q) -> poly``, numbers (ten for a 4-D state,
            nineteen for a 6-D one; entries 0, 3, 6 are ``sxx``, ``syy``, ``sxy`` now) from
            which ``position_det`` evaluates ``det Sigma^xy`` after any number of steps.
        position_det: ``(motion, tau, poly, steps) -> det``, m^4.
        position_det_rate: ``(motion, tau, poly, steps) -> (det, d det / d steps)``.
        step_matrices: ``(motion, tau, q, f, qq)``: one step's ``d x d`` ``F`` and ``Q``.
        predict_mean: ``(motion, tau, mean, elapsed, out)``, the whole predicted mean state
            after ``elapsed`` s written into ``out`` (``out`` may be ``mean``).
        straight: whether the mean moves in a straight line at its velocity (then the
            intercept and the spiral's shift have closed forms).
        state_size: ``d``, the length of a state: 4 for ``[x, y, vx, vy]``, 6 for
            ``[x, y, vx, vy, ax, ay]`` (m, m/s, m/s^2; `hptrack.models.state`).
    """

    mean_state: Callable
    predict_covariance: Callable
    position_covariance: Callable
    position_terms: Callable
    position_det: Callable
    position_det_rate: Callable
    step_matrices: Callable
    predict_mean: Callable
    straight: bool
    state_size: int


_MOTIONS: dict[type, MotionKernels] = {}


def register_motion(motion_class: type, kernels: MotionKernels) -> None:
    """Make ``kernels`` the belief motion of ``motion_class``."""
    _MOTIONS[motion_class] = kernels


def _kernel(motion, name):
    return getattr(registered(_MOTIONS, motion, "belief motion"), name).py_func


def mean_state(motion, tau, mean, elapsed):
    """The registered ``mean_state`` (compiled code only)."""
    raise NotImplementedError


def predict_covariance(motion, tau, cov, q, steps, out):
    """The registered ``predict_covariance`` (compiled code only)."""
    raise NotImplementedError


def position_covariance(motion, tau, cov, q, steps):
    """The registered ``position_covariance`` (compiled code only)."""
    raise NotImplementedError


def position_terms(motion, tau, cov, q):
    """The registered ``position_terms`` (compiled code only)."""
    raise NotImplementedError


def position_det(motion, tau, poly, steps):
    """The registered ``position_det`` (compiled code only)."""
    raise NotImplementedError


def position_det_rate(motion, tau, poly, steps):
    """The registered ``position_det_rate`` (compiled code only)."""
    raise NotImplementedError


def step_matrices(motion, tau, q, f, qq):
    """The registered ``step_matrices`` (compiled code only)."""
    raise NotImplementedError


def predict_mean(motion, tau, mean, elapsed, out):
    """The registered ``predict_mean`` (compiled code only)."""
    raise NotImplementedError


def moves_straight(motion):
    """The registered ``straight`` flag, a compile-time constant (compiled code only)."""
    raise NotImplementedError


def state_size(motion):
    """The registered ``state_size``, a compile-time constant (compiled code only)."""
    raise NotImplementedError


@overload(mean_state)
def _mean_state(motion, tau, mean, elapsed):
    return _kernel(motion, "mean_state")


@overload(predict_covariance)
def _predict_covariance(motion, tau, cov, q, steps, out):
    return _kernel(motion, "predict_covariance")


@overload(position_covariance)
def _position_covariance(motion, tau, cov, q, steps):
    return _kernel(motion, "position_covariance")


@overload(position_terms)
def _position_terms(motion, tau, cov, q):
    return _kernel(motion, "position_terms")


@overload(position_det)
def _position_det(motion, tau, poly, steps):
    return _kernel(motion, "position_det")


@overload(position_det_rate)
def _position_det_rate(motion, tau, poly, steps):
    return _kernel(motion, "position_det_rate")


@overload(step_matrices)
def _step_matrices(motion, tau, q, f, qq):
    return _kernel(motion, "step_matrices")


@overload(predict_mean)
def _predict_mean(motion, tau, mean, elapsed, out):
    return _kernel(motion, "predict_mean")


@overload(moves_straight)
def _moves_straight(motion):
    if registered(_MOTIONS, motion, "belief motion").straight:
        return lambda motion: True
    return lambda motion: False


@overload(state_size)
def _state_size(motion):
    size = registered(_MOTIONS, motion, "belief motion").state_size
    return lambda motion: size


@numba.njit(cache=True, inline="always")
def predict_mean_4(motion, tau, mean, elapsed, out):
    """``predict_mean`` of a 4-D state from its model's ``mean_state`` (the registered one)."""
    x, y, vx, vy = mean_state(motion, tau, mean, elapsed)
    set_position(out, x, y)
    set_velocity(out, vx, vy)


# --- the one linear-Gaussian path ------------------------------------------------------------
@numba.njit(cache=True, inline="always")
def linear_predict(cov, f, noise, out):
    """``out = F cov F' + Q`` for per-axis ``F = f = (f_pp, f_pv, f_vp, f_vv)`` and
    ``Q = noise = (q_pp, q_pv, q_vv)`` on ``[x, y, vx, vy]`` (``out`` may be ``cov``)."""
    fpp, fpv, fvp, fvv = f
    qpp, qpv, qvv = noise
    m = np.empty((4, 4))  # F cov
    for j in range(4):
        for axis in range(2):
            p, v = cov[axis, j], cov[2 + axis, j]
            m[axis, j] = fpp * p + fpv * v
            m[2 + axis, j] = fvp * p + fvv * v
    for i in range(4):
        for axis in range(2):
            p, v = m[i, axis], m[i, 2 + axis]
            out[i, axis] = p * fpp + v * fpv
            out[i, 2 + axis] = p * fvp + v * fvv
    for axis in range(2):
        out[axis, axis] += qpp
        out[axis, 2 + axis] += qpv
        out[2 + axis, axis] += qpv
        out[2 + axis, 2 + axis] += qvv


@numba.njit(cache=True, inline="always")
def linear_position(cov, f, noise):
    """``(sxx, sxy, syy)`` of `linear_predict`'s position block, without the 4x4."""
    fpp, fpv = f[0], f[1]
    qpp = noise[0]
    sxx = fpp * fpp * cov[0, 0] + 2.0 * fpp * fpv * cov[0, 2] + fpv * fpv * cov[2, 2] + qpp
    syy = fpp * fpp * cov[1, 1] + 2.0 * fpp * fpv * cov[1, 3] + fpv * fpv * cov[3, 3] + qpp
    sxy = fpp * fpp * cov[0, 1] + fpp * fpv * (cov[0, 3] + cov[2, 1]) + fpv * fpv * cov[2, 3]
    return sxx, sxy, syy


@numba.njit(cache=True, inline="always")
def linear_mean(mean, f):
    """The mean ``[x, y, vx, vy]`` moved by the per-axis ``F``."""
    fpp, fpv, fvp, fvv = f
    return (
        fpp * mean[0] + fpv * mean[2],
        fpp * mean[1] + fpv * mean[3],
        fvp * mean[0] + fvv * mean[2],
        fvp * mean[1] + fvv * mean[3],
    )


@numba.njit(cache=True, inline="always")
def fill_linear_step(f, noise, f_out, q_out):
    """4x4 ``F`` and ``Q`` from their per-axis blocks."""
    for i in range(4):
        for j in range(4):
            f_out[i, j] = 0.0
            q_out[i, j] = 0.0
    for axis in range(2):
        p, v = axis, 2 + axis
        f_out[p, p] = f[0]
        f_out[p, v] = f[1]
        f_out[v, p] = f[2]
        f_out[v, v] = f[3]
        q_out[p, p] = noise[0]
        q_out[p, v] = q_out[v, p] = noise[1]
        q_out[v, v] = noise[2]


# --- constant velocity: the paper's closed forms ---------------------------------------------
class ConstantVelocity(NamedTuple):
    """The paper's constant velocity (Eq. (1)).

    Attributes:
        velocity_variance_per_q: the velocity block of one step's ``Q`` over ``q``, s (``tau``,
            the continuous form) or 1 (the paper's printed form, `hptrack.models.motion`).
    """

    velocity_variance_per_q: float


@numba.njit(cache=True, inline="always")
def _cv_mean(motion, tau, mean, elapsed):
    x, y = cv.mean_position_at(mean, elapsed)
    return x, y, mean[2], mean[3]


@numba.njit(cache=True, inline="always")
def _cv_predict(motion, tau, cov, q, steps, out):
    cv.predict_covariance(cov, q, steps, tau, motion.velocity_variance_per_q, out)


@numba.njit(cache=True, inline="always")
def _cv_position(motion, tau, cov, q, steps):
    return cv.position_covariance_after(cov, q, steps, tau, motion.velocity_variance_per_q)


@numba.njit(cache=True, inline="always")
def _cv_terms(motion, tau, cov, q):
    return cv.position_polynomials(cov, q, tau, motion.velocity_variance_per_q)


@numba.njit(cache=True, inline="always")
def _polynomial_det(motion, tau, poly, steps):
    return cv.position_det(poly, steps)


@numba.njit(cache=True, inline="always")
def _polynomial_det_rate(motion, tau, poly, steps):
    return cv.position_det_rate(poly, steps)


@numba.njit(cache=True, inline="always")
def _cv_step(motion, tau, q, f, qq):
    cv.fill_transition(tau, f)
    cv.fill_process_noise(q, 1.0, tau, motion.velocity_variance_per_q, qq)


register_motion(
    ConstantVelocity,
    MotionKernels(
        _cv_mean,
        _cv_predict,
        _cv_position,
        _cv_terms,
        _polynomial_det,
        _polynomial_det_rate,
        _cv_step,
        predict_mean_4,
        True,
        4,
    ),
)


# --- random walk -------------------------------------------------------------------------------
class RandomWalkMotion(NamedTuple):
    """A diffusing position (the targets' ``q`` is not used).

    Attributes:
        diffusion: ``D``, the position variance gained per second on each axis, m^2/s.
    """

    diffusion: float


_STILL = (1.0, 0.0, 0.0, 1.0)


@numba.njit(cache=True, inline="always")
def _rw_noise(motion, duration):
    return motion.diffusion * duration, 0.0, 0.0


@numba.njit(cache=True, inline="always")
def _rw_mean(motion, tau, mean, elapsed):
    return linear_mean(mean, _STILL)


@numba.njit(cache=True, inline="always")
def _rw_predict(motion, tau, cov, q, steps, out):
    linear_predict(cov, _STILL, _rw_noise(motion, steps * tau), out)


@numba.njit(cache=True, inline="always")
def _rw_position(motion, tau, cov, q, steps):
    return linear_position(cov, _STILL, _rw_noise(motion, steps * tau))


@numba.njit(cache=True, inline="always")
def _rw_terms(motion, tau, cov, q):
    """The position covariance as `hptrack.models.motion.position_polynomials`' polynomials
    in the step count: ``Sigma^xy(k) = Sigma^xy + D tau k I``."""
    rate = motion.diffusion * tau
    return (cov[0, 0], rate, 0.0, cov[1, 1], rate, 0.0, cov[0, 1], 0.0, 0.0, 0.0)


@numba.njit(cache=True, inline="always")
def _rw_step(motion, tau, q, f, qq):
    fill_linear_step(_STILL, _rw_noise(motion, tau), f, qq)


register_motion(
    RandomWalkMotion,
    MotionKernels(
        _rw_mean,
        _rw_predict,
        _rw_position,
        _rw_terms,
        _polynomial_det,
        _polynomial_det_rate,
        _rw_step,
        predict_mean_4,
        False,
        4,
    ),
)


# --- Ornstein-Uhlenbeck velocity -------------------------------------------------------------
class OrnsteinUhlenbeckMotion(NamedTuple):
    """A velocity pulled back to rest while driven by the targets' ``q``.

    Attributes:
        damping: ``K``, the rate at which the velocity decays, 1/s.
    """

    damping: float


SERIES_BELOW = 0.5
"""``K T`` below which `ou_axis_noise` sums ``phi``'s series (its closed form cancels)."""
SERIES_TERMS = 24
"""Terms of that series (the last is below 1e-20 of the first)."""


@numba.njit(cache=True)
def ou_phi(u):
    """``phi(u) = u - 2 (1 - e^{-u}) + (1 - e^{-2u}) / 2 = sum_{n >= 3} (-1)^n (2 - 2^{n-1})
    u^n / n!`` (summed for small ``u``, where the closed form loses its digits)."""
    if u >= SERIES_BELOW:
        return u + 2.0 * math.expm1(-u) - 0.5 * math.expm1(-2.0 * u)
    total = 0.0
    power = u * u / 2.0  # u^n / n! at n = 2
    sign = 1.0
    for n in range(3, SERIES_TERMS + 3):
        power *= u / n
        sign = -sign
        total += sign * (2.0 - 2.0 ** (n - 1)) * power
    return total


@numba.njit(cache=True, inline="always")
def ou_axis_transition(damping, duration):
    """Per-axis ``F(T) = (1, g, 0, e^{-KT})`` with ``g = (1 - e^{-KT}) / K``."""
    a = -math.expm1(-damping * duration)
    return 1.0, a / damping, 0.0, 1.0 - a


@numba.njit(cache=True, inline="always")
def ou_axis_noise(damping, duration):
    """Per-axis ``Q(T)`` at ``q = 1``: ``(phi(KT) / K^3, g^2 / 2, (1 - e^{-2KT}) / (2K))``
    (the Van Loan integral of ``A = [[0, 1], [0, -K]]``, ``g = (1 - e^{-KT}) / K``)."""
    k = damping
    u = k * duration
    g = -math.expm1(-u) / k
    return ou_phi(u) / (k * k * k), 0.5 * g * g, -math.expm1(-2.0 * u) / (2.0 * k)


@numba.njit(cache=True, inline="always")
def _ou_scaled(motion, q, duration):
    pp, pv, vv = ou_axis_noise(motion.damping, duration)
    return q * pp, q * pv, q * vv


@numba.njit(cache=True, inline="always")
def _ou_mean(motion, tau, mean, elapsed):
    return linear_mean(mean, ou_axis_transition(motion.damping, elapsed))


@numba.njit(cache=True, inline="always")
def _ou_predict(motion, tau, cov, q, steps, out):
    t = steps * tau
    linear_predict(cov, ou_axis_transition(motion.damping, t), _ou_scaled(motion, q, t), out)


@numba.njit(cache=True, inline="always")
def _ou_position(motion, tau, cov, q, steps):
    t = steps * tau
    return linear_position(cov, ou_axis_transition(motion.damping, t), _ou_scaled(motion, q, t))


@numba.njit(cache=True, inline="always")
def _ou_terms(motion, tau, cov, q):
    """``(x0, x1, x2, y0, y1, y2, c0, c1, c2, q)``: ``sxx = x0 + x1 g + x2 g^2 + q phi /
    K^3`` (``syy``, ``sxy`` likewise, without the noise in ``sxy``)."""
    return (
        cov[0, 0],
        2.0 * cov[0, 2],
        cov[2, 2],
        cov[1, 1],
        2.0 * cov[1, 3],
        cov[3, 3],
        cov[0, 1],
        cov[0, 3] + cov[2, 1],
        cov[2, 3],
        q,
    )


@numba.njit(cache=True, inline="always")
def _ou_det_rate(motion, tau, poly, steps):
    k = motion.damping
    t = steps * tau
    decay = math.exp(-k * t)
    g = -math.expm1(-k * t) / k
    noise = poly[9] * ou_phi(k * t) / (k * k * k)
    sxx = poly[0] + g * (poly[1] + g * poly[2]) + noise
    syy = poly[3] + g * (poly[4] + g * poly[5]) + noise
    sxy = poly[6] + g * (poly[7] + g * poly[8])
    noise_rate = poly[9] * g * g  # d (q phi / K^3) / dt
    dxx = tau * ((poly[1] + 2.0 * g * poly[2]) * decay + noise_rate)
    dyy = tau * ((poly[4] + 2.0 * g * poly[5]) * decay + noise_rate)
    dxy = tau * (poly[7] + 2.0 * g * poly[8]) * decay
    return sxx * syy - sxy * sxy, dxx * syy + sxx * dyy - 2.0 * sxy * dxy


@numba.njit(cache=True, inline="always")
def _ou_det(motion, tau, poly, steps):
    det, _ = _ou_det_rate(motion, tau, poly, steps)
    return det


@numba.njit(cache=True, inline="always")
def _ou_step(motion, tau, q, f, qq):
    fill_linear_step(ou_axis_transition(motion.damping, tau), _ou_scaled(motion, q, tau), f, qq)


register_motion(
    OrnsteinUhlenbeckMotion,
    MotionKernels(
        _ou_mean,
        _ou_predict,
        _ou_position,
        _ou_terms,
        _ou_det,
        _ou_det_rate,
        _ou_step,
        predict_mean_4,
        False,
        4,
    ),
)


# --- the 3-component linear path: [x, y, vx, vy, ax, ay] ---------------------------------------
@numba.njit(cache=True, inline="always")
def linear3_predict(cov, f, noise, out):
    """``out = F cov F' + Q`` on ``[x, y, vx, vy, ax, ay]`` for the per-axis upper-triangular
    ``F = f = (f_pp, f_pv, f_pa, f_vv, f_va, f_aa)`` and symmetric
    ``Q = noise = (q_pp, q_pv, q_pa, q_vv, q_va, q_aa)`` (``out`` may be ``cov``)."""
    fpp, fpv, fpa, fvv, fva, faa = f
    # out = F cov, column by column: each axis' three entries of a column read before written
    for j in range(6):
        for axis in range(2):
            p, v, a = cov[axis, j], cov[2 + axis, j], cov[4 + axis, j]
            out[axis, j] = fpp * p + fpv * v + fpa * a
            out[2 + axis, j] = fvv * v + fva * a
            out[4 + axis, j] = faa * a
    # out = out F', row by row, in place likewise (no scratch)
    for i in range(6):
        for axis in range(2):
            p, v, a = out[i, axis], out[i, 2 + axis], out[i, 4 + axis]
            out[i, axis] = p * fpp + v * fpv + a * fpa
            out[i, 2 + axis] = v * fvv + a * fva
            out[i, 4 + axis] = a * faa
    for axis in range(2):
        for r in range(3):
            for c in range(3):
                out[2 * r + axis, 2 * c + axis] += noise[_SYMMETRIC[r][c]]


_SYMMETRIC = ((0, 1, 2), (1, 3, 4), (2, 4, 5))
"""Where entry ``(r, c)`` of a symmetric 3x3 lies in ``(q_pp, q_pv, q_pa, q_vv, q_va, q_aa)``."""


@numba.njit(cache=True, inline="always")
def _row_cov_row(cov, fp, fv, fa, ax, ay):
    """``r_ax cov r_ay'`` with ``r = (fp, fv, fa)`` on the rows of axis ``ax`` and the columns
    of axis ``ay``."""
    return (
        fp * (fp * cov[ax, ay] + fv * cov[ax, 2 + ay] + fa * cov[ax, 4 + ay])
        + fv * (fp * cov[2 + ax, ay] + fv * cov[2 + ax, 2 + ay] + fa * cov[2 + ax, 4 + ay])
        + fa * (fp * cov[4 + ax, ay] + fv * cov[4 + ax, 2 + ay] + fa * cov[4 + ax, 4 + ay])
    )


@numba.njit(cache=True, inline="always")
def linear3_position(cov, f, noise):
    """``(sxx, sxy, syy)`` of `linear3_predict`'s position block, without the 6x6."""
    fp, fv, fa = f[0], f[1], f[2]
    sxx = _row_cov_row(cov, fp, fv, fa, 0, 0) + noise[0]
    sxy = _row_cov_row(cov, fp, fv, fa, 0, 1)
    syy = _row_cov_row(cov, fp, fv, fa, 1, 1) + noise[0]
    return sxx, sxy, syy


@numba.njit(cache=True, inline="always")
def linear3_mean(mean, f):
    """The mean ``[x, y, vx, vy, ax, ay]`` moved by the per-axis ``F`` (a 6-tuple)."""
    fpp, fpv, fpa, fvv, fva, faa = f
    return (
        fpp * mean[0] + fpv * mean[2] + fpa * mean[4],
        fpp * mean[1] + fpv * mean[3] + fpa * mean[5],
        fvv * mean[2] + fva * mean[4],
        fvv * mean[3] + fva * mean[5],
        faa * mean[4],
        faa * mean[5],
    )


@numba.njit(cache=True, inline="always")
def fill_linear3_step(f, noise, f_out, q_out):
    """6x6 ``F`` and ``Q`` from their per-axis blocks (`linear3_predict`'s tuples)."""
    for i in range(6):
        for j in range(6):
            f_out[i, j] = 0.0
            q_out[i, j] = 0.0
    for axis in range(2):
        for r in range(3):
            for c in range(3):
                q_out[2 * r + axis, 2 * c + axis] = noise[_SYMMETRIC[r][c]]
                if c >= r:
                    f_out[2 * r + axis, 2 * c + axis] = f[_SYMMETRIC[r][c]]


@numba.njit(cache=True, inline="always")
def accel_position_terms(cov, intensity):
    """The position covariance after ``T`` s under a model with ``f_pp = 1``, ``f_pv = T``
    (both of the acceleration models) as nineteen numbers
    ``(x0, x1, x2, y0, y1, y2, c0, c1, c2, q, x3, x4, x5, y3, y4, y5, c3, c4, c5)``:
    ``sxx = x0 + x1 T + x2 T^2 + f_pa (x3 + x4 T + x5 f_pa) + q Q_pp(T)`` at unit intensity
    (``syy`` likewise, ``sxy`` from the ``c`` without the noise); ``x0``, ``y0``, ``c0`` are
    the covariance now and ``q`` the model's intensity, as in the ten terms of the 4-D
    models."""
    return (
        cov[0, 0],
        2.0 * cov[0, 2],
        cov[2, 2],
        cov[1, 1],
        2.0 * cov[1, 3],
        cov[3, 3],
        cov[0, 1],
        cov[0, 3] + cov[2, 1],
        cov[2, 3],
        intensity,
        2.0 * cov[0, 4],
        2.0 * cov[2, 4],
        cov[4, 4],
        2.0 * cov[1, 5],
        2.0 * cov[3, 5],
        cov[5, 5],
        cov[0, 5] + cov[4, 1],
        cov[2, 5] + cov[4, 3],
        cov[4, 5],
    )


@numba.njit(cache=True, inline="always")
def accel_det_rate(poly, tau, t, fpa, fva, noise_pp):
    """``(det Sigma^xy, d det / d steps)`` from `accel_position_terms`' ``poly`` at ``T = t``
    with ``f_pa(t)``, its rate ``f_va(t)`` and the unit-intensity ``Q_pp(t)`` (whose rate is
    ``f_pa^2``)."""
    q = poly[9]
    sxx = poly[0] + t * (poly[1] + t * poly[2]) + fpa * (poly[10] + t * poly[11] + fpa * poly[12])
    syy = poly[3] + t * (poly[4] + t * poly[5]) + fpa * (poly[13] + t * poly[14] + fpa * poly[15])
    sxy = poly[6] + t * (poly[7] + t * poly[8]) + fpa * (poly[16] + t * poly[17] + fpa * poly[18])
    sxx += q * noise_pp
    syy += q * noise_pp
    noise_rate = q * fpa * fpa
    dxx = (
        poly[1]
        + 2.0 * t * poly[2]
        + fva * (poly[10] + t * poly[11] + 2.0 * fpa * poly[12])
        + fpa * poly[11]
        + noise_rate
    )
    dyy = (
        poly[4]
        + 2.0 * t * poly[5]
        + fva * (poly[13] + t * poly[14] + 2.0 * fpa * poly[15])
        + fpa * poly[14]
        + noise_rate
    )
    dxy = (
        poly[7]
        + 2.0 * t * poly[8]
        + fva * (poly[16] + t * poly[17] + 2.0 * fpa * poly[18])
        + fpa * poly[17]
    )
    det = sxx * syy - sxy * sxy
    return det, tau * (dxx * syy + sxx * dyy - 2.0 * sxy * dxy)


@numba.njit(cache=True, inline="always")
def _predict_mean_6(f, mean, out):
    x, y, vx, vy, ax, ay = linear3_mean(mean, f)  # read all before writing: out may be mean
    out[0] = x
    out[1] = y
    out[2] = vx
    out[3] = vy
    out[4] = ax
    out[5] = ay


# --- Singer acceleration -------------------------------------------------------------------------
class SingerMotion(NamedTuple):
    """Singer's (1970) acceleration, pulled back to zero at ``alpha`` while driven by white noise
    of intensity ``2 alpha sigma_m^2`` per axis (the targets' ``q`` is not used); state
    ``[x, y, vx, vy, ax, ay]``. The mean's acceleration decays, so its speed stays bounded: its
    velocity ``v + a (1 - e^{-alpha t}) / alpha`` runs along the segment from ``v`` to
    ``v + a / alpha`` (of the mean now), so its speed is at most ``max(|v|, |v + a / alpha|)``
    (which can exceed ``|v|``: the intercept's single-root assumption may not hold).

    Attributes:
        damping: ``alpha``, the rate at which the acceleration decays, 1/s (> 0).
        acceleration_std: ``sigma_m``, the stationary std of each acceleration component,
            m/s^2.
    """

    damping: float
    acceleration_std: float


SINGER_SERIES_BELOW = 1.5
"""``alpha T`` below which `singer_axis_transition` and `singer_axis_noise` sum power series in
``alpha T`` for the entries whose closed forms cancel (``f_pa``, ``Q_pp``, ``Q_pv``, ``Q_pa``,
``Q_vv``)."""
SINGER_SERIES_BANDS = (0.01, 0.1, 0.5, SINGER_SERIES_BELOW)
"""Upper ends of the bands of ``alpha T`` that sum their own number of terms
(`SINGER_SERIES_TERMS`)."""
_SERIES_TOP = 40


def _singer_series() -> tuple[np.ndarray, tuple[int, ...]]:
    """Rows: the coefficients of ``f_pa / T^2``, ``Q_pp / T^5``, ``Q_pv / T^4``, ``Q_pa / T^3``,
    ``Q_vv / T^3`` (unit intensity) in powers of ``u = alpha T``, exact fractions (integer sums
    over factorials) rounded once:
    ``Q_ij = int_0^T f_i3 f_j3 ds`` with ``alpha^{3-i} f_i3 = (u - 1 + e^{-u}, 1 - e^{-u},
    e^{-u})`` at ``u = alpha s``; and per band of `SINGER_SERIES_BANDS` the terms after which
    every row's tail (in absolute values, at the band's top) is below 2^-60 of its sum."""
    top = _SERIES_TOP

    def sign(i, k):  # the u^k coefficient of alpha^{3-i} f_i3 is sign(i, k) / k!
        if (i == 1 and k < 2) or (i == 2 and k < 1):
            return 0
        return -((-1) ** k) if i == 2 else (-1) ** k

    rows = [[Fraction(sign(1, k + 2), math.factorial(k + 2)) for k in range(top)]]
    for i, j, power in ((1, 1, 5), (1, 2, 4), (1, 3, 3), (2, 2, 3)):
        # the w^m coefficient of f_i3 f_j3 is sum_k sign sign binom(m, k) / m!, and
        # int_0^u w^m dw = u^{m+1} / (m + 1); the lowest power is u^power
        rows.append(
            [
                Fraction(
                    sum(sign(i, k) * sign(j, m - k) * math.comb(m, k) for k in range(m + 1)),
                    math.factorial(m + 1),
                )
                for m in range(power - 1, power - 1 + top)
            ]
        )
    table = np.array([[float(c) for c in row] for row in rows])
    lengths = []
    for band in SINGER_SERIES_BANDS:
        terms = np.abs(table) * band ** np.arange(top)
        total = (table * band ** np.arange(top)).sum(axis=1)
        tails = np.cumsum(terms[:, ::-1], axis=1)[:, ::-1]  # tails[r, n] = sum_{m >= n}
        lengths.append(int(np.argmax(np.all(tails <= total[:, None] / 2.0**60, axis=0))))
    return table, tuple(lengths)


_SINGER_SERIES, SINGER_SERIES_TERMS = _singer_series()
# SINGER_SERIES_TERMS: the terms summed in each band of SINGER_SERIES_BANDS (8, 12, 18, 28)


@numba.njit(cache=True, inline="always")
def _series_terms(u):
    """The terms `_series` sums at ``u`` (its band's)."""
    for band in range(3):
        if u < SINGER_SERIES_BANDS[band]:
            return SINGER_SERIES_TERMS[band]
    return SINGER_SERIES_TERMS[3]


@numba.njit(cache=True, inline="always")
def _series(row, u, terms):
    total = 0.0
    for k in range(terms - 1, -1, -1):
        total = total * u + _SINGER_SERIES[row, k]
    return total


@numba.njit(cache=True)
def singer_axis_transition(damping, duration):
    """Per-axis ``F(T) = (1, T, f_pa, 1, f_va, f_aa)`` with ``u = alpha T``:
    ``f_pa = (u - 1 + e^{-u}) / alpha^2``, ``f_va = (1 - e^{-u}) / alpha``, ``f_aa = e^{-u}``."""
    t = duration
    u = damping * t
    e1 = -math.expm1(-u)
    if u < SINGER_SERIES_BELOW:
        fpa = t * t * _series(0, u, _series_terms(u))
    else:
        fpa = (u - e1) / (damping * damping)
    return 1.0, t, fpa, 1.0, e1 / damping, math.exp(-u)


@numba.njit(cache=True)
def singer_axis_noise(damping, duration):
    """Per-axis ``Q(T)`` at unit intensity, ``(q_pp, q_pv, q_pa, q_vv, q_va, q_aa)`` (module
    docstring; power series in ``u = alpha T`` below `SINGER_SERIES_BELOW` for the first
    four)."""
    a = damping
    t = duration
    u = a * t
    e1 = -math.expm1(-u)
    e2 = -math.expm1(-2.0 * u)
    qva = e1 * e1 / (2.0 * a * a)
    qaa = e2 / (2.0 * a)
    if u < SINGER_SERIES_BELOW:
        n = _series_terms(u)
        t3 = t * t * t
        qpp = t3 * t * t * _series(1, u, n)
        qpv = t3 * t * _series(2, u, n)
        return qpp, qpv, t3 * _series(3, u, n), t3 * _series(4, u, n), qva, qaa
    qvv = ou_phi(u) / (a * a * a)
    ue = u * math.exp(-u)
    a2 = a * a
    qpp = (u * u * u / 3.0 - u * u + u - 2.0 * ue + 0.5 * e2) / (a2 * a2 * a)
    qpv = (0.5 * u * u - u + e1 + ue - 0.5 * e2) / (a2 * a2)
    qpa = (0.5 * e2 - ue) / (a2 * a)
    return qpp, qpv, qpa, qvv, qva, qaa


@numba.njit(cache=True, inline="always")
def singer_intensity(motion):
    """``q = 2 alpha sigma_m^2``, the white-noise intensity on each acceleration, m^2/s^5."""
    return 2.0 * motion.damping * motion.acceleration_std * motion.acceleration_std


@numba.njit(cache=True, inline="always")
def _singer_axis(motion, duration):
    f = singer_axis_transition(motion.damping, duration)
    q = singer_intensity(motion)
    pp, pv, pa, vv, va, aa = singer_axis_noise(motion.damping, duration)
    return f, (q * pp, q * pv, q * pa, q * vv, q * va, q * aa)


@numba.njit(cache=True, inline="always")
def _singer_mean(motion, tau, mean, elapsed):
    x, y, vx, vy, _, _ = linear3_mean(mean, singer_axis_transition(motion.damping, elapsed))
    return x, y, vx, vy


@numba.njit(cache=True, inline="always")
def _singer_predict_mean(motion, tau, mean, elapsed, out):
    _predict_mean_6(singer_axis_transition(motion.damping, elapsed), mean, out)


@numba.njit(cache=True, inline="always")
def _singer_predict(motion, tau, cov, q, steps, out):
    f, noise = _singer_axis(motion, steps * tau)
    linear3_predict(cov, f, noise, out)


@numba.njit(cache=True, inline="always")
def _singer_position(motion, tau, cov, q, steps):
    f, noise = _singer_axis(motion, steps * tau)
    return linear3_position(cov, f, noise)


@numba.njit(cache=True, inline="always")
def _singer_terms(motion, tau, cov, q):
    return accel_position_terms(cov, singer_intensity(motion))


@numba.njit(cache=True, inline="always")
def _singer_det_rate(motion, tau, poly, steps):
    t = steps * tau
    f = singer_axis_transition(motion.damping, t)
    noise_pp = singer_axis_noise(motion.damping, t)[0]
    return accel_det_rate(poly, tau, t, f[2], f[4], noise_pp)


@numba.njit(cache=True, inline="always")
def _singer_det(motion, tau, poly, steps):
    det, _ = _singer_det_rate(motion, tau, poly, steps)
    return det


@numba.njit(cache=True, inline="always")
def _singer_step(motion, tau, q, f, qq):
    per_axis, noise = _singer_axis(motion, tau)
    fill_linear3_step(per_axis, noise, f, qq)


register_motion(
    SingerMotion,
    MotionKernels(
        _singer_mean,
        _singer_predict,
        _singer_position,
        _singer_terms,
        _singer_det,
        _singer_det_rate,
        _singer_step,
        _singer_predict_mean,
        False,
        6,
    ),
)


# --- constant acceleration (white jerk) ----------------------------------------------------------
class ConstantAccelerationMotion(NamedTuple):
    """Bar-Shalom's constant-acceleration (Wiener-process acceleration) model: white jerk of
    intensity ``j`` per axis (the targets' ``q`` is not used); state ``[x, y, vx, vy, ax, ay]``.
    The mean keeps its acceleration, so its speed grows without bound.

    Attributes:
        jerk_intensity: ``j``, the acceleration variance gained per second on each axis,
            m^2/s^5.
        acceleration_std: the prior std of each acceleration component, m/s^2 (used only by
            `extended_prior`).
    """

    jerk_intensity: float
    acceleration_std: float


@numba.njit(cache=True)
def ca_axis_transition(duration):
    """Per-axis ``F(T) = (1, T, T^2 / 2, 1, T, 1)``."""
    t = duration
    return 1.0, t, 0.5 * t * t, 1.0, t, 1.0


@numba.njit(cache=True)
def ca_axis_noise(duration):
    """Per-axis ``Q(T)`` at unit intensity: ``(T^5/20, T^4/8, T^3/6, T^3/3, T^2/2, T)``."""
    t = duration
    t2 = t * t
    t3 = t2 * t
    return t3 * t2 / 20.0, t2 * t2 / 8.0, t3 / 6.0, t3 / 3.0, 0.5 * t2, t


@numba.njit(cache=True, inline="always")
def _ca_axis(motion, duration):
    j = motion.jerk_intensity
    pp, pv, pa, vv, va, aa = ca_axis_noise(duration)
    return ca_axis_transition(duration), (j * pp, j * pv, j * pa, j * vv, j * va, j * aa)


@numba.njit(cache=True, inline="always")
def _ca_mean(motion, tau, mean, elapsed):
    x, y, vx, vy, _, _ = linear3_mean(mean, ca_axis_transition(elapsed))
    return x, y, vx, vy


@numba.njit(cache=True, inline="always")
def _ca_predict_mean(motion, tau, mean, elapsed, out):
    _predict_mean_6(ca_axis_transition(elapsed), mean, out)


@numba.njit(cache=True, inline="always")
def _ca_predict(motion, tau, cov, q, steps, out):
    f, noise = _ca_axis(motion, steps * tau)
    linear3_predict(cov, f, noise, out)


@numba.njit(cache=True, inline="always")
def _ca_position(motion, tau, cov, q, steps):
    f, noise = _ca_axis(motion, steps * tau)
    return linear3_position(cov, f, noise)


@numba.njit(cache=True, inline="always")
def _ca_terms(motion, tau, cov, q):
    return accel_position_terms(cov, motion.jerk_intensity)


@numba.njit(cache=True, inline="always")
def _ca_det_rate(motion, tau, poly, steps):
    t = steps * tau
    return accel_det_rate(poly, tau, t, 0.5 * t * t, t, ca_axis_noise(t)[0])


@numba.njit(cache=True, inline="always")
def _ca_det(motion, tau, poly, steps):
    det, _ = _ca_det_rate(motion, tau, poly, steps)
    return det


@numba.njit(cache=True, inline="always")
def _ca_step(motion, tau, q, f, qq):
    per_axis, noise = _ca_axis(motion, tau)
    fill_linear3_step(per_axis, noise, f, qq)


register_motion(
    ConstantAccelerationMotion,
    MotionKernels(
        _ca_mean,
        _ca_predict,
        _ca_position,
        _ca_terms,
        _ca_det,
        _ca_det_rate,
        _ca_step,
        _ca_predict_mean,
        False,
        6,
    ),
)


# --- the numpy face ----------------------------------------------------------------------------
@numba.njit(cache=True)
def _predict_stacked(motion, tau, means, covariances, q, steps, out_means, out_covs):
    for i in range(means.shape[0]):
        predict_mean(motion, tau, means[i], steps[i] * tau, out_means[i])
        predict_covariance(motion, tau, covariances[i], q[i], steps[i], out_covs[i])


@numba.njit(cache=True)
def _mean_path(motion, tau, mean, elapsed, out):
    for j in range(elapsed.shape[0]):
        x, y, _, _ = mean_state(motion, tau, mean, elapsed[j])
        out[j, 0] = x
        out[j, 1] = y


@dataclass(frozen=True)
class BeliefMotion:
    """The numpy face of a belief motion part (module docstring).

    Attributes:
        time_step: ``tau``, s.
        part: the registered motion (`ConstantVelocity`, ...).
    """

    time_step: float
    part: tuple

    def predict(
        self,
        means: np.ndarray,
        covariances: np.ndarray,
        q: np.ndarray | float,
        duration: np.ndarray | float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Predict stacked beliefs ``(n, d)``, ``(n, d, d)`` over ``duration`` seconds (any
        non-negative duration); ``q`` (m^2/s^3) and ``duration`` scalars or one per target."""
        means = np.ascontiguousarray(means, dtype=float)
        n = means.shape[0]
        q = np.ascontiguousarray(np.broadcast_to(np.asarray(q, dtype=float), (n,)))
        steps = np.ascontiguousarray(
            np.broadcast_to(np.asarray(duration, dtype=float) / self.time_step, (n,))
        )
        d = self.state_size
        out_means = np.empty((n, d))
        out_covs = np.empty((n, d, d))
        _predict_stacked(
            self.part,
            self.time_step,
            means,
            np.ascontiguousarray(covariances, dtype=float),
            q,
            steps,
            out_means,
            out_covs,
        )
        return out_means, out_covs

    def mean_positions(self, mean: np.ndarray, elapsed: np.ndarray | list[float]) -> np.ndarray:
        """Positions ``(len(elapsed), 2)`` of one belief mean ``(d,)`` after each of
        ``elapsed`` seconds, m."""
        elapsed = np.ascontiguousarray(elapsed, dtype=float).reshape(-1)
        out = np.empty((elapsed.shape[0], 2))
        _mean_path(self.part, self.time_step, np.asarray(mean, dtype=float), elapsed, out)
        return out

    @property
    def straight(self) -> bool:
        """Whether the mean moves in a straight line at its velocity."""
        return registered_motion(self.part).straight

    @property
    def state_size(self) -> int:
        """``d``, the length of a state under this motion (4 or 6)."""
        return registered_motion(self.part).state_size


def registered_motion(part: tuple) -> MotionKernels:
    """The kernels registered for ``part``'s class.

    Raises:
        ValueError: ``part`` is not a registered belief motion.
    """
    if type(part) not in _MOTIONS:
        raise ValueError(f"no belief motion registered for {part!r}")
    return _MOTIONS[type(part)]


def extended_prior(part: tuple, mean: np.ndarray, covariance: np.ndarray):
    """A prior ``(mean, covariance)`` for a state of ``part``'s size: unchanged (the same
    objects) under a 4-D model; under a 6-D one (`SingerMotion`, `ConstantAccelerationMotion`)
    a 4-D prior ``[x, y, vx, vy]`` gains a zero mean acceleration and the block
    ``acceleration_std^2 I`` (m^2/s^4), uncorrelated with the position and velocity.

    Raises:
        ValueError: ``part`` is not a registered belief motion.
    """
    size = registered_motion(part).state_size
    mean_in = np.asarray(mean, dtype=float)
    if size == 4 or mean_in.shape[-1] == size:
        return mean, covariance
    cov_in = np.asarray(covariance, dtype=float)
    extra = size - mean_in.shape[-1]
    out_mean = np.concatenate([mean_in, np.zeros(mean_in.shape[:-1] + (extra,))], axis=-1)
    out_cov = np.zeros(cov_in.shape[:-2] + (size, size))
    d = cov_in.shape[-1]
    out_cov[..., :d, :d] = cov_in
    if not isinstance(part, SingerMotion | ConstantAccelerationMotion):
        raise ValueError(f"{part!r} has no prior spread of its accelerations")
    variance = float(part.acceleration_std) ** 2
    for k in range(d, size):
        out_cov[..., k, k] = variance
    return out_mean, out_cov
