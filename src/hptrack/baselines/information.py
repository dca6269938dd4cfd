"""Deterministic covariance rollouts shared by the ARVI and A* baselines.

With linear Gaussian target motion and a linear position sensor, the Kalman covariances depend
only on *where the agent is*, never on the measured values (Atanasov et al., ICRA 2014,
"Information acquisition with sensing robots"; Schlotfeldt et al., RA-L 2018 and IROS 2019).
Planning the agent's controls over a horizon is then a deterministic search over covariance
sequences (``shared/notes/baselines.md``, "Shared model"):

* the belief means are propagated open loop with the constant-velocity model (the expected
  innovation is zero), so the mean positions at every future sub-step are shared by all nodes;
* at a future sub-step, target ``i`` is measured when its predicted mean lies within ``w/2`` of
  the planned agent position; its covariance then gets the Kalman update with ``R``, otherwise
  only the prediction of Eq. (1);
* the step cost is the seed paper's modification (Sec. V-B): the change of the total uncertainty
  ``c_t = sum_i [log det Sigma_i^xy(t+1) - log det Sigma_i^xy(t)]``; the original papers' cost,
  the uncertainty itself ``sum_i log det Sigma_i^xy(t+1)`` summed over the steps, is the option
  ``"sum"``.

Runs of unmeasured sub-steps use the closed-form prediction of ``hptrack.models.motion``, so a
primitive costs one prediction per measurement plus one, whatever its duration; a target that no
control of a node can bring into the footprint during the primitive is predicted once for all of
that node's children. Searches that prune before they need the children's covariances
(ARVI with ``epsilon = inf``) ask for the uncertainties first (:func:`expand_uncertainty`) and for
the covariances of the kept children only (:func:`child_covariances`).

:class:`RiccatiBound` is the admissible heuristic of A* (Schlotfeldt, Atanasov, Pappas, IROS
2019, "Maximum Information Bounds for Planning Active Sensing Trajectories"), with the step cost
changed to match: every target is measured at every sub-step from the first one at which the
agent could have reached its predicted mean. The "measured at every step" Riccati recursion is
precomputed once per mission as linear-fractional maps ``X -> A (X^-1 + G)^-1 A' + H`` (the
composition rule of the structure-preserving doubling algorithm), so the bound costs O(1) per
target and node, whatever the horizon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numba
import numpy as np

from hptrack.models.motion import noise_blocks

if TYPE_CHECKING:
    from hptrack.sim.interface import MissionSpec

CostKind = Literal["difference", "sum"]
"""``"difference"``: change of total ``log det`` per step (seed paper); ``"sum"``: the total
``log det`` after each step, summed over the steps (original ARVI / A* papers)."""


@dataclass(frozen=True)
class RolloutSpec:
    """The mission constants a covariance rollout needs, as plain numbers and arrays.

    Attributes:
        time_step_s: simulator step ``tau``, s.
        step_length_m: agent displacement per step at full speed ``v_a tau``, m.
        sensor_radius_m: footprint radius ``w/2``, m.
        noise_variance_m2: measurement noise variance per axis (``R = r I``), m^2.
        c_per_step: lower-right block of the per-step ``Q`` divided by ``q`` (``tau`` s or 1).
        process_noise: ``(n,)`` noise intensities ``q`` per target, m^2/s^3.
    """

    time_step_s: float
    step_length_m: float
    sensor_radius_m: float
    noise_variance_m2: float
    c_per_step: float
    process_noise: np.ndarray

    @classmethod
    def from_mission(cls, mission: MissionSpec) -> RolloutSpec:
        """The rollout constants of ``mission``."""
        return cls(
            time_step_s=mission.time_step,
            step_length_m=mission.step_length,
            sensor_radius_m=0.5 * mission.sensor.sensor_diameter,
            noise_variance_m2=mission.sensor.noise_std**2,
            c_per_step=mission.motion.c_per_step,
            process_noise=np.asarray(mission.process_noise, dtype=float),
        )


def mean_positions(means: np.ndarray, time_step_s: float, n_sub_steps: int) -> np.ndarray:
    """Open-loop predicted mean positions ``(n_sub_steps + 1, n, 2)`` at sub-steps ``0..S``, m."""
    t = time_step_s * np.arange(n_sub_steps + 1)
    return means[None, :, :2] + t[:, None, None] * means[None, :, 2:]


@numba.njit(cache=True, inline="always")
def _predict(p: np.ndarray, steps: float, q: float, tau: float, c_per_step: float) -> None:
    """``p <- F^k p F^k' + sum_{j<k} F^j Q F^j'`` in place (closed form, O(1) in ``steps``)."""
    t = steps * tau
    qpp, qpv, qvv = noise_blocks(q, steps, tau, c_per_step)
    for a in range(2):
        for b in range(a, 2):
            v = (p[a, b] + t * (p[a + 2, b] + p[a, b + 2]) + t * t * p[a + 2, b + 2])
            p[a, b] = v
            p[b, a] = v
    for a in range(2):
        for b in range(2):
            v = p[a, b + 2] + t * p[a + 2, b + 2]
            p[a, b + 2] = v
            p[b + 2, a] = v
    for a in range(2):
        p[a, a] += qpp
        p[a, a + 2] += qpv
        p[a + 2, a] += qpv
        p[a + 2, a + 2] += qvv


@numba.njit(cache=True, inline="always")
def _update(p: np.ndarray, r: float) -> None:
    """Kalman update with a position measurement, ``R = r I``, in place (symmetrised)."""
    s00 = p[0, 0] + r
    s01 = p[0, 1]
    s11 = p[1, 1] + r
    det = s00 * s11 - s01 * s01
    i00 = s11 / det
    i01 = -s01 / det
    i11 = s00 / det
    k = np.empty((4, 2))
    hp = np.empty((2, 4))
    for a in range(4):
        k[a, 0] = p[a, 0] * i00 + p[a, 1] * i01
        k[a, 1] = p[a, 0] * i01 + p[a, 1] * i11
        hp[0, a] = p[0, a]
        hp[1, a] = p[1, a]
    for a in range(4):
        for b in range(a, 4):
            v = p[a, b] - k[a, 0] * hp[0, b] - k[a, 1] * hp[1, b]
            w = p[b, a] - k[b, 0] * hp[0, a] - k[b, 1] * hp[1, a]
            p[a, b] = 0.5 * (v + w)
            p[b, a] = p[a, b]


@numba.njit(cache=True, inline="always")
def _position_logdet(p: np.ndarray) -> float:
    return math.log(p[0, 0] * p[1, 1] - p[0, 1] * p[1, 0])


@numba.njit(cache=True)
def rollout_children(positions, covariances, children, step_displacements, level_means,
                     process_noise, tau, c_per_step, noise_variance, radius, store,
                     out_covariances, out_uncertainty):
    """Compiled kernel of :func:`expand`: children ``a C + c`` listed in ``children``.

    Writes each child's total ``log det Sigma^xy`` to ``out_uncertainty`` and, if ``store``, its
    covariances to ``out_covariances`` (same order as ``children``).
    """
    n_controls = step_displacements.shape[0]
    n_targets = covariances.shape[1]
    n_steps = level_means.shape[0] - 1
    radius2 = radius * radius
    reach = 0.0
    for c in range(n_controls):
        reach = max(reach, n_steps * math.hypot(step_displacements[c, 0],
                                                step_displacements[c, 1]))
    p = np.empty((4, 4))
    # A target out of reach of every control of a node is only predicted; the prediction is
    # shared by that node's children, which are consecutive in ``children``.
    far_node = np.full(n_targets, -1, dtype=np.int64)
    far_cov = np.empty((n_targets, 4, 4))
    far_logdet = np.empty(n_targets)
    for j in range(children.shape[0]):
        a = children[j] // n_controls
        c = children[j] % n_controls
        px = positions[a, 0]
        py = positions[a, 1]
        dx = step_displacements[c, 0]
        dy = step_displacements[c, 1]
        total = 0.0
        for i in range(n_targets):
            if far_node[i] != a:
                drift = math.hypot(level_means[n_steps, i, 0] - level_means[0, i, 0],
                                   level_means[n_steps, i, 1] - level_means[0, i, 1])
                gap0 = math.hypot(level_means[0, i, 0] - px, level_means[0, i, 1] - py)
                if gap0 > reach + drift + radius:
                    far_cov[i] = covariances[a, i]
                    _predict(far_cov[i], n_steps, process_noise[i], tau, c_per_step)
                    far_logdet[i] = _position_logdet(far_cov[i])
                    far_node[i] = a
            if far_node[i] == a:
                total += far_logdet[i]
                if store:
                    out_covariances[j, i] = far_cov[i]
                continue
            p[:, :] = covariances[a, i]
            gap = 0
            for s in range(1, n_steps + 1):
                gap += 1
                ex = px + s * dx - level_means[s, i, 0]
                ey = py + s * dy - level_means[s, i, 1]
                if ex * ex + ey * ey <= radius2:
                    _predict(p, gap, process_noise[i], tau, c_per_step)
                    _update(p, noise_variance)
                    gap = 0
            if gap > 0:
                _predict(p, gap, process_noise[i], tau, c_per_step)
            total += _position_logdet(p)
            if store:
                out_covariances[j, i] = p
        out_uncertainty[j] = total


def _run_rollout(spec: RolloutSpec, step_displacements: np.ndarray, level_means: np.ndarray,
                 positions: np.ndarray, covariances: np.ndarray, children: np.ndarray,
                 store: bool) -> tuple[np.ndarray, np.ndarray]:
    n_targets = covariances.shape[1]
    out_covariances = np.empty((children.shape[0] if store else 0, n_targets, 4, 4))
    out_uncertainty = np.empty(children.shape[0])
    rollout_children(np.ascontiguousarray(positions, dtype=float),
                     np.ascontiguousarray(covariances, dtype=float),
                     np.asarray(children, dtype=np.int64),
                     np.ascontiguousarray(step_displacements, dtype=float),
                     np.ascontiguousarray(level_means, dtype=float), spec.process_noise,
                     spec.time_step_s, spec.c_per_step, spec.noise_variance_m2,
                     spec.sensor_radius_m, store, out_covariances, out_uncertainty)
    return out_covariances, out_uncertainty


def child_positions(step_displacements: np.ndarray, n_steps: int, positions: np.ndarray
                    ) -> np.ndarray:
    """``(N C, 2)`` agent positions after each control of ``n_steps`` sub-steps from each node;
    child ``a C + c`` is node ``a`` after control ``c``."""
    return (positions[:, None, :] + n_steps * step_displacements[None, :, :]).reshape(-1, 2)


def expand(spec: RolloutSpec, step_displacements: np.ndarray, level_means: np.ndarray,
           positions: np.ndarray, covariances: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Expand every node with every control: one motion primitive of ``K`` sub-steps each.

    Args:
        spec: the mission constants.
        step_displacements: ``(C, 2)`` agent displacement per sub-step of each control, m.
        level_means: ``(K + 1, n, 2)`` predicted mean positions at the primitive's sub-steps
            ``0..K`` (a slice of :func:`mean_positions`), m.
        positions: ``(N, 2)`` agent positions of the nodes, m.
        covariances: ``(N, n, 4, 4)`` target covariances of the nodes.

    Returns:
        ``(N C, 2)`` child positions, ``(N C, n, 4, 4)`` child covariances and ``(N C,)``
        total uncertainty ``sum_i log det Sigma_i^xy`` of the children; child ``a C + c`` is
        node ``a`` after control ``c``.
    """
    children = np.arange(positions.shape[0] * step_displacements.shape[0])
    covs, uncertainty = _run_rollout(spec, step_displacements, level_means, positions,
                                     covariances, children, store=True)
    n_steps = level_means.shape[0] - 1
    return child_positions(step_displacements, n_steps, positions), covs, uncertainty


def expand_uncertainty(spec: RolloutSpec, step_displacements: np.ndarray,
                       level_means: np.ndarray, positions: np.ndarray, covariances: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`expand` without the child covariances: ``(N C, 2)`` positions, ``(N C,)``
    total uncertainty (for searches that prune before storing covariances)."""
    children = np.arange(positions.shape[0] * step_displacements.shape[0])
    _, uncertainty = _run_rollout(spec, step_displacements, level_means, positions,
                                  covariances, children, store=False)
    n_steps = level_means.shape[0] - 1
    return child_positions(step_displacements, n_steps, positions), uncertainty


def child_covariances(spec: RolloutSpec, step_displacements: np.ndarray,
                      level_means: np.ndarray, positions: np.ndarray, covariances: np.ndarray,
                      children: np.ndarray) -> np.ndarray:
    """Covariances ``(M, n, 4, 4)`` of the children ``a C + c`` listed in ``children``."""
    covs, _ = _run_rollout(spec, step_displacements, level_means, positions, covariances,
                           np.asarray(children, dtype=np.int64), store=True)
    return covs


def step_costs(parent_uncertainty: np.ndarray, child_uncertainty: np.ndarray,
               kind: CostKind) -> np.ndarray:
    """Cost of one step from the total uncertainty ``sum_i log det Sigma_i^xy`` before and after.

    ``"difference"`` (seed paper, Sec. V-B): ``after - before``; ``"sum"`` (original papers):
    ``after``. Both arrays broadcast.
    """
    if kind == "difference":
        return child_uncertainty - parent_uncertainty
    if kind == "sum":
        return np.asarray(child_uncertainty, dtype=float).copy()
    raise ValueError(f"unknown cost kind {kind!r}")


def _compose(first: tuple, then: tuple) -> tuple:
    """``then o first`` for maps ``X -> A (X^-1 + G)^-1 A' + H`` (4x4 each)."""
    a1, g1, h1 = first
    a2, g2, h2 = then
    m = np.linalg.inv(np.eye(4) + h1 @ g2)
    a = a2 @ m @ a1
    g = g1 + a1.T @ g2 @ m @ a1
    h = h2 + a2 @ m @ h1 @ a2.T
    return a, 0.5 * (g + g.T), 0.5 * (h + h.T)


@numba.njit(cache=True, inline="always")
def _apply_map(p: np.ndarray, a: np.ndarray, g: np.ndarray, h: np.ndarray,
               work: np.ndarray) -> float:
    """``log det`` of the position block of ``A (p^-1 + G)^-1 A' + H``, via ``(I + p G) y = p``."""
    for r in range(4):
        for c in range(4):
            v = 1.0 if r == c else 0.0
            for k in range(4):
                v += p[r, k] * g[k, c]
            work[r, c] = v
        for c in range(4):
            work[r, 4 + c] = p[r, c]
    for col in range(4):
        piv = col
        for r in range(col + 1, 4):
            if abs(work[r, col]) > abs(work[piv, col]):
                piv = r
        if piv != col:
            for c in range(8):
                work[col, c], work[piv, c] = work[piv, c], work[col, c]
        for r in range(4):
            if r != col:
                factor = work[r, col] / work[col, col]
                for c in range(col, 8):
                    work[r, c] -= factor * work[col, c]
    for r in range(4):
        d = work[r, r]
        for c in range(4, 8):
            work[r, c] /= d
    x00 = h[0, 0]
    x01 = h[0, 1]
    x11 = h[1, 1]
    for k in range(4):
        for m in range(4):
            y = work[k, 4 + m]
            x00 += a[0, k] * y * a[0, m]
            x01 += a[0, k] * y * a[1, m]
            x11 += a[1, k] * y * a[1, m]
    return math.log(x00 * x11 - x01 * x01)


@numba.njit(cache=True)
def bound_children(positions, covariances, start, boundaries, all_means, process_noise, tau,
                   c_per_step, step_length, radius, maps_a, maps_g, maps_h, out):
    """Compiled kernel of :meth:`RiccatiBound.lower_bounds`; adds the bounds to ``out``."""
    n_nodes, n_targets = covariances.shape[:2]
    n_total = all_means.shape[0] - 1
    p = np.empty((4, 4))
    work = np.empty((4, 8))
    for j in range(n_nodes):
        for i in range(n_targets):
            first = n_total + 1
            for s in range(1, n_total - start + 1):
                ex = all_means[start + s, i, 0] - positions[j, 0]
                ey = all_means[start + s, i, 1] - positions[j, 1]
                reach = s * step_length + radius
                if ex * ex + ey * ey <= reach * reach:
                    first = s
                    break
            for b in range(boundaries.shape[0]):
                length = boundaries[b] - start
                p[:, :] = covariances[j, i]
                if first > length:
                    _predict(p, length, process_noise[i], tau, c_per_step)
                    out[j, b] += _position_logdet(p)
                else:
                    _predict(p, first, process_noise[i], tau, c_per_step)
                    m = length - first
                    out[j, b] += _apply_map(p, maps_a[i, m], maps_g[i, m], maps_h[i, m], work)


class RiccatiBound:
    """Lower bound on the ``log det Sigma^xy`` still reachable, the heuristic of A*.

    From a node at sub-step ``t`` and agent position ``p``, target ``i`` can first be measured
    at the first sub-step ``t + s`` at which its predicted mean lies within
    ``s v_a tau + w/2`` of ``p``. The optimistic future predicts it until then and measures it at
    every sub-step from there on. The Riccati map is monotone in the positive-semidefinite order
    and an update never increases a covariance, so this covariance is a lower bound, in that
    order, on the one of every feasible plan at every later sub-step (Schlotfeldt et al., IROS
    2019), hence so is its ``log det Sigma^xy``. The bound never couples targets (the agent is
    allowed to measure them all at once), which keeps it admissible.

    ``maps[i, m]`` is the map of ``m + 1`` consecutive measured sub-steps applied to the
    covariance predicted to the first one: ``update o (predict o update)^m``, precomputed for
    each target's ``q`` and ``m < max_sub_steps``.
    """

    def __init__(self, spec: RolloutSpec, max_sub_steps: int) -> None:
        self.spec = spec
        tau = spec.time_step_s
        f = np.eye(4)
        f[0, 2] = f[1, 3] = tau
        w = np.zeros((4, 4))
        w[0, 0] = w[1, 1] = 1.0 / spec.noise_variance_m2
        n = spec.process_noise.shape[0]
        shape = (n, max(max_sub_steps, 1), 4, 4)
        self.maps_a, self.maps_g, self.maps_h = np.empty(shape), np.empty(shape), np.empty(shape)
        for i, q in enumerate(spec.process_noise):
            qpp, qpv, qvv = noise_blocks(float(q), 1.0, tau, spec.c_per_step)
            noise = np.block([[qpp * np.eye(2), qpv * np.eye(2)], [qpv * np.eye(2),
                                                                   qvv * np.eye(2)]])
            cycle = (f, w, noise)
            current = (np.eye(4), w, np.zeros((4, 4)))
            for m in range(shape[1]):
                self.maps_a[i, m], self.maps_g[i, m], self.maps_h[i, m] = current
                current = _compose(cycle, current)

    def lower_bounds(self, positions: np.ndarray, covariances: np.ndarray, start: int,
                     boundaries: np.ndarray, all_means: np.ndarray) -> np.ndarray:
        """Lower bounds ``(N, B)`` on ``sum_i log det Sigma_i^xy`` at each of ``boundaries``.

        Args:
            positions: ``(N, 2)`` agent positions of nodes at sub-step ``start``, m.
            covariances: ``(N, n, 4, 4)`` their target covariances.
            start: the nodes' sub-step index, counted from the decision.
            boundaries: ``(B,)`` later sub-step indices, at most ``start + max_sub_steps``.
            all_means: ``(S + 1, n, 2)`` predicted mean positions (:func:`mean_positions`), m.
        """
        out = np.zeros((positions.shape[0], len(boundaries)))
        spec = self.spec
        bound_children(np.ascontiguousarray(positions, dtype=float),
                       np.ascontiguousarray(covariances, dtype=float), int(start),
                       np.asarray(boundaries, dtype=np.int64), np.ascontiguousarray(all_means),
                       spec.process_noise, spec.time_step_s, spec.c_per_step,
                       spec.step_length_m, spec.sensor_radius_m, self.maps_a, self.maps_g,
                       self.maps_h, out)
        return out
