"""Negative information: the belief after a look that saw nothing (beyond the paper, which
uses none, Sec. III).

A look from the agent at ``a`` covers the footprint disc ``|p - a| <= w/2`` and detects a
target inside at the distance ``d = |p - a|`` with probability ``Pd(d)``
(`hptrack.models.measurement.table_probability`). A look that detects nothing multiplies a
Gaussian belief ``N(mu, P)`` by the likelihood ``g(p) = 1 - Pd(|p - a|) 1[|p - a| <= w/2]``
of the position alone. `miss_update` moment-matches that posterior:

* position: ``Z = E[g]``, ``m = E[p g] / Z``, ``C = E[(p - m)(p - m)' g] / Z`` by a quadrature
  in the whitened position ``u = L^-1 (p - mu_p)`` (``L L' = P_pp``), polar about the mean:
  along each ray the disc is one interval of the radius ``s`` (a quadratic's roots), integrated
  by Gauss-Legendre against ``s e^(-s^2/2) / 2 pi``. A mean outside the disc takes the rays
  between the disc's two tangents (Chebyshev-spaced); its removed mass is at most 1/2, so
  ``1 - removed`` loses no precision. A mean inside the disc takes every direction, and each
  ray's part beyond the disc in closed form (``int_s^inf t^k e^(-t^2/2) dt``, ``k = 1, 2, 3``),
  so ``Z`` keeps its digits when the disc removes nearly all the mass.
* the rest of the state (velocity, acceleration) by the linear-Gaussian regression on the
  position (`condition_on_position`): ``E[v | p] = mu_v + K (p - mu_p)``,
  ``K = P_vp P_pp^-1``, so ``mu_v += K (m - mu_p)``, ``P_vp <- K C``,
  ``P_vv += K (C - P_pp) K'``.

A disc more than `FAR_SIGMAS` standard deviations (the largest) from the mean changes nothing.
The likelihood is floored, ``g + MASS_FLOOR`` (so ``Z >= MASS_FLOOR``): a miss that the belief
says could not happen (a certain detector over all its mass) leaves the belief all but as it
was instead of dividing by nothing; elsewhere the floor changes the moments by about
``1e-9 / Z``.

The closed form (`centred_miss_scale`): a disc of Mahalanobis radius ``r`` centred on the mean,
``a = r^2 / 2`` and a constant ``Pd = p``: the mean is unchanged and the position covariance
scales by (before the floor) ``c = [2 - p (2 - e^-a (2a + 2))] / (2 (1 - p (1 - e^-a)))``
(``1 + a`` at ``p = 1``): in whitened polar coordinates ``Z = 1 - p (1 - e^-a)`` and
``E[|u|^2 g] = 2 - p int_0^r s^3 e^(-s^2/2) ds = 2 - p (2 - e^-a (2a + 2))``, each axis
carrying half. It is `miss_update`'s answer for a circular belief centred in the footprint
(the tests check one against the other); the sub-task MDP's miss branch uses it
(`hptrack.planning.subtask_mdp`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from hptrack.models.measurement import table_probability

FAR_SIGMAS = 8.0
"""A disc whose nearest point is farther than this many standard deviations (of the position
covariance's major axis) from the mean leaves the belief as it is."""
MASS_FLOOR = 1e-9
"""The floor of a miss's likelihood ``g`` (so of the remaining mass ``Z``)."""
RADIAL_NODES = 16
"""Gauss-Legendre nodes along each ray inside the disc."""
ANGLES = 64
"""Rays of the quadrature."""
MAX_RADIUS = 9.0
"""Whitened radius beyond which the quadrature inside the disc stops (mass ``< 1e-17``)."""

_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(RADIAL_NODES)
_NODES.flags.writeable = False
_WEIGHTS.flags.writeable = False
_SQRT_HALF_PI = math.sqrt(0.5 * math.pi)
_INV_2PI = 1.0 / (2.0 * math.pi)


@numba.njit(cache=True)
def condition_covariance(cov, cxx, cxy, cyy):
    """Set a covariance's position block to ``C = [[cxx, cxy], [cxy, cyy]]`` (m^2) and the rest
    by the regression on the position (module docstring), in place."""
    d = cov.shape[0]
    sxx, sxy, syy = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[1, 1]
    det = sxx * syy - sxy * sxy
    ixx, ixy, iyy = syy / det, -sxy / det, sxx / det
    ex, exy, ey = cxx - sxx, cxy - sxy, cyy - syy  # C - P_pp
    for i in range(2, d):
        ki0 = cov[i, 0] * ixx + cov[i, 1] * ixy
        ki1 = cov[i, 0] * ixy + cov[i, 1] * iyy
        for j in range(i, d):
            kj0 = cov[j, 0] * ixx + cov[j, 1] * ixy
            kj1 = cov[j, 0] * ixy + cov[j, 1] * iyy
            v = cov[i, j] + ki0 * (ex * kj0 + exy * kj1) + ki1 * (exy * kj0 + ey * kj1)
            cov[i, j] = v
            cov[j, i] = v
    for i in range(2, d):  # the cross terms last: the loop above read the old ones
        ki0 = cov[i, 0] * ixx + cov[i, 1] * ixy
        ki1 = cov[i, 0] * ixy + cov[i, 1] * iyy
        c0 = ki0 * cxx + ki1 * cxy
        c1 = ki0 * cxy + ki1 * cyy
        cov[i, 0] = c0
        cov[0, i] = c0
        cov[i, 1] = c1
        cov[1, i] = c1
    cov[0, 0] = cxx
    cov[0, 1] = cxy
    cov[1, 0] = cxy
    cov[1, 1] = cyy


@numba.njit(cache=True)
def condition_on_position(mean, cov, mx, my, cxx, cxy, cyy):
    """Set a belief's position moments to ``m = (mx, my)`` (m) and ``C`` (m^2,
    `condition_covariance`) and the other components by the regression on the position
    (module docstring), in place: a likelihood of the position alone leaves ``p(v | p)`` as
    it was."""
    sxx, sxy, syy = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[1, 1]
    det = sxx * syy - sxy * sxy
    ixx, ixy, iyy = syy / det, -sxy / det, sxx / det
    dx, dy = mx - mean[0], my - mean[1]
    for i in range(2, mean.shape[0]):
        ki0 = cov[i, 0] * ixx + cov[i, 1] * ixy
        ki1 = cov[i, 0] * ixy + cov[i, 1] * iyy
        mean[i] += ki0 * dx + ki1 * dy
    mean[0] = mx
    mean[1] = my
    condition_covariance(cov, cxx, cxy, cyy)


@numba.njit(cache=True, inline="always")
def _chord(cx, cy, wx, wy, k):
    """The radii ``s`` where the ray ``c + s w`` (relative to the disc's centre) crosses the
    disc's edge, ``k = |c|^2 - R^2``: ``(s1, s2)``, ``s1 > s2`` when it does not."""
    ww = wx * wx + wy * wy
    cw = cx * wx + cy * wy
    disc = cw * cw - ww * k
    if disc < 0.0:
        return 1.0, 0.0
    root = math.sqrt(disc)
    return (-cw - root) / ww, (-cw + root) / ww


@numba.njit(cache=True)
def _ray(cx, cy, wx, wy, lo, hi, distances, probabilities, keep):
    """``(int Pd s^(k+1) phi ds)`` for ``k = 0, 1, 2`` over ``[lo, hi]`` on the ray ``c + s w``
    (Gauss-Legendre; ``keep``: of ``1 - Pd`` instead), ``phi = e^(-s^2/2) / 2 pi``."""
    half = 0.5 * (hi - lo)
    mid = 0.5 * (hi + lo)
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    for q in range(RADIAL_NODES):
        s = mid + half * _NODES[q]
        pd = table_probability(distances, probabilities, math.hypot(cx + s * wx, cy + s * wy))
        f = (1.0 - pd) if keep else pd
        w = _WEIGHTS[q] * half * f * s * math.exp(-0.5 * s * s) * _INV_2PI
        m0 += w
        m1 += w * s
        m2 += w * s * s
    return m0, m1, m2


@numba.njit(cache=True)
def miss_update(mean, cov, agent_x, agent_y, radius, distances, probabilities):
    """The belief ``(mean, cov)`` (a state ``(d,)`` with the position first, m, and ``(d, d)``)
    after a look from ``(agent_x, agent_y)`` (m) over a disc of ``radius`` m, detecting with
    ``Pd(d)`` of the table ``(distances, probabilities)``, saw nothing: moment-matched, in place
    (module docstring)."""
    sxx, sxy, syy = cov[0, 0], 0.5 * (cov[0, 1] + cov[1, 0]), cov[1, 1]
    cx, cy = mean[0] - agent_x, mean[1] - agent_y  # the mean from the disc's centre
    dist2 = cx * cx + cy * cy
    k = dist2 - radius * radius
    major = 0.5 * (sxx + syy) + math.sqrt(0.25 * (sxx - syy) ** 2 + sxy * sxy)
    gap = math.sqrt(dist2) - radius
    if gap > FAR_SIGMAS * math.sqrt(major):
        return
    l11 = math.sqrt(sxx)
    l21 = sxy / l11
    r22 = syy - l21 * l21
    if not (l11 > 0.0 and r22 > 0.0):
        return
    l22 = math.sqrt(r22)
    # whitened moments of g: z = E[g], (ux, uy) = E[u g], (uxx, uxy, uyy) = E[u u' g]
    z = 0.0
    ux = 0.0
    uy = 0.0
    uxx = 0.0
    uxy = 0.0
    uyy = 0.0
    if k < 0.0:  # the mean inside the disc: every ray, g integrated directly
        step = 2.0 * math.pi / ANGLES
        for j in range(ANGLES):
            phi = (j + 0.5) * step
            ex, ey = math.cos(phi), math.sin(phi)
            wx, wy = l11 * ex, l21 * ex + l22 * ey
            s2 = _chord(cx, cy, wx, wy, k)[1]
            top = min(s2, MAX_RADIUS)
            m0, m1, m2 = _ray(cx, cy, wx, wy, 0.0, top, distances, probabilities, True)
            e2 = math.exp(-0.5 * s2 * s2)
            t1 = e2
            t2 = s2 * e2 + _SQRT_HALF_PI * math.erfc(s2 / math.sqrt(2.0))
            t3 = (s2 * s2 + 2.0) * e2
            m0 += t1 * _INV_2PI
            m1 += t2 * _INV_2PI
            m2 += t3 * _INV_2PI
            z += m0 * step
            ux += m1 * ex * step
            uy += m1 * ey * step
            uxx += m2 * ex * ex * step
            uxy += m2 * ex * ey * step
            uyy += m2 * ey * ey * step
    else:  # the mean outside: the rays between the tangents, the removed mass subtracted
        # the disc's centre in whitened coordinates, u_c = L^-1 (a - mu_p)
        vx = -cx / l11
        vy = (-cy - l21 * vx) / l22
        centre = math.atan2(vy, vx)
        # tangent rays: (c.Le)^2 - k |Le|^2 = 0, a quadratic form e'Me in the direction e
        bx, by = l11 * cx + l21 * cy, l22 * cy  # L' c
        m11 = bx * bx - k * (l11 * l11 + l21 * l21)
        m12 = bx * by - k * (l21 * l22)
        m22 = by * by - k * (l22 * l22)
        a2 = 0.5 * (m11 - m22)
        c0 = 0.5 * (m11 + m22)
        rho = math.hypot(a2, m12)
        delta = math.atan2(m12, a2)
        alpha = math.acos(min(1.0, max(-1.0, -c0 / rho))) if rho > 0.0 else 0.5 * math.pi
        lo = math.pi
        hi = -math.pi
        for phi in (0.5 * (delta + alpha), 0.5 * (delta - alpha)):
            # each root is a tangent up to pi: take the one whose ray runs towards the disc
            if cx * (l11 * math.cos(phi)) + cy * (l21 * math.cos(phi) + l22 * math.sin(phi)) > 0:
                phi += math.pi
            off = (phi - centre + math.pi) % (2.0 * math.pi) - math.pi
            lo = min(lo, off)
            hi = max(hi, off)
        mid = 0.5 * (hi + lo)
        half = 0.5 * (hi - lo)
        r0 = 0.0
        r1x = 0.0
        r1y = 0.0
        r2xx = 0.0
        r2xy = 0.0
        r2yy = 0.0
        for j in range(ANGLES):
            theta = (j + 0.5) * math.pi / ANGLES
            phi = centre + mid + half * math.cos(theta)
            dphi = half * math.sin(theta) * math.pi / ANGLES
            ex, ey = math.cos(phi), math.sin(phi)
            wx, wy = l11 * ex, l21 * ex + l22 * ey
            s1, s2 = _chord(cx, cy, wx, wy, k)
            s1 = max(s1, 0.0)
            s2 = min(s2, MAX_RADIUS)
            if s2 <= s1:
                continue
            m0, m1, m2 = _ray(cx, cy, wx, wy, s1, s2, distances, probabilities, False)
            r0 += m0 * dphi
            r1x += m1 * ex * dphi
            r1y += m1 * ey * dphi
            r2xx += m2 * ex * ex * dphi
            r2xy += m2 * ex * ey * dphi
            r2yy += m2 * ey * ey * dphi
        z = 1.0 - r0
        ux, uy = -r1x, -r1y
        uxx, uxy, uyy = 1.0 - r2xx, -r2xy, 1.0 - r2yy
    z += MASS_FLOOR  # the likelihood floored: g + MASS_FLOOR (module docstring)
    uxx += MASS_FLOOR
    uyy += MASS_FLOOR
    mux, muy = ux / z, uy / z
    cuxx = uxx / z - mux * mux
    cuxy = uxy / z - mux * muy
    cuyy = uyy / z - muy * muy
    # back to metres: m = mu_p + L mu_u, C = L C_u L'
    mx = mean[0] + l11 * mux
    my = mean[1] + l21 * mux + l22 * muy
    cxx = l11 * l11 * cuxx
    cxy = l11 * (l21 * cuxx + l22 * cuxy)
    cyy = l21 * l21 * cuxx + 2.0 * l21 * l22 * cuxy + l22 * l22 * cuyy
    condition_on_position(mean, cov, mx, my, cxx, cxy, cyy)


@numba.njit(cache=True)
def centred_miss_scale(a, p):
    """The closed form's covariance factor ``c`` (module docstring) of a look over the
    Mahalanobis disc with ``a = r^2 / 2`` centred on the mean, constant ``Pd = p``, with the
    likelihood floored as `miss_update`'s."""
    tail = math.exp(-a)
    kept = 1.0 - p + p * tail + MASS_FLOOR  # Z = 1 - p (1 - e^-a), floored
    second = 2.0 * (1.0 - p) + p * tail * (2.0 * a + 2.0) + 2.0 * MASS_FLOOR  # E[|u|^2 g]
    return second / (2.0 * kept)


@numba.njit(cache=True)
def search_miss_scale(p_find, factor):
    """The covariance factor ``c`` of a coverage sub-task that ended in a miss: the spiral swept
    the Mahalanobis disc ``a = S_cover / (2 pi sqrt(det))`` and found with ``p_find = 1 - (1 -
    F)^eta`` (``F = 1 - e^-a`` the chance the target was in it, ``eta`` = ``factor``, the
    sensor's ``find_factor``; `hptrack.coverage.estimator`), so ``a = -ln(1 - p_find) / eta``
    and a target in the disc was detected with ``p_find / F``: `centred_miss_scale` of those.
    1 when ``p_find`` is 0 or 1 (no miss to learn from)."""
    if not 0.0 < p_find < 1.0:
        return 1.0
    a = -math.log1p(-p_find) / factor
    return centred_miss_scale(a, min(p_find / -math.expm1(-a), 1.0))


@numba.njit(cache=True)
def scale_position_covariance(cov, c):
    """The closed form applied in place: the position covariance times ``c`` and the rest by
    the regression (`condition_covariance`; the mean does not move)."""
    condition_covariance(cov, c * cov[0, 0], c * 0.5 * (cov[0, 1] + cov[1, 0]), c * cov[1, 1])
