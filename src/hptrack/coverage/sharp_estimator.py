"""A sharper coverage outcome estimator: the paper's sub-task (Sec. IV-A, IV-B) with detections
during the intercept flight and the spiral's real footprint (``docs/coverage-validation.md``,
"The sharp estimator").

The paper's estimator (`hptrack.coverage.estimator.coverage_outcome`, Eqs. (6)-(8)) counts a
target found when it lies, at step ``k`` of the spiral, inside an ellipse of the belief's shape and
of area ``S_cover(k)``. Two things it leaves out make it conservative after a departure delay:

* **The spiral's footprint reaches beyond its mean boundary.** With a belief dominated by its
  velocity uncertainty each target keeps its place in the belief's normalised coordinates
  ``z = Sigma(t)^-1/2 (x - mean)``, so a target is found when the footprint, at *its* pass,
  reaches the target's normalised radius. Where the spiral passed at scale ``s'`` (phase
  ``theta' = s' / b``, loop ellipse ``s'A, s'B``) the footprint's outer edge encloses the
  parallel body of that ellipse at distance ``w/2`` (Steiner's formula)

      S_out(s') = pi A B s'^2 + (w/2) P(A, B) s' + pi (w/2)^2,   P = ellipse perimeter,

  normalised at the time of that pass: ``h_out(s') = S_out(s') / (pi sqrt(det Sigma^xy(t')))``.
  The last pass at each angle happened at a phase uniform in the last turn, ``s' = s - b alpha``
  with ``alpha`` uniform in ``[0, 2 pi)`` (angles the first turn has not reached yet have only
  the start footprint), and a target once reached stays found, so the normalised area found by
  step ``k`` is

      h_F(k) = mean over alpha of  max_{t <= t'(s - b alpha)} h_out(t),

  and ``P_spiral(k) = 1 - exp(-h_F(k) / 2)`` (the chi-squared CDF of Eq. (7) for that area). The
  path length fixes the scale: ``v_a tau k = P s^2 / (4 pi b)``.
* **Detections during the intercept flight.** Relative to the belief mean the agent flies a
  straight line ending on it, ``delta`` metres per step; its footprint sweeps a half-strip of
  width ``w``. In the normalised coordinates at the start of the coverage that is a half-strip
  of half-width ``w_n = (w/2) / sigma_c`` (``sigma_c``: the belief's spread across the line), so
  the flight adds, outside the spiral's disk of radius ``sqrt(h_F)``, the mass

      H(k) = int_{-w_n}^{w_n} phi(y) P(X >= sqrt(h_F - y^2)) dy        (h_F >= w_n^2),

  (a narrower disk adds the annulus ``(e^{-h_F/2} - e^{-w_n^2/2}) / 2``). A target ``xi`` along
  the line (towards the incoming agent) and ``c`` across it is reached ``X = (xi + sqrt((w/2)^2 -
  c^2)) / |delta|`` steps before the coverage starts, so the flight's steps after the find sum to
  ``sum_{m=1}^{n} P(X >= m)`` (Euler-Maclaurin on the closed-form integral, Gauss-Legendre over
  ``c``).

``F(k) = P_spiral(k) + H(k)`` is the probability of a find by step ``k`` of the coverage.
``t_cutoff = K`` is the paper's (Eq. (8)), so the plan and a miss's duration are unchanged; the
find probability is ``F(K)`` and the expected finding time

    E = ((n + K) F(K) - sum_{j<n} F_flight(j) - sum_{k<K} F(k)) / F(K)

is counted in steps from the start of the sub-task (departure), the flight included: the
sub-task's duration given a find. A sensor that detects with a probability below one sweeps the
effective width ``eta w`` (``eta`` its ``find_factor``), as in the paper's estimator
(`hptrack.coverage.estimator`, where the choice of this form is argued): the found mass
``-log(1 - F)`` of every step scales by ``eta``, ``F_eta(k) = 1 - (1 - F(k))^eta``, and the
expected time follows from ``F_eta`` (the flight's sum of ``F_flight`` scaled by ``F_eta(0) /
F(0)``, an approximation); ``t_cutoff`` is unchanged. `sharp_coverage_outcome` is the compiled
kernel (cost
``O(t_cutoff)`` cheap steps plus a fixed number of quadrature evaluations, no allocation);
`estimate_sharp` its validated Python wrapper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from hptrack.coverage.estimator import estimate_coverage, ratio_grows
from hptrack.interface import MissionSpec
from hptrack.models.mission import position_det_on, position_det_rate_on, position_polynomials_on
from hptrack.models.sensor import held_find_share, sensor_find_factor, sensor_hold_looks

PHASE_NODES = 2
"""Gauss-Legendre nodes in the phase of the last pass ``alpha``."""
_ALPHA_X, _ALPHA_W = np.polynomial.legendre.leggauss(PHASE_NODES)
ALPHA_FRACTIONS = 0.5 * (_ALPHA_X + 1.0)
"""Nodes ``alpha / (2 pi)`` in ``[0, 1]``."""
ALPHA_WEIGHTS = 0.5 * _ALPHA_W
"""Their weights (sum 1)."""
_STRIP_X, _STRIP_W = np.polynomial.legendre.leggauss(3)
STRIP_NODES = np.sin(0.25 * math.pi * (_STRIP_X + 1.0))
"""Nodes ``y / w_n = sin(gamma)`` of the strip integral ``H``, Gauss-Legendre in ``gamma`` on
``[0, pi/2]`` (smooth where the disk's edge meets the strip's)."""
STRIP_WEIGHTS = 0.25 * math.pi * _STRIP_W * np.cos(0.25 * math.pi * (_STRIP_X + 1.0))
"""Their weights times ``dy / dgamma / w_n = cos(gamma)``."""
_CROSS_X, _CROSS_W = np.polynomial.legendre.leggauss(6)
CROSS_SINES = np.sin(0.5 * math.pi * _CROSS_X)
"""``c / (w/2) = sin(beta)`` at the Gauss-Legendre nodes ``beta`` of the flight integral."""
CROSS_COSINES = np.cos(0.5 * math.pi * _CROSS_X)
"""``cos(beta)``, the half chord over ``w/2``."""
CROSS_WEIGHTS = 0.5 * math.pi * _CROSS_W
EXACT_STEPS = 8
"""Coverage steps at the start where ``F`` is evaluated at every step."""
GRID_INTERVALS = 16
"""Intervals (of equal whole steps) on which ``F`` is evaluated after them."""

_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


@numba.njit(cache=True, inline="always")
def upper_tail(x):
    """Standard normal ``P(X >= x)``."""
    return 0.5 * math.erfc(x * (1.0 / math.sqrt(2.0)))


@numba.njit(cache=True, inline="always")
def _density(x):
    """Standard normal density."""
    return _INV_SQRT_2PI * math.exp(-0.5 * x * x)


@numba.njit(cache=True)
def ellipse_perimeter(semi_a, semi_b):
    """Perimeter of an ellipse with semi-axes ``semi_a, semi_b`` (m), Ramanujan's second
    approximation (relative error below 4e-5 at every eccentricity)."""
    h = ((semi_a - semi_b) / (semi_a + semi_b)) ** 2
    return math.pi * (semi_a + semi_b) * (1.0 + 3.0 * h / (10.0 + math.sqrt(4.0 - 3.0 * h)))


@numba.njit(cache=True)
def strip_constants(strip_halfwidth):
    """What `strip_mass` needs of a strip of half-width ``w_n``, computed once per
    estimate: ``(w_n, H(w_n^2), e^{-w_n^2/2})`` and the three node weights times ``2 w_n
    phi(y_i)``."""
    w = strip_halfwidth
    factors = (
        2.0 * w * STRIP_WEIGHTS[0] * _density(w * STRIP_NODES[0]),
        2.0 * w * STRIP_WEIGHTS[1] * _density(w * STRIP_NODES[1]),
        2.0 * w * STRIP_WEIGHTS[2] * _density(w * STRIP_NODES[2]),
    )
    edge = math.exp(-0.5 * w * w)
    at_edge = strip_mass(w * w, (w, 0.0, edge, factors[0], factors[1], factors[2]))
    return w, at_edge, edge, factors[0], factors[1], factors[2]


@numba.njit(cache=True)
def strip_mass(h_found, strip):
    """``H``: standard normal mass of the half-strip ``{x >= 0, |y| <= w_n}`` outside the disk
    of radius ``sqrt(h_found)``; ``strip`` from `strip_constants`."""
    w = strip[0]
    if h_found < w * w:  # polar: half of each circle of radius below w_n lies in the strip
        return 0.5 * (math.exp(-0.5 * h_found) - strip[2]) + strip[1]
    # int_{-w_n}^{w_n} phi(y) P(X >= sqrt(h - y^2)) dy
    y0, y1, y2 = w * STRIP_NODES[0], w * STRIP_NODES[1], w * STRIP_NODES[2]
    return (
        strip[3] * upper_tail(math.sqrt(h_found - y0 * y0))
        + strip[4] * upper_tail(math.sqrt(h_found - y1 * y1))
        + strip[5] * upper_tail(math.sqrt(h_found - y2 * y2))
    )


@numba.njit(cache=True)
def _tail_sum(mu, sd, n):
    """``sum_{m=1}^{n} P(X >= m)`` for ``X ~ N(mu, sd^2)``: the Euler-Maclaurin formula on the
    closed-form integral when ``sd >= 1``, else the terms within ``8 sd`` of ``mu`` one by one
    (those below count 1 each)."""
    if sd >= 1.0:
        a0, an = -mu / sd, (n - mu) / sd
        g0, gn = upper_tail(a0), upper_tail(an)
        f0, fn = _density(a0), _density(an)
        integral = sd * ((f0 - a0 * g0) - (fn - an * gn))
        return integral - 0.5 * (g0 - gn) + (f0 - fn) / (12.0 * sd)
    low = max(1, min(n + 1, int(math.floor(mu - 8.0 * sd))))
    high = min(n, int(math.ceil(mu + 8.0 * sd)))
    total = float(low - 1)
    for m in range(low, high + 1):
        total += upper_tail((m - mu) / sd)
    return total


@numba.njit(cache=True)
def flight_detection_sum(cov, flight_steps, approach_x, approach_y, radius):
    """``(sum_{j < n} F_flight(j), sigma_c)``: the expected number of the ``n`` flight steps at
    which the target is already found, and the belief's spread across the flight line (m).
    ``delta = (approach_x, approach_y)`` is the agent's displacement per step relative to the
    belief mean (m), ``cov`` the covariance where the flight ends, ``radius`` ``w/2`` (m)."""
    step = math.hypot(approach_x, approach_y)
    dx, dy = approach_x / step, approach_y / step
    sxx, sxy, syy = cov[0, 0], cov[0, 1], cov[1, 1]
    # xi = -d.e (towards the incoming agent), c = d_perp.e with d_perp = (-dy, dx)
    var_a = dx * dx * sxx + 2.0 * dx * dy * sxy + dy * dy * syy
    var_c = dy * dy * sxx - 2.0 * dx * dy * sxy + dx * dx * syy
    cov_ac = -(-dx * dy * sxx + (dx * dx - dy * dy) * sxy + dx * dy * syy)
    sigma_c = math.sqrt(var_c)
    slope = cov_ac / var_c
    sd = math.sqrt(max(var_a - cov_ac * slope, 0.0)) / step
    total = 0.0
    for i in range(CROSS_SINES.shape[0]):
        c = radius * CROSS_SINES[i]
        half_chord = radius * CROSS_COSINES[i]
        weight = CROSS_WEIGHTS[i] * half_chord * _density(c / sigma_c) / sigma_c
        mu = (slope * c + half_chord) / step  # X = (xi + half_chord) / |delta| ~ N(mu, sd^2)
        total += weight * _tail_sum(mu, sd, flight_steps)
    return total, sigma_c


@numba.njit(cache=True, inline="always")
def _outer_area_ratio(mission, poly, scale, area_ab, perimeter, radius):
    """``h_out``: the parallel body of the loop at ``scale`` over ``pi sqrt(det Sigma^xy)`` at
    the time of that loop, ``scale^2 / scale_rate`` steps into the coverage (``poly`` is the
    motion's position terms and ``scale_rate``)."""
    steps = scale * scale / poly[1]
    area = area_ab * scale * scale + radius * perimeter * scale + math.pi * radius * radius
    return area / (math.pi * math.sqrt(position_det_on(mission, poly[0], steps)))


@numba.njit(cache=True, inline="always")
def _outer_growing(mission, poly, k, area_ab, perimeter, radius):
    """Whether ``h_out`` grows at ``k > 0`` steps: ``2 S_out' det > S_out det'``."""
    rate = poly[1]
    scale = math.sqrt(rate * k)
    area = area_ab * scale * scale + radius * perimeter * scale + math.pi * radius * radius
    area_rate = rate * (area_ab + 0.5 * radius * perimeter / scale)
    det, det_rate = position_det_rate_on(mission, poly[0], k)
    return 2.0 * area_rate * det > area * det_rate


@numba.njit(cache=True)
def _outer_peak(mission, poly, cutoff, area_ab, perimeter, radius):
    """``(t*, h_out(t*))``: where ``h_out`` stops growing within ``t_cutoff`` steps, by bisection
    on the sign of its derivative to 0.05 steps (it rises while the swept area outgrows the
    belief, then falls); ``(inf, 0)`` when it still grows at ``t_cutoff``."""
    if cutoff <= 0.0 or _outer_growing(mission, poly, cutoff, area_ab, perimeter, radius):
        return math.inf, 0.0
    lo, hi = 0.0, cutoff
    while hi - lo > 0.05:
        mid = 0.5 * (lo + hi)
        if _outer_growing(mission, poly, mid, area_ab, perimeter, radius):
            lo = mid
        else:
            hi = mid
    return lo, _outer_area_ratio(mission, poly, math.sqrt(poly[1] * lo), area_ab, perimeter, radius)


@numba.njit(cache=True)
def _found_ratio(
    mission, poly, k, pitch, area_ab, perimeter, radius, peak_steps, peak_ratio, start
):
    """``h_F(k)``: the normalised area found by step ``k`` (module docstring); ``start`` is the
    start footprint's, ``h_out(0)``."""
    scale = math.sqrt(poly[1] * k)
    total = 0.0
    for i in range(ALPHA_FRACTIONS.shape[0]):
        passed = scale - pitch * 2.0 * math.pi * ALPHA_FRACTIONS[i]
        if passed <= 0.0:
            value = start
        elif passed * passed / poly[1] >= peak_steps:
            value = peak_ratio
        else:
            value = _outer_area_ratio(mission, poly, passed, area_ab, perimeter, radius)
        total += ALPHA_WEIGHTS[i] * value
    return total


@numba.njit(cache=True, inline="always")
def swept_share(found, factor):
    """``1 - (1 - F)^eta``: a find probability ``F`` of the footprint's width when the sensor
    sweeps ``eta`` of it (``F`` itself, exactly, when ``eta = 1``)."""
    if factor == 1.0:
        return found
    if found >= 1.0:
        return 1.0
    return -math.expm1(factor * math.log1p(-found))


@numba.njit(cache=True, inline="always")
def _found(
    mission,
    poly,
    k,
    pitch,
    area_ab,
    perimeter,
    radius,
    peak_steps,
    peak_ratio,
    start,
    flight_steps,
    strip,
    share,
):
    """``F(k)``: spiral plus flight strip (times ``share`` when the sensor's draws hold over a
    pass, else as its sweep width says)."""
    h = _found_ratio(
        mission, poly, k, pitch, area_ab, perimeter, radius, peak_steps, peak_ratio, start
    )
    p = -math.expm1(-0.5 * h)
    if flight_steps > 0:
        p += strip_mass(h, strip)
    if sensor_hold_looks(mission.sensor) > 1:
        return share * p
    return swept_share(p, sensor_find_factor(mission.sensor))


@numba.njit(cache=True)
def sharp_coverage_outcome(
    mission,
    cov: np.ndarray,
    q: float,
    max_steps: int,
    flight_steps: int,
    approach_x: float,
    approach_y: float,
) -> tuple:
    """Outcome of a sub-task (intercept flight, then spiral) with the sharp model.

    Args:
        mission: the mission record (time step, agent speed, footprint, ``Q`` form).
        cov: ``d x d`` belief covariance at the start of the coverage (the end of the flight).
        q: process noise intensity (m^2/s^3).
        max_steps: coverage steps left in the budget (truncates ``t_cutoff``); negative when the
            budget ends before the coverage starts.
        flight_steps: whole steps of the intercept flight ``n`` (0: none).
        approach_x, approach_y: the agent's displacement per flight step relative to the belief
            mean, m (`hptrack.coverage.intercept.approach_step`); unused when ``n = 0``.

    Returns:
        ``(cutoff_steps, p_find, expected_steps)``: the paper's ``t_cutoff`` in steps from the
        start of the coverage, the probability of a find by then (flight included; the
        sensor's ``find_factor`` applied, module docstring), and the
        expected duration of the sub-task given a find, in steps from its start (departure);
        ``(0, 0, 0)`` when ``max_steps < 0``.
    """
    if max_steps < 0:
        return 0.0, 0.0, 0.0
    terms = position_polynomials_on(mission, cov, q)
    x0, y0, c0 = terms[0], terms[3], terms[6]  # the position covariance now
    speed, tau, diameter = mission.vehicle.speed, mission.time_step, mission.sensor.diameter
    radius = 0.5 * diameter
    tr = 0.5 * (x0 + y0)
    gap = math.sqrt(max(tr * tr - (x0 * y0 - c0 * c0), 0.0))
    semi_a, semi_b = math.sqrt(tr + gap), math.sqrt(max(tr - gap, 0.0))
    pitch = diameter / (2.0 * math.pi * semi_a)  # b of Eq. (4)
    perimeter = ellipse_perimeter(semi_a, semi_b)
    area_ab = math.pi * semi_a * semi_b
    # path length v_a tau k = P s^2 / (4 pi b): s^2 = scale_rate k
    poly = (terms, 4.0 * math.pi * pitch * speed * tau / perimeter)
    # The paper's t_cutoff (Eq. (8)), step by step with coverage_outcome's arithmetic.
    area1 = speed * diameter * tau  # S_cover(k) = area + k area1
    area = math.pi * radius * radius
    det = x0 * y0 - c0 * c0
    k = 0
    while k < max_steps:
        next_det = position_det_on(mission, terms, k + 1.0)
        next_area = area + area1
        if not ratio_grows(area, det, next_area, next_det):
            break
        k += 1
        area = next_area
        det = next_det
    cutoff = k
    peak_steps, peak_ratio = _outer_peak(mission, poly, float(cutoff), area_ab, perimeter, radius)
    # The flight: its detections' time sum and the strip's width.
    flight_sum = 0.0
    strip = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if flight_steps > 0:
        flight_sum, sigma_c = flight_detection_sum(
            cov, flight_steps, approach_x, approach_y, radius
        )
        strip = strip_constants(radius / sigma_c)
    # F on a grid; sum_{k < K} F(k) by linear interpolation between its points, less the
    # curvature term F'' L (L^2 - 1) / 12 of each interval of L steps (F'' from its neighbours).
    spacing = max(1, -(-(cutoff - EXACT_STEPS) // GRID_INTERVALS))
    at, before = 0, 0
    start = _outer_area_ratio(mission, poly, 0.0, area_ab, perimeter, radius)
    share = held_find_share(mission.sensor, cov, speed)
    found = _found(
        mission,
        poly,
        0.0,
        pitch,
        area_ab,
        perimeter,
        radius,
        peak_steps,
        peak_ratio,
        start,
        flight_steps,
        strip,
        share,
    )
    factor = sensor_find_factor(mission.sensor)
    if sensor_hold_looks(mission.sensor) > 1:  # F_flight sum to the held draws' share of it
        flight_sum *= share
    elif factor != 1.0 and flight_steps > 0 and 0.0 < found < 1.0:  # F_flight sum to F_eta's
        flight_sum *= found / -math.expm1(math.log1p(-found) / factor)
    previous = found
    coverage_sum = 0.0
    while at < cutoff:
        length = min(1 if at < EXACT_STEPS else spacing, cutoff - at)
        nxt = _found(
            mission,
            poly,
            float(at + length),
            pitch,
            area_ab,
            perimeter,
            radius,
            peak_steps,
            peak_ratio,
            start,
            flight_steps,
            strip,
            share,
        )
        coverage_sum += length * found + 0.5 * (nxt - found) * (length - 1)
        if length > 1 and before > 0:
            second = (
                2.0 * ((nxt - found) / length - (found - previous) / before) / (length + before)
            )
            coverage_sum -= second * length * (length * length - 1) / 12.0
        previous, found, before = found, nxt, length
        at += length
    total = float(flight_steps + cutoff)
    expected = (total * found - flight_sum - coverage_sum) / found
    return float(cutoff), found, expected


@dataclass(frozen=True)
class SharpEstimate:
    """Outcome of one sub-task (intercept flight, then spiral) by the sharp estimator.

    Attributes:
        flight_steps: whole steps of the intercept flight ``n``.
        cutoff_steps: the paper's ``t_cutoff`` in steps from the start of the coverage (truncated
            by the budget when ``budget_limited``).
        p_find: probability of a find by ``t_cutoff``, the flight included; 0 when the budget
            ends before the coverage starts.
        expected_time: expected duration of the sub-task given a find, s from its start
            (departure), the flight included.
        time_step: ``tau``, s.
        budget_limited: whether the budget ended before the unconstrained ``t_cutoff``.
    """

    flight_steps: int
    cutoff_steps: int
    p_find: float
    expected_time: float
    time_step: float
    budget_limited: bool

    @property
    def expected_steps(self) -> float:
        """Expected duration given a find, steps from departure."""
        return self.expected_time / self.time_step

    @property
    def miss_steps(self) -> int:
        """Duration of the sub-task without a find: flight plus ``t_cutoff``, steps."""
        return self.flight_steps + self.cutoff_steps


def estimate_sharp(
    covariance: np.ndarray,
    q: float,
    mission: MissionSpec,
    flight_steps: int,
    approach: tuple[float, float] | np.ndarray,
    remaining_time: float | None = None,
) -> SharpEstimate:
    """The sharp estimate of a sub-task whose coverage starts from ``covariance`` after an
    intercept flight of ``flight_steps`` steps, ``approach`` (m) per step relative to the belief
    mean (`hptrack.coverage.intercept.approach_step`).

    ``remaining_time`` is the budget left when the coverage starts (s; ``None``: no budget), as
    for `hptrack.coverage.estimator.estimate_coverage`, whose checks and ``t_cutoff`` this
    shares.

    Raises:
        ValueError: what `estimate_coverage` refuses, a negative flight, or an approach
            that is not two finite numbers (non-zero when there is a flight).
    """
    paper = estimate_coverage(covariance, q, mission, remaining_time)
    steps = int(flight_steps)
    step = np.asarray(approach, dtype=float)
    if steps < 0 or steps != flight_steps:
        raise ValueError(f"flight_steps must be a non-negative integer, got {flight_steps!r}")
    if step.shape != (2,) or not np.all(np.isfinite(step)) or (steps > 0 and not np.any(step)):
        raise ValueError(
            f"approach must be two finite numbers (m per step, non-zero with a "
            f"flight), got {approach!r}"
        )
    tau = mission.time_step
    if remaining_time is not None and remaining_time < 0.0:
        return SharpEstimate(steps, 0, 0.0, 0.0, tau, True)
    cutoff, p_find, expected = sharp_coverage_outcome(
        mission.record,
        np.asarray(covariance, dtype=float),
        float(q),
        paper.cutoff_steps,
        steps,
        float(step[0]),
        float(step[1]),
    )
    return SharpEstimate(
        steps, int(cutoff), float(p_find), float(expected) * tau, tau, paper.budget_limited
    )
