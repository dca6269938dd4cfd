"""Constant-velocity target motion with closed-form covariance growth (paper Sec. III, Eq. (1)).

State ``[x, y, vx, vy]`` in m and m/s. One step of ``tau`` seconds applies
``F = [[I, tau I], [0, I]]`` and adds process noise ``Q = q [[a I, b I], [b I, c I]]``.

Two forms of ``Q`` are offered (see ``shared/notes/model-and-protocol.md``):

* ``"continuous"`` (default): ``a, b, c = tau^3/3, tau^2/2, tau`` -- the discretised continuous
  white-noise acceleration model. After ``k`` steps the accumulated noise is exactly
  ``q [[T^3/3, T^2/2], [T^2/2, T]]`` per axis with ``T = k tau``.
* ``"paper_text"``: ``a, b, c = tau^3/3, tau^2/2, 1`` -- the form printed in the paper's Sec. V-A.

For any per-step blocks ``(a, b, c)`` the sum ``sum_{j<k} F^j Q F^j'`` is, per axis,
``q [[k a + 2 tau s1 b + tau^2 s2 c, k b + tau s1 c], [., k c]]`` with ``s1 = k(k-1)/2`` and
``s2 = k(k-1)(2k-1)/6``, so a prediction over any duration costs O(1).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np

ProcessNoiseForm = Literal["continuous", "paper_text"]


@numba.njit(cache=True, inline="always")
def noise_blocks(q: float, steps: float, tau: float, c_per_step: float) -> tuple:
    """Accumulated process noise after ``steps`` steps, per axis: ``(Qpp, Qpv, Qvv)``.

    ``steps`` may be a scalar or an array (element-wise). ``c_per_step`` is the lower-right
    per-step block over ``q`` (``tau`` or ``1``).
    """
    k = steps
    s1 = k * (k - 1.0) / 2.0
    s2 = k * (k - 1.0) * (2.0 * k - 1.0) / 6.0
    a = tau**3 / 3.0
    b = tau**2 / 2.0
    qpp = q * (k * a + 2.0 * tau * s1 * b + tau * tau * s2 * c_per_step)
    qpv = q * (k * b + tau * s1 * c_per_step)
    qvv = q * k * c_per_step
    return qpp, qpv, qvv


@numba.njit(cache=True)
def position_covariance_after(cov: np.ndarray, q: float, steps: float, tau: float,
                              c_per_step: float) -> tuple:
    """2x2 position covariance ``(sxx, sxy, syy)`` after ``steps`` prediction steps, in m^2.

    ``cov`` is the 4x4 state covariance now. O(1) in ``steps`` (Eq. (1) in closed form).
    """
    t = steps * tau
    qpp, _, _ = noise_blocks(q, steps, tau, c_per_step)
    sxx = cov[0, 0] + 2.0 * t * cov[0, 2] + t * t * cov[2, 2] + qpp
    syy = cov[1, 1] + 2.0 * t * cov[1, 3] + t * t * cov[3, 3] + qpp
    sxy = cov[0, 1] + t * (cov[0, 3] + cov[2, 1]) + t * t * cov[2, 3]
    return sxx, sxy, syy


@dataclass(frozen=True)
class ConstantVelocityModel:
    """Constant-velocity model of Eq. (1).

    Attributes:
        time_step: ``tau`` in s (the paper uses 0.5 s).
        process_noise_form: which ``Q`` to use (module docstring).
    """

    time_step: float = 0.5
    process_noise_form: ProcessNoiseForm = "continuous"

    @property
    def c_per_step(self) -> float:
        """Lower-right block of the per-step ``Q`` divided by ``q``."""
        return self.time_step if self.process_noise_form == "continuous" else 1.0

    def transition(self, steps: float = 1) -> np.ndarray:
        """``F^k``: the 4x4 transition over ``steps`` steps."""
        f = np.eye(4)
        f[0, 2] = f[1, 3] = steps * self.time_step
        return f

    def process_noise(self, q: float, steps: float = 1) -> np.ndarray:
        """Accumulated process noise ``sum_{j<k} F^j Q F^j'`` (4x4) after ``steps`` steps."""
        qpp, qpv, qvv = noise_blocks(float(q), float(steps), self.time_step, self.c_per_step)
        eye = np.eye(2)
        return np.block([[qpp * eye, qpv * eye], [qpv * eye, qvv * eye]])

    def predict(self, means: np.ndarray, covariances: np.ndarray, q: np.ndarray | float,
                steps: np.ndarray | float = 1) -> tuple[np.ndarray, np.ndarray]:
        """Predict stacked beliefs ``(n, 4)``, ``(n, 4, 4)`` over ``steps`` steps in closed form.

        ``q`` (m^2/s^3) and ``steps`` may be scalars or one value per target.
        """
        n = means.shape[0]
        q = np.broadcast_to(np.asarray(q, dtype=float), (n,))
        steps = np.broadcast_to(np.asarray(steps, dtype=float), (n,))
        f = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        f[:, 0, 2] = f[:, 1, 3] = steps * self.time_step
        qpp, qpv, qvv = (q * b for b in noise_blocks(1.0, steps, self.time_step,
                                                      self.c_per_step))
        noise = np.zeros((n, 4, 4))
        for i, j, block in ((0, 0, qpp), (1, 1, qpp), (2, 2, qvv), (3, 3, qvv),
                            (0, 2, qpv), (2, 0, qpv), (1, 3, qpv), (3, 1, qpv)):
            noise[:, i, j] = block
        new_means = np.einsum("nij,nj->ni", f, means)
        new_covs = f @ covariances @ f.transpose(0, 2, 1) + noise
        return new_means, new_covs

    def sample_motion(self, states: np.ndarray, q: np.ndarray, rng: np.random.Generator
                      ) -> np.ndarray:
        """Propagate true states ``(n, 4)`` one step with ``w ~ N(0, Q_i)`` noise."""
        unit_noise = self.process_noise(1.0, 1)
        chol = np.linalg.cholesky(unit_noise)
        noise = rng.standard_normal(states.shape) @ chol.T
        return states @ self.transition(1).T + np.sqrt(q)[:, None] * noise
