"""The mission score ``U = sum_i log det Sigma^xy_i`` (paper Sec. III, lower is better) over
beliefs stored as stacked arrays: means ``(n, 4)`` in m and m/s, covariances ``(n, 4, 4)``."""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, inline="always")
def logdet_xy(sxx, sxy, syy):
    """``log det`` of the 2x2 position covariance ``[[sxx, sxy], [sxy, syy]]`` (log m^4)."""
    return math.log(sxx * syy - sxy * sxy)


def position_logdet(covariances: np.ndarray) -> np.ndarray:
    """``log det`` of the 2x2 position block of each covariance ``(..., 4, 4)``."""
    p = covariances[..., :2, :2]
    return np.log(p[..., 0, 0] * p[..., 1, 1] - p[..., 0, 1] * p[..., 1, 0])
