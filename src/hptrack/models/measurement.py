"""Position measurement and Kalman update (paper Sec. III; notes: R = 10 I by default).

A target inside the circular sensor footprint is measured as ``z = [x, y] + v``,
``v ~ N(0, R)``. The update uses the Joseph form so the covariance stays symmetric positive
definite over thousands of updates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

H = np.hstack([np.eye(2), np.zeros((2, 2))])


@dataclass(frozen=True)
class PositionMeasurementModel:
    """Linear position sensor with a circular footprint.

    Attributes:
        noise_std: standard deviation of each position coordinate, m (``R = noise_std^2 I``).
        sensor_diameter: footprint diameter ``w``, m; targets within ``w/2`` are measured.
    """

    noise_std: float = float(np.sqrt(10.0))
    sensor_diameter: float = 100.0
    noise_covariance: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "noise_covariance", self.noise_std**2 * np.eye(2))

    def in_footprint(self, agent_position: np.ndarray, positions: np.ndarray) -> np.ndarray:
        """Boolean mask ``(n,)``: which positions ``(n, 2)`` lie within ``w/2`` of the agent."""
        d2 = np.sum((positions - agent_position) ** 2, axis=-1)
        return d2 <= (0.5 * self.sensor_diameter) ** 2

    def sample(self, positions: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Noisy measurements ``(m, 2)`` of true positions ``(m, 2)``."""
        return positions + self.noise_std * rng.standard_normal(positions.shape)

    def update(self, means: np.ndarray, covariances: np.ndarray, measurements: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """Kalman update of stacked beliefs ``(m, 4)``, ``(m, 4, 4)`` with ``z`` ``(m, 2)``.

        Joseph form ``P+ = (I - K H) P (I - K H)' + K R K'``.
        """
        r = self.noise_covariance
        innovation_cov = covariances[:, :2, :2] + r
        gain = np.linalg.solve(innovation_cov, covariances[:, :2, :]).transpose(0, 2, 1)
        innovation = measurements - means[:, :2]
        new_means = means + np.einsum("mij,mj->mi", gain, innovation)
        i_kh = np.eye(4) - gain @ H
        new_covs = i_kh @ covariances @ i_kh.transpose(0, 2, 1) + gain @ r @ gain.transpose(0, 2, 1)
        return new_means, 0.5 * (new_covs + new_covs.transpose(0, 2, 1))
