"""Target belief manager (paper Fig. 2, "Target Belief Manager") and the mission score U.

Keeps one Gaussian belief per target as stacked arrays: means ``(n, 4)`` in m and m/s,
covariances ``(n, 4, 4)``. ``U = sum_i log det Sigma^xy_i`` (paper Sec. III), lower is better.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel


@numba.njit(cache=True, inline="always")
def logdet_xy(sxx, sxy, syy):
    """``log det`` of the 2x2 position covariance ``[[sxx, sxy], [sxy, syy]]`` (log m^4)."""
    return math.log(sxx * syy - sxy * sxy)


def position_logdet(covariances: np.ndarray) -> np.ndarray:
    """``log det`` of the 2x2 position block of each covariance ``(..., 4, 4)``."""
    p = covariances[..., :2, :2]
    return np.log(p[..., 0, 0] * p[..., 1, 1] - p[..., 0, 1] * p[..., 1, 0])


@dataclass
class TargetBeliefs:
    """Beliefs over ``n`` independent targets, predicted and updated in place.

    Attributes:
        means: ``(n, 4)`` state means.
        covariances: ``(n, 4, 4)`` state covariances.
        process_noise: ``(n,)`` noise intensities ``q`` (m^2/s^3).
        motion: the motion model (``tau`` and ``Q`` form).
        sensor: the measurement model (``R``, footprint).
    """

    means: np.ndarray
    covariances: np.ndarray
    process_noise: np.ndarray
    motion: ConstantVelocityModel
    sensor: PositionMeasurementModel

    def predict(self, duration: float) -> None:
        """Propagate every belief ``duration`` seconds with Eq. (1) (closed form, any gap)."""
        self.means, self.covariances = self.motion.predict(
            self.means, self.covariances, self.process_noise, duration
        )

    def update(self, indices: np.ndarray, measurements: np.ndarray) -> None:
        """Kalman-update the beliefs of targets ``indices`` with position ``measurements``."""
        if len(indices) == 0:
            return
        m, c = self.sensor.update(self.means[indices], self.covariances[indices], measurements)
        self.means[indices] = m
        self.covariances[indices] = c

    def position_logdets(self) -> np.ndarray:
        """Per-target ``log det Sigma^xy`` (log m^4)."""
        return position_logdet(self.covariances)

    def uncertainty(self) -> float:
        """Mission score ``U = sum_i log det Sigma^xy_i``."""
        return float(np.sum(self.position_logdets()))

    def copy(self) -> TargetBeliefs:
        """An independent copy (arrays copied, models shared)."""
        return TargetBeliefs(
            self.means.copy(),
            self.covariances.copy(),
            self.process_noise.copy(),
            self.motion,
            self.sensor,
        )
