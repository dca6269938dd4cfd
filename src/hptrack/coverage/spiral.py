"""The shifting elliptic spiral of the coverage path planner (paper Sec. IV-A, Eqs. (3)-(5)).

In the frame ``{E}`` that moves with the belief mean and whose axes follow the eigenvectors of the
2x2 position covariance ``Sigma^xy`` at the start of the coverage, the spiral is (Eq. (3))

    r(theta) = b theta,   x_E = r A cos(theta),   y_E = r B sin(theta),

with ``a = 0`` and ``theta_0 = 0`` so that it starts at the belief centre, ``A = sqrt(lambda1)``,
``B = sqrt(lambda2)`` (``lambda1 >= lambda2``) and ``b = w / (2 pi max(A, B))`` so that
consecutive loops are at most ``w`` apart along both axes (Eq. (4)). In the world frame (Eq. (5))

    p_k = c_0 + R [x_E(theta_k), y_E(theta_k)] + v_hat k tau,

with ``R = [u1 u2]`` (a proper rotation). Each next phase ``theta_{k+1}`` is the smallest root
above ``theta_k`` of ``f(theta) = |p_E(theta) + v_E tau - p_E(theta_k)|^2 - (v_a tau)^2``, so that
every step of the agent is exactly ``v_a tau`` long. ``f(theta_k) = (|v_hat|^2 - v_a^2) tau^2 < 0``;
the root is bracketed by marching ``theta`` up in increments that move the spiral point by at
most ``v_a tau / 32`` and refined by bisection to machine precision (far below a millimetre).

`spiral_phases` is the compiled kernel; `ShiftingSpiral` extends it lazily.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np

MARCH_FRACTION = 1.0 / 32.0
"""Largest spiral displacement per bracketing increment, as a fraction of ``v_a tau``."""
MAX_MARCH_INCREMENT = 0.25
"""Largest bracketing increment of the phase, rad."""
CHUNK_STEPS = 256
"""Steps computed at a time when the lazy spiral is extended."""


@numba.njit(cache=True, inline="always")
def _gap(theta, pitch, semi_a, semi_b, ref_x, ref_y, step2):
    """``f(theta)`` with ``ref = p_E(theta_k) - v_E tau``."""
    r = pitch * theta
    dx = r * semi_a * math.cos(theta) - ref_x
    dy = r * semi_b * math.sin(theta) - ref_y
    return dx * dx + dy * dy - step2


@numba.njit(cache=True)
def spiral_phases(
    theta_start: float,
    pitch: float,
    semi_a: float,
    semi_b: float,
    shift_x: np.ndarray,
    shift_y: np.ndarray,
    step_length: float,
    out: np.ndarray,
) -> int:
    """Fill ``out`` with the phases ``theta_{k+1}, theta_{k+2}, ...`` that follow ``theta_start``.

    Args:
        theta_start: the current phase ``theta_k``, rad.
        pitch: ``b`` (m per rad per m of semi-axis; ``r = b theta``).
        semi_a, semi_b: ``A >= B`` along the E-frame axes, m.
        shift_x, shift_y: the frame's displacement in E axes, m, over each step to fill
            (``v_E tau`` every step when the mean moves at a constant velocity).
        step_length: ``v_a tau``, m; must exceed ``|v_E tau|``.
        out: preallocated phases to fill.

    Returns:
        How many phases were filled: ``len(out)``, or fewer if a root could not be bracketed
        (inconsistent inputs), never an endless loop.
    """
    step2 = step_length * step_length
    speed_scale = pitch * max(semi_a, semi_b)  # |dp/dtheta| <= speed_scale * sqrt(1 + theta^2)
    theta = theta_start
    for i in range(out.shape[0]):
        # A root lies below theta_k + reach: on the u1 axis |p_E(m pi)| = b m pi A while
        # |p_E(theta_k)| <= b theta_k A, so some m pi in that range is farther than step + shift.
        shift = math.hypot(shift_x[i], shift_y[i])
        reach = 2.0 * math.pi + 2.0 * (step_length + shift) / (pitch * semi_a)
        r = pitch * theta
        ref_x = r * semi_a * math.cos(theta) - shift_x[i]
        ref_y = r * semi_b * math.sin(theta) - shift_y[i]
        lo = theta
        if _gap(lo, pitch, semi_a, semi_b, ref_x, ref_y, step2) >= 0.0:
            return i
        limit = theta + reach
        hi = lo
        while True:
            increment = MARCH_FRACTION * step_length / (speed_scale * math.sqrt(1.0 + hi * hi))
            hi = lo + min(increment, MAX_MARCH_INCREMENT)
            if _gap(hi, pitch, semi_a, semi_b, ref_x, ref_y, step2) >= 0.0:
                break
            if hi > limit:
                return i
            lo = hi
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            if mid <= lo or mid >= hi:
                break
            if _gap(mid, pitch, semi_a, semi_b, ref_x, ref_y, step2) < 0.0:
                lo = mid
            else:
                hi = mid
        f_lo = -_gap(lo, pitch, semi_a, semi_b, ref_x, ref_y, step2)
        f_hi = _gap(hi, pitch, semi_a, semi_b, ref_x, ref_y, step2)
        theta = lo if f_lo < f_hi else hi
        out[i] = theta
    return out.shape[0]


def ellipse_axes(position_covariance: np.ndarray) -> tuple[float, float, np.ndarray]:
    """``(A, B, R)``: semi-axes ``sqrt(lambda1) >= sqrt(lambda2)`` (m) and the proper rotation
    ``R = [u1 u2]`` of a 2x2 position covariance (m^2).

    Raises:
        ValueError: not a finite, symmetric, positive definite 2x2 matrix.
    """
    cov = np.asarray(position_covariance, dtype=float)
    if cov.shape != (2, 2) or not np.all(np.isfinite(cov)):
        raise ValueError(f"position covariance must be a finite 2x2 matrix, got {cov.tolist()}")
    scale = float(np.max(np.abs(cov)))
    if abs(cov[0, 1] - cov[1, 0]) > 1e-9 * max(scale, 1.0):
        raise ValueError(f"position covariance is not symmetric: {cov.tolist()}")
    eigenvalues, eigenvectors = np.linalg.eigh(0.5 * (cov + cov.T))
    if eigenvalues[0] <= 1e-12 * eigenvalues[1]:
        raise ValueError(
            "position covariance is not positive definite (eigenvalues "
            f"{eigenvalues.tolist()} m^2): the belief ellipse is degenerate"
        )
    rotation = eigenvectors[:, ::-1].copy()  # columns u1 (largest eigenvalue), u2
    if np.linalg.det(rotation) < 0.0:
        rotation[:, 1] *= -1.0
    return float(np.sqrt(eigenvalues[1])), float(np.sqrt(eigenvalues[0])), rotation


class ShiftingSpiral:
    """The shifting spiral of Eq. (5), extended lazily in chunks; it never ends.

    Step ``k`` (time ``k tau`` after the coverage starts) has phase ``theta_k`` (``theta_0 = 0``)
    and world position ``p_k``; ``p_0`` is the belief centre and ``|p_{k+1} - p_k| = v_a tau``.

    Args:
        centre: ``(2,)`` belief mean position when the coverage starts, m.
        velocity: ``(2,)`` estimated target velocity ``v_hat``, m/s; ``|v_hat| < speed``.
        position_covariance: 2x2 ``Sigma^xy`` when the coverage starts, m^2 (positive definite).
        speed: agent speed ``v_a``, m/s.
        time_step: ``tau``, s.
        sensor_diameter: footprint diameter ``w``, m.
        mean_offsets: for a belief mean that does not move at a constant velocity, a function
            from spiral steps ``(m,)`` to the mean's displacement from ``centre`` ``(m, 2)``, m
            (its speed never above ``|velocity|``); ``None``: ``v_hat k tau``.
    """

    def __init__(
        self,
        centre: np.ndarray,
        velocity: np.ndarray,
        position_covariance: np.ndarray,
        speed: float,
        time_step: float,
        sensor_diameter: float,
        mean_offsets: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.mean_offsets = mean_offsets
        self.centre = np.asarray(centre, dtype=float).copy()
        self.velocity = np.asarray(velocity, dtype=float).copy()
        if (
            self.centre.shape != (2,)
            or self.velocity.shape != (2,)
            or not (np.all(np.isfinite(self.centre)) and np.all(np.isfinite(self.velocity)))
        ):
            raise ValueError(
                f"centre and velocity must be two finite numbers each, got "
                f"{centre!r} and {velocity!r}"
            )
        for name, value in (
            ("speed", speed),
            ("time_step", time_step),
            ("sensor_diameter", sensor_diameter),
        ):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        target_speed = float(np.hypot(*self.velocity))
        if target_speed >= speed:
            raise ValueError(
                f"the target's estimated speed {target_speed:g} m/s is not below "
                f"the agent speed {speed:g} m/s: no spiral can keep up"
            )
        self.semi_a, self.semi_b, self.rotation = ellipse_axes(position_covariance)
        self.pitch = sensor_diameter / (2.0 * math.pi * max(self.semi_a, self.semi_b))
        self.speed = float(speed)
        self.time_step = float(time_step)
        self.sensor_diameter = float(sensor_diameter)
        self._shift = self.rotation.T @ self.velocity * self.time_step  # v_E tau
        self._phases = np.zeros(1)

    @property
    def step_length(self) -> float:
        """``v_a tau``, m."""
        return self.speed * self.time_step

    def _offsets(self, steps: np.ndarray) -> np.ndarray:
        """The mean's displacement from ``centre`` at spiral steps ``steps``, ``(m, 2)``, m."""
        if self.mean_offsets is None:
            return self.velocity * (steps[:, None] * self.time_step)
        return np.asarray(self.mean_offsets(steps), dtype=float).reshape(-1, 2)

    def _frame_shifts(self, first: int, count: int) -> np.ndarray:
        """The frame's displacement in E axes over steps ``first .. first + count - 1``
        (each to the next), ``(count, 2)``, m."""
        if self.mean_offsets is None:
            return np.repeat(self._shift[None, :], count, axis=0)
        path = self._offsets(np.arange(first, first + count + 1, dtype=float))
        return np.diff(path, axis=0) @ self.rotation

    def _extend(self, n_steps: int) -> None:
        while self._phases.shape[0] < n_steps:
            more = max(CHUNK_STEPS, n_steps - self._phases.shape[0])
            out = np.empty(more)
            shifts = self._frame_shifts(self._phases.shape[0] - 1, more)
            filled = spiral_phases(
                float(self._phases[-1]),
                self.pitch,
                self.semi_a,
                self.semi_b,
                np.ascontiguousarray(shifts[:, 0]),
                np.ascontiguousarray(shifts[:, 1]),
                self.step_length,
                out,
            )
            if filled < more:
                raise RuntimeError(
                    f"spiral step {self._phases.shape[0] + filled} could not be "
                    "bracketed; the spiral parameters are inconsistent"
                )
            self._phases = np.concatenate([self._phases, out])

    def phases(self, n_steps: int) -> np.ndarray:
        """``theta_k`` for ``k = 0 .. n_steps - 1``, rad."""
        if n_steps < 0:
            raise ValueError(f"n_steps must be non-negative, got {n_steps}")
        self._extend(n_steps)
        return self._phases[:n_steps].copy()

    def frame_positions(self, n_steps: int) -> np.ndarray:
        """``(n_steps, 2)`` positions in ``{E}`` (moving with the mean, axes ``u1, u2``), m."""
        theta = self.phases(n_steps)
        r = self.pitch * theta
        return np.stack([r * self.semi_a * np.cos(theta), r * self.semi_b * np.sin(theta)], axis=1)

    def positions(self, n_steps: int) -> np.ndarray:
        """``(n_steps, 2)`` world positions of steps ``0 .. n_steps - 1`` (Eq. (5)), m."""
        k = np.arange(n_steps, dtype=float)
        return self.centre + self.frame_positions(n_steps) @ self.rotation.T + self._offsets(k)

    def position(self, step: int) -> np.ndarray:
        """World position ``(2,)`` of step ``step``, m."""
        if step < 0:
            raise ValueError(f"step must be non-negative, got {step}")
        self._extend(step + 1)
        theta = float(self._phases[step])
        r = self.pitch * theta
        frame = np.array([r * self.semi_a * math.cos(theta), r * self.semi_b * math.sin(theta)])
        if self.mean_offsets is None:
            return self.centre + self.rotation @ frame + self.velocity * (step * self.time_step)
        offset = self._offsets(np.array([float(step)]))[0]
        return self.centre + self.rotation @ frame + offset
