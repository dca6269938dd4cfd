"""A sensor's ``detection_probability`` fitted from a detector's logged looks: each look at a
target inside the footprint, its distance from the footprint's centre (m) and whether the
detector reported it.

The looks are independent Bernoulli trials with ``Pd(d)`` (the model of
`hptrack.models.sensor.DetectingFootprintSensor`), so the maximum-likelihood ``Pd`` of a bin of
distances is its share of hits; under the constraint that ``Pd`` does not grow with the distance
it is the weighted isotonic (non-increasing) regression of those shares, weighted by the bins'
looks (the pool-adjacent-violators fit, ``scipy.optimize.isotonic_regression``). Each bin's
uncertainty is its 95 % Wilson score interval.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from scipy.optimize import isotonic_regression

MAX_BINS = 100_000
"""Most distance bins a fit may have (the largest distance over the bin width)."""
WILSON_Z = 1.959963984540054
"""The standard normal's 97.5 % quantile: a two-sided 95 % Wilson interval."""


def wilson_interval(hits: np.ndarray, looks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 95 % Wilson score interval ``(low, high)`` of ``hits`` successes in ``looks``
    trials (elementwise; ``looks > 0``)."""
    hits = np.asarray(hits, dtype=float)
    looks = np.asarray(looks, dtype=float)
    z2 = WILSON_Z**2
    share = hits / looks
    centre = (share + z2 / (2 * looks)) / (1 + z2 / looks)
    half = WILSON_Z * np.sqrt(share * (1 - share) / looks + z2 / (4 * looks**2)) / (1 + z2 / looks)
    return centre - half, centre + half


class DetectionFit(NamedTuple):
    """The fit of `fit_detection_probability`; one entry per bin of distances that holds looks.

    Attributes:
        low_m: ``(k,)`` each bin's smallest distance from the footprint's centre, m.
        high_m: ``(k,)`` its largest (exclusive, but the last bin's), m.
        looks: ``(k,)`` looks in the bin.
        hits: ``(k,)`` looks that detected the target.
        fitted: ``(k,)`` the bin's fitted ``Pd`` (its share of hits, or the non-increasing fit).
        interval_low: ``(k,)`` the lower end of the share's 95 % Wilson interval.
        interval_high: ``(k,)`` its upper end.
        constant: the maximum-likelihood constant ``Pd``, all looks together.
        constant_low: its 95 % Wilson interval's lower end.
        constant_high: its upper end.
    """

    low_m: np.ndarray
    high_m: np.ndarray
    looks: np.ndarray
    hits: np.ndarray
    fitted: np.ndarray
    interval_low: np.ndarray
    interval_high: np.ndarray
    constant: float
    constant_low: float
    constant_high: float

    def rows(self) -> list[list[float]]:
        """The fit as a scenario's ``detection_probability`` table: rows ``[distance_m, Pd]``,
        the first bin's ``Pd`` at 0 m, each later bin's at its centre (the sensor interpolates
        linearly between rows and holds the last one to the footprint's edge)."""
        centres = 0.5 * (self.low_m + self.high_m)
        distances = [0.0, *(float(c) for c in centres[1:])]
        return [[d, float(p)] for d, p in zip(distances, self.fitted, strict=True)]


def fit_detection_probability(
    distances_m: np.ndarray,
    detected: np.ndarray,
    bin_width_m: float,
    monotone: bool = True,
) -> DetectionFit:
    """Fit ``Pd`` by distance from logged looks (module docstring).

    Args:
        distances_m: ``(L,)`` each look's distance from the footprint's centre to the target, m.
        detected: ``(L,)`` whether the look detected it.
        bin_width_m: the width of the distance bins, m, from 0.
        monotone: fit a ``Pd`` that does not grow with the distance (else each bin's share).

    Raises:
        ValueError: no looks, a distance negative or not finite, a bin width not positive, or
            more than `MAX_BINS` bins.
    """
    distances_m = np.asarray(distances_m, dtype=float)
    detected = np.asarray(detected, dtype=bool)
    if distances_m.size == 0:
        raise ValueError("no looks to fit")
    if not (math.isfinite(bin_width_m) and bin_width_m > 0):
        raise ValueError(f"the bin width must be a positive number of metres, value {bin_width_m}")
    bad = ~np.isfinite(distances_m) | (distances_m < 0)
    if bad.any():
        raise ValueError(
            f"look {int(np.argmax(bad))}: a distance must be finite and >= 0 m, "
            f"value {distances_m[bad][0]}"
        )
    if distances_m.max() / bin_width_m >= MAX_BINS:
        raise ValueError(
            f"a bin width of {bin_width_m:g} m gives more than {MAX_BINS} bins up to "
            f"{distances_m.max():g} m"
        )
    index = np.floor(distances_m / bin_width_m).astype(np.int64)
    looks = np.bincount(index)
    hits = np.bincount(index, weights=detected.astype(float), minlength=looks.size)
    kept = np.flatnonzero(looks)
    looks, hits = looks[kept], hits[kept].astype(np.int64)
    share = hits / looks
    fitted = isotonic_regression(share, weights=looks, increasing=False).x if monotone else share
    low, high = wilson_interval(hits, looks)
    total_low, total_high = wilson_interval(np.array([hits.sum()]), np.array([looks.sum()]))
    return DetectionFit(
        low_m=kept * bin_width_m,
        high_m=(kept + 1) * bin_width_m,
        looks=looks,
        hits=hits,
        fitted=np.asarray(fitted, dtype=float),
        interval_low=low,
        interval_high=high,
        constant=float(hits.sum() / looks.sum()),
        constant_low=float(total_low[0]),
        constant_high=float(total_high[0]),
    )
