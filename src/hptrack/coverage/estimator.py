"""Coverage outcome estimator (paper Sec. IV-B, Eqs. (6)-(8); ``docs/model.md``).

During a spiral coverage that starts from the belief covariance ``Sigma`` (4x4) the covered area
grows linearly, ``S_cover(k) = v_a w k tau + pi (w/2)^2``, while the position covariance grows
as Eq. (1). The probability of having found the target by step ``k`` of the coverage is the
chi-squared CDF with 2 degrees of freedom,

    P_cdf(k) = 1 - exp(-S_cover(k) / (2 pi sqrt(det Sigma^xy(k)))).

``t_cutoff`` is the first step after which ``P_cdf`` stops increasing, ``p_max = P_cdf(t_cutoff)``
and ``E[T_find]`` is the expected finding time given the target is found by ``t_cutoff``,
measured from the start of the coverage. When the remaining budget ends first, everything is
truncated at the budget's end.

A sensor that detects a target inside its footprint with a probability below one
(`hptrack.models.sensor.DetectingFootprintSensor`) sweeps an effective width ``W = eta w``
instead of ``w`` (``eta`` its ``find_factor``, `hptrack.models.sensor.pass_detection_factor`:
the integral over the lateral offset of one straight pass's chance of a detection, over the same
with certain detection). The covered area becomes ``eta S_cover(k)``:

    P_cdf(k) = 1 - exp(-eta S_cover(k) / (2 pi sqrt(det Sigma^xy(k)))),

``t_cutoff`` is unchanged (``eta`` does not change where ``S_cover / sqrt(det)`` stops growing) and
``E[T_find]`` follows from this CDF. The other form, ``p_max = eta P_cdf(t_cutoff)`` with
``E[T_find]`` unchanged (one pass reaches a target and detects it with ``eta``, a miss is final),
is rejected: the spiral's passes overlap (its loops are ``w`` apart along the belief's major axis,
closer along the minor one, and the targets drift across them), so a target one pass missed is
often detected by the next, and the Monte Carlo of the spiral finds about as much more as the
sweep-width form says (``docs/model.md``, "Sensor and measurement"). A constant per-step ``Pd =
p`` is not ``W = p w``: a target near a pass's line is inside the footprint for about ``w / (v_a
tau)`` looks and is all but surely detected. With the paper's sensor ``eta = 1`` and every number
is what it was, bit for bit.

A detector whose draws hold over consecutive looks (``hold_looks > 1``: misses that come in
runs) detects a target at most once per pass, whatever the pass's length: the passes, not the
looks, are the independent trials. Its ``find_factor`` is then one pass's chance of a detection,
and the chance of a find is ``P_cdf`` of the footprint's width times the share of covered targets
that some pass over them detects (`hptrack.models.sensor.repeat_pass_share`: the spiral's loops
overlap by a factor that depends on the belief's axis ratio); ``t_cutoff`` and ``E[T_find]`` are
those of the certain sensor.

`coverage_outcome` is the compiled kernel used by the tree search: O(t_cutoff) arithmetic
with the covariance in closed form (for constant velocity polynomials in the step count; for
other belief motions the motion's own terms, `hptrack.models.mission.position_det_on`), one
root and one exponential per step, no allocation. `estimate_coverage` is its validated
Python wrapper, returning a `CoverageEstimate` in seconds with the CDF.

Under random walk and Ornstein-Uhlenbeck beliefs the position covariance grows linearly in
time in the long run (``D t`` per axis, ``q t / K^2`` for Ornstein-Uhlenbeck) while ``S_cover``
does too, so ``S_cover / sqrt(det)`` tends to a finite limit and ``P_cdf`` stays below
``1 - exp(-v_a w / (2 pi D))`` (``D = q / K^2``) however long the coverage: ``p_max < 1``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from hptrack.interface import MissionSpec
from hptrack.models.mission import (
    position_covariance_on,
    position_det_on,
    position_polynomials_on,
    steps_left,
)
from hptrack.models.sensor import held_find_share, sensor_find_factor, sensor_hold_looks

MAX_COVERAGE_STEPS = 10_000_000
"""Cap on ``t_cutoff`` when no budget is given; reaching it means the belief does not grow."""


@numba.njit(cache=True, inline="always")
def ratio_grows(area, det, next_area, next_det):
    """Whether ``S_cover / sqrt(det)`` still grows from one step to the next (the ``t_cutoff``
    test of Eq. (8)), without roots or divisions."""
    return next_area * next_area * det > area * area * next_det


@numba.njit(cache=True)
def _covered_ratio(mission, cov, q, k):
    """``S_cover(k) / sqrt(det Sigma^xy(k))`` (dimensionless; the footprint's, without the
    sensor's ``find_factor``)."""
    sxx, sxy, syy = position_covariance_on(mission, cov, q, k)
    speed, diameter, tau = mission.vehicle.speed, mission.sensor.diameter, mission.time_step
    area = speed * diameter * k * tau + math.pi * 0.25 * diameter * diameter
    return area / math.sqrt(sxx * syy - sxy * sxy)


@numba.njit(cache=True)
def coverage_outcome(mission, cov: np.ndarray, q: float, max_steps: int) -> tuple:
    """Estimated outcome of a coverage starting from covariance ``cov``.

    Args:
        mission: the mission record (time step, agent speed, footprint, ``Q`` form).
        cov: ``d x d`` belief covariance at the start of the coverage.
        q: process noise intensity (m^2/s^3).
        max_steps: coverage steps left in the budget (truncates ``t_cutoff``); negative when the
            budget ends before the coverage starts.

    Returns:
        ``(cutoff_steps, p_find, expected_steps)``: ``t_cutoff`` in steps, ``p_max`` and
        ``E[T_find]`` in steps from the start of the coverage (the covered area times the
        sensor's ``find_factor``, 1 for the paper's); ``(0, 0, 0)`` when ``max_steps < 0``.
    """
    if max_steps < 0:
        return 0.0, 0.0, 0.0
    poly = position_polynomials_on(mission, cov, q)
    x0, y0, c0 = poly[0], poly[3], poly[6]  # the position covariance now
    speed, diameter, tau = mission.vehicle.speed, mission.sensor.diameter, mission.time_step
    area0 = math.pi * 0.25 * diameter * diameter  # S_cover(k) = area0 + k area1
    area1 = speed * diameter * tau
    inv_two_pi = 1.0 / (2.0 * math.pi)
    factor = sensor_find_factor(mission.sensor)  # W / w (1: the paper's sensor, exactly)
    share = held_find_share(mission.sensor, cov, speed)  # draws held over a pass: P x share
    if sensor_hold_looks(mission.sensor) > 1:
        factor = 1.0
    k = 0
    area = area0
    det = x0 * y0 - c0 * c0
    cdf_sum = 0.0  # sum_{j<k} P_cdf(j)
    while k < max_steps:
        next_det = position_det_on(mission, poly, k + 1.0)
        next_area = area + area1
        if not ratio_grows(area, det, next_area, next_det):
            break
        cdf_sum -= math.expm1(-(factor * area) * inv_two_pi / math.sqrt(det))
        k += 1
        area = next_area
        det = next_det
    p = -math.expm1(-(factor * area) * inv_two_pi / math.sqrt(det))
    # E[T | T <= K] = sum_k k (P(k) - P(k-1)) / P(K) = (K P(K) - sum_{j<K} P(j)) / P(K)
    expected = (k * p - cdf_sum) / p
    return float(k), share * p, expected


@numba.njit(cache=True)
def coverage_cdf(mission, cov: np.ndarray, q: float, n_steps: int) -> np.ndarray:
    """``P_cdf(k)`` for ``k = 0 .. n_steps - 1`` (no cutoff applied; the covered area times the
    sensor's ``find_factor``, 1 for the paper's), for plots and reports."""
    out = np.empty(n_steps)
    factor = sensor_find_factor(mission.sensor)
    share = held_find_share(mission.sensor, cov, mission.vehicle.speed)
    if sensor_hold_looks(mission.sensor) > 1:
        factor = 1.0
    for k in range(n_steps):
        ratio = factor * _covered_ratio(mission, cov, q, float(k))
        out[k] = -share * math.expm1(-ratio / (2.0 * math.pi))
    return out


@dataclass(frozen=True, eq=False)
class CoverageEstimate:
    """Estimated outcome of one spiral coverage (Sec. IV-B).

    Attributes:
        cutoff_steps: ``t_cutoff`` in steps from the start of the coverage (truncated by the
            budget when ``budget_limited``).
        p_find: ``p_max = P_cdf(t_cutoff)``; 0 when the budget ends before the coverage
            starts.
        expected_time: ``E[T_find]`` given the target is found by ``t_cutoff``, s from the start
            of the coverage.
        cdf: ``P_cdf(k)`` for ``k = 0 .. cutoff_steps`` (empty when the coverage never starts).
        time_step: ``tau``, s.
        budget_limited: whether the remaining budget ended before the unconstrained ``t_cutoff``.
    """

    cutoff_steps: int
    p_find: float
    expected_time: float
    cdf: np.ndarray
    time_step: float
    budget_limited: bool

    @property
    def cutoff_time(self) -> float:
        """``t_cutoff`` in s from the start of the coverage."""
        return self.cutoff_steps * self.time_step

    @property
    def expected_steps(self) -> float:
        """``E[T_find]`` in steps."""
        return self.expected_time / self.time_step


def check_state_covariance(covariance: np.ndarray) -> np.ndarray:
    """A finite, symmetric, positive semi-definite ``d x d`` covariance (``d`` 4 or 6, a state
    with accelerations) whose 2x2 position block is positive definite, as a float array.

    Raises:
        ValueError: naming what is wrong.
    """
    cov = np.asarray(covariance, dtype=float)
    if cov.shape not in ((4, 4), (6, 6)) or not np.all(np.isfinite(cov)):
        raise ValueError(f"covariance must be a finite 4x4 or 6x6 matrix, got {cov.tolist()}")
    scale = max(float(np.max(np.abs(cov))), 1.0)
    if np.max(np.abs(cov - cov.T)) > 1e-9 * scale:
        raise ValueError(f"covariance is not symmetric: {cov.tolist()}")
    if np.min(np.linalg.eigvalsh(cov)) < -1e-9 * scale:
        raise ValueError(f"covariance is not positive semi-definite: {cov.tolist()}")
    det = cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0]
    if not (cov[0, 0] > 0.0 and det > 1e-12 * cov[0, 0] * cov[1, 1]):
        raise ValueError(
            "position covariance is not positive definite "
            f"({cov[:2, :2].tolist()} m^2): the belief ellipse is degenerate"
        )
    return cov


def estimate_coverage(
    covariance: np.ndarray, q: float, mission: MissionSpec, remaining_time: float | None = None
) -> CoverageEstimate:
    """Estimate the outcome of a spiral coverage starting from ``covariance`` (Sec. IV-B).

    Args:
        covariance: 4x4 belief covariance when the coverage starts (m, m/s).
        q: process noise intensity, m^2/s^3.
        mission: the mission constants (agent speed, footprint, time step, ``Q`` form).
        remaining_time: budget left when the coverage starts, s; ``None`` for no budget. When it
            ends before ``t_cutoff`` the estimate is ``P_cdf`` at the budget's end; when it is
            negative the coverage never starts and ``p_find = 0``.

    Raises:
        ValueError: bad covariance, ``q`` or ``remaining_time``, or (without a budget) a belief
            that does not grow, so that ``P_cdf`` never stops rising.
    """
    cov = check_state_covariance(covariance)
    if not (math.isfinite(q) and q >= 0.0):
        raise ValueError(f"process noise q must be a non-negative finite number, got {q!r}")
    record = mission.record
    tau = record.time_step
    if remaining_time is None:
        max_steps = MAX_COVERAGE_STEPS
    elif math.isnan(remaining_time):
        raise ValueError("remaining_time is NaN")
    elif remaining_time < 0.0:
        return CoverageEstimate(0, 0.0, 0.0, np.zeros(0), tau, True)
    else:
        max_steps = min(steps_left(tau, remaining_time), MAX_COVERAGE_STEPS)
    cutoff, p_find, expected = coverage_outcome(record, cov, float(q), max_steps)
    cutoff = int(cutoff)
    limited = cutoff == max_steps and _covered_ratio(
        record, cov, float(q), cutoff + 1.0
    ) > _covered_ratio(record, cov, float(q), float(cutoff))
    if limited and remaining_time is None:
        raise ValueError(
            f"P_cdf still rises after {MAX_COVERAGE_STEPS} steps: the belief does "
            "not grow (zero velocity variance and q = 0?), so t_cutoff is undefined"
        )
    cdf = coverage_cdf(record, cov, float(q), cutoff + 1)
    return CoverageEstimate(cutoff, float(p_find), float(expected) * tau, cdf, tau, bool(limited))
