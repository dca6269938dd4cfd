"""Tracking metrics beside ``U``: GOSPA between the belief means and the true positions, track
loss at the budget's end and the targets never detected.

GOSPA (Rahmathullah, Garcia-Fernandez and Svensson, 2017) between estimates ``X`` (``m``
points) and truths ``Y`` (``n`` points), ``m <= n`` (else swap them), cutoff ``c`` m, order
``p`` and ``alpha``:

    d = (min_pi sum_{i <= m} min(|x_i - y_pi(i)|, c)^p + c^p / alpha (n - m))^(1/p),

the minimum over the injections ``pi`` of the estimates into the truths (an optimal
assignment, `scipy.optimize.linear_sum_assignment`). It is label-free: which belief is whose
does not enter. With ``alpha = 2`` (the default, as here) it is a localisation error of the
pairs closer than ``c`` plus ``c^p / 2`` per missed or false point, and a pair at ``c`` or
more counts as one of each. hptrack takes ``p = 2``, ``alpha = 2`` and ``c = w / 2``, the
footprint's radius: an estimate farther than that from its target would not put the target
under the sensor.

A target's track is *lost* at the end when its true position lies outside its belief's 99 %
ellipse (the squared Mahalanobis distance of the position above the chi-square 2-dof
quantile, ``-2 ln 0.01``), or when the end's optimal assignment pairs its belief with another
target's truth closer than ``c`` (a swapped track).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import linear_sum_assignment

GOSPA_ORDER = 2.0
"""``p`` of hptrack's GOSPA."""
GOSPA_ALPHA = 2.0
"""``alpha`` of hptrack's GOSPA."""
ELLIPSE_LEVEL = 0.99
"""The belief ellipse's probability in the track-loss rule."""
ELLIPSE_CHI2 = -2.0 * math.log(1.0 - ELLIPSE_LEVEL)
"""The chi-square quantile of 2 degrees of freedom at `ELLIPSE_LEVEL` (9.21): a 2-D
Gaussian's squared Mahalanobis distance has ``P(d2 <= r2) = 1 - exp(-r2 / 2)``."""


def gospa_cutoff(sensor_diameter: float) -> float:
    """hptrack's GOSPA cutoff ``c`` for a footprint of diameter ``w`` (m): its radius, m."""
    return 0.5 * sensor_diameter


def gospa_assignment(
    estimates: np.ndarray,
    truths: np.ndarray,
    cutoff: float,
    p: float = GOSPA_ORDER,
    alpha: float = GOSPA_ALPHA,
) -> tuple[float, np.ndarray]:
    """GOSPA (module docstring) between ``estimates`` ``(m, 2)`` and ``truths`` ``(n, 2)``
    (m) and its optimal assignment.

    Returns:
        ``(d, pairs)``: the distance, m, and ``(m, )`` the truth each estimate is assigned to,
        ``-1`` for one left unassigned (no truth left, or none closer than ``cutoff``).

    Raises:
        ValueError: ``cutoff <= 0``, ``p < 1`` or ``alpha`` outside ``(0, 2]``.
    """
    if not cutoff > 0 or not p >= 1 or not 0 < alpha <= 2:
        raise ValueError(f"GOSPA needs c > 0, p >= 1, 0 < alpha <= 2; got {cutoff}, {p}, {alpha}")
    x = np.asarray(estimates, dtype=float).reshape(-1, 2)
    y = np.asarray(truths, dtype=float).reshape(-1, 2)
    pairs = np.full(len(x), -1, dtype=np.int64)
    unmatched = abs(len(x) - len(y))
    total = 0.0
    if len(x) and len(y):
        distance = np.hypot(x[:, None, 0] - y[None, :, 0], x[:, None, 1] - y[None, :, 1])
        cost = np.minimum(distance, cutoff) ** p
        rows, cols = linear_sum_assignment(cost)
        total = float(cost[rows, cols].sum())
        close = distance[rows, cols] < cutoff
        pairs[rows[close]] = cols[close]
    total += cutoff**p / alpha * unmatched
    return total ** (1.0 / p), pairs


def gospa(
    estimates: np.ndarray,
    truths: np.ndarray,
    cutoff: float,
    p: float = GOSPA_ORDER,
    alpha: float = GOSPA_ALPHA,
) -> float:
    """GOSPA between ``estimates`` ``(m, 2)`` and ``truths`` ``(n, 2)``, m
    (`gospa_assignment`)."""
    return gospa_assignment(estimates, truths, cutoff, p, alpha)[0]


def gospa_history(mean_positions: np.ndarray, true_positions: np.ndarray, cutoff: float):
    """GOSPA at every step of ``(K, n, 2)`` belief means and true positions, ``(K,)`` m."""
    return np.array(
        [gospa(x, y, cutoff) for x, y in zip(mean_positions, true_positions, strict=True)]
    )


def outside_ellipse(means: np.ndarray, covariances: np.ndarray, truths: np.ndarray) -> np.ndarray:
    """``(n,)`` whether each true position ``truths`` ``(n, 2)`` lies outside its belief's
    `ELLIPSE_LEVEL` ellipse (``means`` ``(n, 2)``, position covariances ``(n, 2, 2)``)."""
    e = np.asarray(truths, dtype=float) - np.asarray(means, dtype=float)
    s = np.asarray(covariances, dtype=float)
    a, b, d = s[:, 0, 0], s[:, 0, 1], s[:, 1, 1]
    d2 = (d * e[:, 0] ** 2 - 2.0 * b * e[:, 0] * e[:, 1] + a * e[:, 1] ** 2) / (a * d - b * b)
    return d2 > ELLIPSE_CHI2


def track_lost(
    means: np.ndarray, covariances: np.ndarray, truths: np.ndarray, cutoff: float
) -> np.ndarray:
    """``(n,)`` which targets' tracks are lost (module docstring): belief ``i`` (mean
    ``(n, 2)``, position covariance ``(n, 2, 2)``) against truth ``i`` ``(n, 2)``."""
    pairs = gospa_assignment(means, truths, cutoff)[1]
    swapped = (pairs >= 0) & (pairs != np.arange(len(pairs)))
    return outside_ellipse(means, covariances, truths) | swapped


def never_detected(detections: np.ndarray) -> int:
    """How many targets no step of ``(K+1, n)`` detections measured."""
    return int(np.sum(~np.asarray(detections).any(axis=0)))
