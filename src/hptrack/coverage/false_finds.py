"""False finds: a coverage sub-task that ends on a false alarm instead of its target.

Under clutter (``lambda`` false detections per m^2 per look, Poisson, uniform over the
footprint) the tracker of detections without identity (`hptrack.models.tracking`) takes a
false alarm ``z`` for the pursued belief ``N(m, P)`` when the report lies in the belief's gate
(``d^2 <= gamma``, ``d`` its Mahalanobis distance under ``S = P_xy + R``) and its likelihood
ratio beats "no detection from the belief": ``Pd N(z; m, S) / lambda > 1 - Pd P_in P_G``. That
region is the ellipse ``d^2 < r^2``,

    r^2 = min(gamma, 2 ln(N_max / kappa)),  N_max = 1 / (2 pi sqrt(det S)),
    kappa = lambda (1 - P_in P_G),

of area ``pi r^2 sqrt(det S)`` (none when ``N_max <= kappa``: a belief so wide that no report
beats the clutter), with ``Pd`` taken as 1 and ``P_in`` the chance that the target lies in a
footprint centred on the mean, ``1 - exp(-rho^2 / (2 sqrt(det P_xy)))`` (``rho`` the footprint's
radius; the circle of the same determinant). While the spiral flies over the belief, a look
takes a false alarm at the rate `take_rate`: ``lambda`` times the area of the footprint inside
the region, at most the smaller of the two.

A sub-task whose estimate (`hptrack.coverage.estimator`) is a find after ``T_f`` looks of search
with probability ``p`` and otherwise a miss after ``T_c`` then has three outcomes, the takes a
Poisson stream of ``mu`` per look competing with the find (`false_find_split`):

* find: ``p e^(-mu T_f)``;
* miss: ``(1 - p) e^(-mu T_c)``;
* false find: the rest, after the first take, ``E[t | t < T] = 1/mu - T e^(-mu T) / (1 -
  e^(-mu T))`` looks of search, mixed over the two ``T`` by their shares.
"""

from __future__ import annotations

import math

import numba

from hptrack.models.tracking import GATE_PROBABILITY

GATE = -2.0 * math.log(1.0 - GATE_PROBABILITY)
"""``gamma``: the tracker's gate, the squared Mahalanobis distance that holds ``P_G`` of a 2-D
report (``chi2_2^-1(P_G) = -2 ln(1 - P_G)``)."""


@numba.njit(cache=True)
def take_rate(density, radius, sxx, sxy, syy, rxx, rxy, ryy):
    """``mu``: the false alarms a look takes for a belief of position covariance ``[[sxx, sxy],
    [sxy, syy]]`` (m^2) under the footprint of ``radius`` m centred on its mean, with clutter
    ``density`` per m^2 per look and measurement noise ``[[rxx, rxy], [rxy, ryy]]`` (m^2)
    (module docstring)."""
    if density <= 0.0:
        return 0.0
    det_p = max(sxx * syy - sxy * sxy, 0.0)
    inside = 1.0 - math.exp(-radius * radius / (2.0 * math.sqrt(det_p))) if det_p > 0.0 else 1.0
    kappa = density * (1.0 - inside * GATE_PROBABILITY)
    det_s = (sxx + rxx) * (syy + ryy) - (sxy + rxy) * (sxy + rxy)
    peak = 1.0 / (2.0 * math.pi * math.sqrt(det_s))
    if peak <= kappa:
        return 0.0
    r2 = min(GATE, 2.0 * math.log(peak / kappa))
    region = math.pi * r2 * math.sqrt(det_s)
    return density * min(region, math.pi * radius * radius)


@numba.njit(cache=True, inline="always")
def _taken_share(rate, looks):
    """``1 - e^(-mu T)``: the chance of a take in ``looks`` looks."""
    return -math.expm1(-rate * looks)


@numba.njit(cache=True, inline="always")
def _mean_take(rate, looks):
    """``E[t | t < T]``, looks: the time of the first take given one in ``looks``."""
    share = _taken_share(rate, looks)
    if share < 1e-12:
        return 0.5 * looks
    return 1.0 / rate - looks * math.exp(-rate * looks) / share


@numba.njit(cache=True)
def false_find_split(p_find, find_looks, miss_looks, rate):
    """``(p_find', p_miss', p_false, false_looks)``: a sub-task's find (after ``find_looks``
    looks of search, probability ``p_find``) and miss (after ``miss_looks``) split by takes at
    ``rate`` per look into find, miss and false find, and the mean looks of search before the
    false find (module docstring)."""
    if rate <= 0.0:
        return p_find, 1.0 - p_find, 0.0, 0.0
    taken_find = _taken_share(rate, find_looks)
    taken_miss = _taken_share(rate, miss_looks)
    false_by_find = p_find * taken_find
    false_by_miss = (1.0 - p_find) * taken_miss
    p_false = false_by_find + false_by_miss
    if p_false <= 0.0:
        return p_find, 1.0 - p_find, 0.0, 0.0
    looks = (
        false_by_find * _mean_take(rate, find_looks) + false_by_miss * _mean_take(rate, miss_looks)
    ) / p_false
    return p_find * (1.0 - taken_find), (1.0 - p_find) * (1.0 - taken_miss), p_false, looks
