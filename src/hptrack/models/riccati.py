"""The covariance of a target measured at every step, in O(1) per query (Riccati compositions).

One step of the Kalman recursion on *predicted* covariances is the linear fractional map
``T(X) = Q + F X (I + S X)^-1 F'`` with ``S = H' R^-1 H`` (update, then predict). ``j`` steps
compose into ``T^j(X) = H_j + A_j X (I + G_j X)^-1 A_j'`` (the composition rule of the
structure-preserving doubling algorithm, applied one step at a time):
``A_{j+1} = F M^-1 A_j``, ``G_{j+1} = G_j + A_j' S M^-1 A_j``, ``H_{j+1} = Q + F M^-1 H_j F'``
with ``M = I + H_j S``.

`riccati_table` precomputes ``(A_j, G_j, H_j)`` for one target's ``q``;
`measured_covariance` applies entry ``j`` and the final update: the posterior after
``j + 1`` consecutive measured steps that starts from the covariance predicted to the first one.
The tree search follows a found target with it (paper Sec. IV-C-2, "consecutive identical
actions"), and A*'s heuristic bounds the information still reachable with it (Schlotfeldt et
al., IROS 2019). Both call these two kernels.
"""

from __future__ import annotations

import numba
import numpy as np

from hptrack.models.linalg import matmul_square, solve_square
from hptrack.models.measurement import update_covariance
from hptrack.models.motion import fill_process_noise, fill_transition

CONVERGED_TOLERANCE = 1e-13
"""Relative size below which the initial covariance no longer affects ``T^j(X)``."""

WORK_SLOTS = 3
"""``d x d`` scratch matrices `measured_covariance` needs."""


@numba.njit(cache=True)
def riccati_table(q, tau, c_per_step, noise, max_steps):
    """Maps ``(A_j, G_j, H_j)`` of ``T^j``, ``j = 0 .. L-1`` (module docstring).

    The table stops when the initial covariance no longer matters, ``|A G^-1 A'| <= 1e-13 |H|``
    (then ``T^j(X) = H_{L-1}`` for every ``j >= L-1``), or at ``j = max_steps``.

    Args:
        q: process noise intensity, m^2/s^3.
        tau: time step, s.
        c_per_step: lower-right per-step ``Q`` block over ``q``.
        noise: ``(2, 2)`` measurement noise ``R``, m^2.
        max_steps: largest ``j`` needed.

    Returns:
        ``(A, G, H, L)``: ``(max_steps + 1, 4, 4)`` arrays, of which the first ``L`` are valid.
    """
    f = np.empty((4, 4))
    fill_transition(tau, f)
    qq = np.empty((4, 4))
    fill_process_noise(q, 1.0, tau, c_per_step, qq)
    return riccati_table_of(f, qq, noise, max_steps)


@numba.njit(cache=True)
def riccati_table_of(f, qq, noise, max_steps):
    """`riccati_table` for any one-step ``F`` and ``Q`` (a mission's motion,
    `hptrack.models.mission.follow_tables`); ``d x d`` for a state of ``d`` entries."""
    d = f.shape[0]
    det = noise[0, 0] * noise[1, 1] - noise[0, 1] * noise[1, 0]
    s = np.zeros((d, d))
    s[0, 0] = noise[1, 1] / det
    s[1, 1] = noise[0, 0] / det
    s[0, 1] = s[1, 0] = -0.5 * (noise[0, 1] + noise[1, 0]) / det
    cap = max_steps + 1
    ta = np.zeros((cap, d, d))
    tg = np.zeros((cap, d, d))
    th = np.zeros((cap, d, d))
    for i in range(d):
        ta[0, i, i] = 1.0
    m = np.empty((d, d))
    rhs = np.empty((d, 2 * d))
    sol = np.empty((d, 2 * d))
    ma = np.empty((d, d))
    mh = np.empty((d, d))
    t1 = np.empty((d, d))
    t2 = np.empty((d, d))
    length = cap
    for j in range(1, cap):
        a1, g1, h1 = ta[j - 1], tg[j - 1], th[j - 1]
        matmul_square(h1, s, m, False)
        for r in range(d):
            m[r, r] += 1.0
            for c in range(d):
                rhs[r, c] = a1[r, c]
                rhs[r, d + c] = h1[r, c]
        solve_square(m, rhs, sol)  # [M^-1 A_j, M^-1 H_j]
        for r in range(d):
            for c in range(d):
                ma[r, c] = sol[r, c]
                mh[r, c] = sol[r, d + c]
        matmul_square(f, ma, ta[j], False)
        matmul_square(s, ma, t1, False)
        for r in range(d):  # G_{j+1} = G_j + A_j' (S M^-1 A_j), symmetrised
            for c in range(d):
                acc = 0.0
                for k in range(d):
                    acc += a1[k, r] * t1[k, c]
                t2[r, c] = acc
        for r in range(d):
            for c in range(d):
                tg[j, r, c] = g1[r, c] + 0.5 * (t2[r, c] + t2[c, r])
        matmul_square(f, mh, t1, False)
        matmul_square(t1, f, t2, True)
        for r in range(d):
            for c in range(d):
                th[j, r, c] = qq[r, c] + 0.5 * (t2[r, c] + t2[c, r])
        # A G^-1 A' bounds what the initial covariance still adds (G is invertible once every
        # derivative has reached the position); a motion whose velocity never reaches the
        # position (a random walk) leaves G singular: no bound, no stop.
        invertible = j >= d // 2  # as many measured steps as the state has derivatives
        for i in range(2, d):
            invertible = invertible and tg[j, i, i] > 0.0
        if invertible:
            for r in range(d):
                for c in range(d):
                    m[r, c] = tg[j, r, c]
                    t2[r, c] = ta[j, c, r]
            solve_square(m, t2, t1)  # G^-1 A'
            matmul_square(ta[j], t1, t2, False)
            bound = 0.0
            scale = 0.0
            for r in range(d):
                for c in range(d):
                    bound = max(bound, abs(t2[r, c]))
                    scale = max(scale, abs(th[j, r, c]))
            if bound <= CONVERGED_TOLERANCE * scale:
                length = j + 1
                break
    return ta, tg, th, length


@numba.njit(cache=True)
def measured_covariance(maps_a, maps_g, maps_h, length, j, predicted, noise, out, work):
    """Posterior covariance after ``j + 1`` consecutive measured steps, starting from the
    covariance ``predicted`` to the first of them: ``update(T^j(predicted))``.

    ``maps_*`` and ``length`` are one target's `riccati_table`; ``j`` beyond the table is
    clamped (the map has converged). ``work`` is ``(>= 3, d, d)`` scratch; ``out`` must not alias
    ``predicted``.
    """
    d = predicted.shape[0]
    k = min(j, length - 1)
    a, g, h = maps_a[k], maps_g[k], maps_h[k]
    m, w, aw = work[0], work[1], work[2]
    matmul_square(predicted, g, m, True)  # m = x g' = (I + g x)' - I, as g and x are symmetric
    for r in range(d):
        m[r, r] += 1.0
        for c in range(d):
            aw[r, c] = predicted[r, c]
    solve_square(m, aw, w)  # w = (I + g x)'^-1 x = (x (I + g x)^-1)'
    matmul_square(a, w, aw, True)  # a x (I + g x)^-1
    matmul_square(aw, a, m, True)
    for r in range(d):
        for c in range(d):
            out[r, c] = h[r, c] + 0.5 * (m[r, c] + m[c, r])
    update_covariance(out, noise, out)
