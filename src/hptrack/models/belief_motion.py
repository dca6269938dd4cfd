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
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
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
        position_terms: ``(motion, tau, cov, q) -> poly``, ten numbers from which
            ``position_det`` evaluates ``det Sigma^xy`` after any number of steps.
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
