"""Coverage outcome estimator (paper Sec. IV-B, Eqs. (6)-(8); notes "Coverage sub-task").

During a spiral coverage that starts from the belief covariance ``Sigma`` (4x4) the covered area
grows linearly, ``S_cover(k) = v_a w k tau + pi (w/2)^2``, while the position covariance grows
as Eq. (1). The probability of having found the target by step ``k`` of the coverage is the
chi-squared CDF with 2 degrees of freedom,

    P_cdf(k) = 1 - exp(-S_cover(k) / (2 pi sqrt(det Sigma^xy(k)))).

``t_cutoff`` is the first step after which ``P_cdf`` stops increasing, ``p_max = P_cdf(t_cutoff)``
and ``E[T_find]`` is the expected finding time given the target is found by ``t_cutoff``,
measured from the start of the coverage. When the remaining budget ends first, everything is
truncated at the budget's end.

:func:`coverage_outcome` is the compiled kernel used by the tree search: O(t_cutoff) arithmetic
with the covariance in closed form, no allocation.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from hptrack.models.motion import position_covariance_after


@numba.njit(cache=True)
def _covered_ratio(cov, q, k, tau, c_per_step, speed, diameter):
    """``S_cover(k) / sqrt(det Sigma^xy(k))`` (dimensionless)."""
    sxx, sxy, syy = position_covariance_after(cov, q, k, tau, c_per_step)
    area = speed * diameter * k * tau + math.pi * 0.25 * diameter * diameter
    return area / math.sqrt(sxx * syy - sxy * sxy)


@numba.njit(cache=True)
def coverage_outcome(cov: np.ndarray, q: float, tau: float, c_per_step: float, speed: float,
                     diameter: float, max_steps: int) -> tuple:
    """Estimated outcome of a coverage starting from covariance ``cov``.

    Args:
        cov: 4x4 belief covariance at the start of the coverage.
        q: process noise intensity (m^2/s^3).
        tau: time step, s.
        c_per_step: lower-right per-step ``Q`` block over ``q`` (``tau`` or ``1``).
        speed: agent speed ``v_a``, m/s.
        diameter: sensor footprint diameter ``w``, m.
        max_steps: coverage steps left in the budget (truncates ``t_cutoff``).

    Returns:
        ``(cutoff_steps, p_find, expected_steps)``: ``t_cutoff`` in steps, ``p_max`` and
        ``E[T_find]`` in steps from the start of the coverage.
    """
    two_pi = 2.0 * math.pi
    k = 0
    ratio = _covered_ratio(cov, q, 0.0, tau, c_per_step, speed, diameter)
    p = -math.expm1(-ratio / two_pi)
    cdf_sum = 0.0  # sum_{j<k} P_cdf(j)
    while k < max_steps:
        next_ratio = _covered_ratio(cov, q, k + 1.0, tau, c_per_step, speed, diameter)
        if next_ratio <= ratio:
            break
        cdf_sum += p
        k += 1
        ratio = next_ratio
        p = -math.expm1(-ratio / two_pi)
    # E[T | T <= K] = sum_k k (P(k) - P(k-1)) / P(K) = (K P(K) - sum_{j<K} P(j)) / P(K)
    expected = (k * p - cdf_sum) / p
    return float(k), p, expected


@numba.njit(cache=True)
def coverage_cdf(cov: np.ndarray, q: float, tau: float, c_per_step: float, speed: float,
                 diameter: float, n_steps: int) -> np.ndarray:
    """``P_cdf(k)`` for ``k = 0 .. n_steps - 1`` (no cutoff applied), for plots and reports."""
    out = np.empty(n_steps)
    for k in range(n_steps):
        ratio = _covered_ratio(cov, q, float(k), tau, c_per_step, speed, diameter)
        out[k] = -math.expm1(-ratio / (2.0 * math.pi))
    return out
