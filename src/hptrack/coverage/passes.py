"""Measurements on the way: the chance that a flight passes over another target's belief.

A sub-task flies the agent across the workspace, and the sensor measures every target inside its
footprint on the way, not only the pursued one. Relative to a target's belief mean the agent
flies a straight segment of length ``L`` (m) in the direction ``d`` (a unit vector); the target's
position error ``e ~ N(0, Sigma^xy)`` is taken as fixed during the pass. The footprint of radius
``r`` sweeps a strip of half-width ``r`` along the segment, extended by ``r`` at both ends, so the
target is measured when its offset across the path lies within ``r`` and its offset along it
within ``[-r, L + r]``. With the two offsets taken as independent normals (the correlation
between them is left out), the probability is the product of two normal interval probabilities.
"""

from __future__ import annotations

import math

import numba

from hptrack.coverage.sharp_estimator import upper_tail


@numba.njit(cache=True, inline="always")
def _interval(mean, variance, low, high):
    """``P(low <= X <= high)`` for ``X ~ N(mean, variance)`` (a point mass if ``variance`` is 0)."""
    if variance <= 0.0:
        return 1.0 if low <= mean <= high else 0.0
    sd = math.sqrt(variance)
    return upper_tail((low - mean) / sd) - upper_tail((high - mean) / sd)


@numba.njit(cache=True)
def pass_probability(offset_x, offset_y, dir_x, dir_y, length, sxx, sxy, syy, radius):
    """Probability that a straight flight measures a target (module docstring).

    Args:
        offset_x, offset_y: the agent's start relative to the target's belief mean, m, in the
            frame moving with that mean.
        dir_x, dir_y: the unit direction of the agent's flight in that frame.
        length: the flight's length in that frame, m.
        sxx, sxy, syy: the target's position covariance ``Sigma^xy`` during the pass, m^2.
        radius: the footprint radius, m.
    """
    along = -(offset_x * dir_x + offset_y * dir_y)  # the target's mean along the path
    across = offset_x * dir_y - offset_y * dir_x
    along_var = dir_x * dir_x * sxx + 2.0 * dir_x * dir_y * sxy + dir_y * dir_y * syy
    across_var = dir_y * dir_y * sxx - 2.0 * dir_x * dir_y * sxy + dir_x * dir_x * syy
    return _interval(across, across_var, -radius, radius) * _interval(
        along, along_var, -radius, length + radius
    )
