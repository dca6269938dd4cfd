"""Deterministic covariance rollouts shared by the ARVI and A* baselines.

With linear Gaussian target motion and a linear position sensor, the Kalman covariances depend
only on *where the agent is*, never on the measured values (Atanasov et al., ICRA 2014,
"Information acquisition with sensing robots"; Schlotfeldt et al., RA-L 2018 and IROS 2019).
Planning the agent's controls over a horizon is then a deterministic search over covariance
sequences (``docs/baselines.md``, "Shared model"):

* the belief means are propagated open loop with the constant-velocity model (the expected
  innovation is zero), so the mean positions at every future sub-step are shared by all nodes;
* at a future sub-step, target ``i`` is measured when its predicted mean lies within ``w/2`` of
  the planned agent position; its covariance then gets the Kalman update with ``R``, otherwise
  only the prediction of Eq. (1);
* the step cost is the seed paper's modification (Sec. V-B): the change of the total uncertainty
  ``c_t = sum_i [log det Sigma_i^xy(t+1) - log det Sigma_i^xy(t)]``; the original papers' cost,
  the uncertainty itself ``sum_i log det Sigma_i^xy(t+1)`` summed over the steps, is the option
  ``"sum"``.

Runs of unmeasured sub-steps use the closed-form prediction of `hptrack.models.motion` and
the Kalman update of `hptrack.models.measurement` (any 2x2 ``R``), so a
primitive costs one prediction per measurement plus one, whatever its duration; a target that no
control of a node can bring into the footprint during the primitive is predicted once for all of
that node's children. Searches that prune before they need the children's covariances
(ARVI with ``epsilon = inf``) ask for the uncertainties first (`expand_uncertainty`) and for
the covariances of the kept children only (`child_covariances`).

With a fence (`hptrack.models.fence`), a primitive is a candidate only when the vehicle may
fly it straight (`hptrack.models.vehicle`'s ``flies_straight_between``: it neither enters a
no-fly zone nor leaves the operating area, both by the margin; hover always is): the others
get an infinite cost and no search keeps them, so every plan is flown as it was scored. In open
space every primitive is a candidate and nothing changes.

`RiccatiBound` is the admissible heuristic of A* (Schlotfeldt, Atanasov, Pappas, IROS
2019, "Maximum Information Bounds for Planning Active Sensing Trajectories"), with the step cost
changed to match: every target is measured at every sub-step from the first one at which the
agent could have reached its predicted mean. The "measured at every step" Riccati recursion is
precomputed once per mission (`hptrack.models.riccati`), so the bound costs O(1) per
target and node, whatever the horizon. A fence only lengthens the way to a target, so the
bound's straight reach stays a lower bound with one (looser).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Literal

import numba
import numpy as np

from hptrack.models.belief_motion import BeliefMotion
from hptrack.models.beliefs import logdet_xy
from hptrack.models.mission import follow_tables, predict_covariance_on
from hptrack.models.motion import predicted_positions
from hptrack.models.riccati import measured_covariance
from hptrack.models.sensor import sensor_measures, sensor_reach, sensor_update_covariance
from hptrack.models.vehicle import vehicle_flies_straight_between

if TYPE_CHECKING:
    from hptrack.interface import MissionSpec

CostKind = Literal["difference", "sum"]
"""``"difference"``: change of total ``log det`` per step (seed paper); ``"sum"``: the total
``log det`` after each step, summed over the steps (original ARVI / A* papers)."""


def mean_positions(means: np.ndarray, motion: BeliefMotion, n_sub_steps: int) -> np.ndarray:
    """Open-loop predicted mean positions ``(n_sub_steps + 1, n, 2)`` at sub-steps ``0..S``
    by the beliefs' ``motion``, m."""
    t = motion.time_step * np.arange(n_sub_steps + 1)
    if motion.straight:
        return predicted_positions(means[None, :, :], t[:, None])
    return np.stack([motion.mean_positions(m, t) for m in means], axis=1)


@numba.njit(cache=True)
def rollout_children(
    mission,
    positions,
    covariances,
    children,
    step_displacements,
    level_means,
    store,
    out_covariances,
    out_uncertainty,
):
    """Compiled kernel of `expand`: children ``a C + c`` listed in ``children``
    (``mission``: the mission record).

    Writes each child's total ``log det Sigma^xy`` to ``out_uncertainty`` and, if ``store``, its
    covariances to ``out_covariances`` (same order as ``children``). A child whose primitive the
    vehicle may not fly straight (into a no-fly zone or out of the operating area, by the
    fence's margin) is not a candidate: its uncertainty is ``inf``, its covariances the node's.
    """
    n_controls = step_displacements.shape[0]
    n_targets = covariances.shape[1]
    n_steps = level_means.shape[0] - 1
    process_noise, sensor = mission.process_noise, mission.sensor
    sensing_range = sensor_reach(sensor)
    reach = 0.0
    for c in range(n_controls):
        reach = max(reach, n_steps * math.hypot(step_displacements[c, 0], step_displacements[c, 1]))
    d = covariances.shape[2]
    p = np.empty((d, d))
    # A target out of reach of every control of a node is only predicted; the prediction is
    # shared by that node's children, which are consecutive in ``children``.
    far_node = np.full(n_targets, -1, dtype=np.int64)
    far_cov = np.empty((n_targets, d, d))
    far_logdet = np.empty(n_targets)
    for j in range(children.shape[0]):
        a = children[j] // n_controls
        c = children[j] % n_controls
        px = positions[a, 0]
        py = positions[a, 1]
        dx = step_displacements[c, 0]
        dy = step_displacements[c, 1]
        if not vehicle_flies_straight_between(
            mission.vehicle, px, py, px + n_steps * dx, py + n_steps * dy
        ):
            out_uncertainty[j] = math.inf
            if store:
                out_covariances[j] = covariances[a]
            continue
        total = 0.0
        for i in range(n_targets):
            if far_node[i] != a:
                drift = math.hypot(
                    level_means[n_steps, i, 0] - level_means[0, i, 0],
                    level_means[n_steps, i, 1] - level_means[0, i, 1],
                )
                gap0 = math.hypot(level_means[0, i, 0] - px, level_means[0, i, 1] - py)
                if gap0 > reach + drift + sensing_range:
                    far_cov[i] = covariances[a, i]
                    predict_covariance_on(
                        mission, far_cov[i], process_noise[i], n_steps, far_cov[i]
                    )
                    far_logdet[i] = logdet_xy(far_cov[i, 0, 0], far_cov[i, 0, 1], far_cov[i, 1, 1])
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
                mx, my = level_means[s, i, 0], level_means[s, i, 1]
                if sensor_measures(sensor, px + s * dx, py + s * dy, mx, my):
                    predict_covariance_on(mission, p, process_noise[i], gap, p)
                    sensor_update_covariance(sensor, p, p)
                    gap = 0
            if gap > 0:
                predict_covariance_on(mission, p, process_noise[i], gap, p)
            total += logdet_xy(p[0, 0], p[0, 1], p[1, 1])
            if store:
                out_covariances[j, i] = p
        out_uncertainty[j] = total


def _run_rollout(
    mission: MissionSpec,
    step_displacements: np.ndarray,
    level_means: np.ndarray,
    positions: np.ndarray,
    covariances: np.ndarray,
    children: np.ndarray,
    store: bool,
) -> tuple[np.ndarray, np.ndarray]:
    n_targets = covariances.shape[1]
    d = covariances.shape[2]
    out_covariances = np.empty((children.shape[0] if store else 0, n_targets, d, d))
    out_uncertainty = np.empty(children.shape[0])
    rollout_children(
        mission.record,
        np.ascontiguousarray(positions, dtype=float),
        np.ascontiguousarray(covariances, dtype=float),
        np.asarray(children, dtype=np.int64),
        np.ascontiguousarray(step_displacements, dtype=float),
        np.ascontiguousarray(level_means, dtype=float),
        store,
        out_covariances,
        out_uncertainty,
    )
    return out_covariances, out_uncertainty


def child_positions(
    step_displacements: np.ndarray, n_steps: int, positions: np.ndarray
) -> np.ndarray:
    """``(N C, 2)`` agent positions after each control of ``n_steps`` sub-steps from each node;
    child ``a C + c`` is node ``a`` after control ``c``."""
    return (positions[:, None, :] + n_steps * step_displacements[None, :, :]).reshape(-1, 2)


def expand(
    mission: MissionSpec,
    step_displacements: np.ndarray,
    level_means: np.ndarray,
    positions: np.ndarray,
    covariances: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Expand every node with every control: one motion primitive of ``K`` sub-steps each.

    Args:
        mission: the mission constants.
        step_displacements: ``(C, 2)`` agent displacement per sub-step of each control, m.
        level_means: ``(K + 1, n, 2)`` predicted mean positions at the primitive's sub-steps
            ``0..K`` (a slice of `mean_positions`), m.
        positions: ``(N, 2)`` agent positions of the nodes, m.
        covariances: ``(N, n, 4, 4)`` target covariances of the nodes.

    Returns:
        ``(N C, 2)`` child positions, ``(N C, n, 4, 4)`` child covariances and ``(N C,)``
        total uncertainty ``sum_i log det Sigma_i^xy`` of the children; child ``a C + c`` is
        node ``a`` after control ``c``.
    """
    children = np.arange(positions.shape[0] * step_displacements.shape[0])
    covs, uncertainty = _run_rollout(
        mission, step_displacements, level_means, positions, covariances, children, store=True
    )
    n_steps = level_means.shape[0] - 1
    return child_positions(step_displacements, n_steps, positions), covs, uncertainty


def expand_uncertainty(
    mission: MissionSpec,
    step_displacements: np.ndarray,
    level_means: np.ndarray,
    positions: np.ndarray,
    covariances: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """`expand` without the child covariances: ``(N C, 2)`` positions, ``(N C,)``
    total uncertainty (for searches that prune before storing covariances)."""
    children = np.arange(positions.shape[0] * step_displacements.shape[0])
    _, uncertainty = _run_rollout(
        mission, step_displacements, level_means, positions, covariances, children, store=False
    )
    n_steps = level_means.shape[0] - 1
    return child_positions(step_displacements, n_steps, positions), uncertainty


def child_covariances(
    mission: MissionSpec,
    step_displacements: np.ndarray,
    level_means: np.ndarray,
    positions: np.ndarray,
    covariances: np.ndarray,
    children: np.ndarray,
) -> np.ndarray:
    """Covariances ``(M, n, 4, 4)`` of the children ``a C + c`` listed in ``children``."""
    covs, _ = _run_rollout(
        mission,
        step_displacements,
        level_means,
        positions,
        covariances,
        np.asarray(children, dtype=np.int64),
        store=True,
    )
    return covs


def step_costs(
    parent_uncertainty: np.ndarray, child_uncertainty: np.ndarray, kind: CostKind
) -> np.ndarray:
    """Cost of one step from the total uncertainty ``sum_i log det Sigma_i^xy`` before and after.

    ``"difference"`` (seed paper, Sec. V-B): ``after - before``; ``"sum"`` (original papers):
    ``after``. Both arrays broadcast.
    """
    if kind == "difference":
        return child_uncertainty - parent_uncertainty
    if kind == "sum":
        return np.asarray(child_uncertainty, dtype=float).copy()
    raise ValueError(f"unknown cost kind {kind!r}")


@numba.njit(cache=True)
def bound_children(mission, follow, positions, covariances, start, boundaries, all_means, out):
    """Compiled kernel of `RiccatiBound.lower_bounds` (``mission``: the mission record,
    ``follow``: its `FollowTables`); adds the bounds to
    ``out``."""
    process_noise, noise = mission.process_noise, mission.sensor.measurement_noise
    step_length, sensing_range = mission.vehicle.step_length, sensor_reach(mission.sensor)
    n_nodes, n_targets = covariances.shape[:2]
    n_total = all_means.shape[0] - 1
    d = covariances.shape[2]
    p = np.empty((d, d))
    measured = np.empty((d, d))
    work = np.empty((3, d, d))
    for j in range(n_nodes):
        for i in range(n_targets):
            first = n_total + 1
            for s in range(1, n_total - start + 1):
                ex = all_means[start + s, i, 0] - positions[j, 0]
                ey = all_means[start + s, i, 1] - positions[j, 1]
                reach = s * step_length + sensing_range
                if ex * ex + ey * ey <= reach * reach:
                    first = s
                    break
            for b in range(boundaries.shape[0]):
                length = boundaries[b] - start
                p[:, :] = covariances[j, i]
                if first > length:
                    predict_covariance_on(mission, p, process_noise[i], length, p)
                    out[j, b] += logdet_xy(p[0, 0], p[0, 1], p[1, 1])
                else:
                    predict_covariance_on(mission, p, process_noise[i], first, p)
                    measured_covariance(
                        follow.a[i],
                        follow.g[i],
                        follow.h[i],
                        follow.length[i],
                        length - first,
                        p,
                        noise,
                        measured,
                        work,
                    )
                    out[j, b] += logdet_xy(measured[0, 0], measured[0, 1], measured[1, 1])


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

    The "measured at every sub-step" maps of each target's ``q``
    (`hptrack.models.riccati.riccati_table`) are built once, for ``max_sub_steps``.
    """

    def __init__(self, mission: MissionSpec, max_sub_steps: int) -> None:
        self.mission = mission
        self.follow = follow_tables(mission.record, max(max_sub_steps, 1))

    def lower_bounds(
        self,
        positions: np.ndarray,
        covariances: np.ndarray,
        start: int,
        boundaries: np.ndarray,
        all_means: np.ndarray,
    ) -> np.ndarray:
        """Lower bounds ``(N, B)`` on ``sum_i log det Sigma_i^xy`` at each of ``boundaries``.

        Args:
            positions: ``(N, 2)`` agent positions of nodes at sub-step ``start``, m.
            covariances: ``(N, n, 4, 4)`` their target covariances.
            start: the nodes' sub-step index, counted from the decision.
            boundaries: ``(B,)`` later sub-step indices, at most ``start + max_sub_steps``.
            all_means: ``(S + 1, n, 2)`` predicted mean positions (`mean_positions`), m.
        """
        out = np.zeros((positions.shape[0], len(boundaries)))
        bound_children(
            self.mission.record,
            self.follow,
            np.ascontiguousarray(positions, dtype=float),
            np.ascontiguousarray(covariances, dtype=float),
            int(start),
            np.asarray(boundaries, dtype=np.int64),
            np.ascontiguousarray(all_means),
            out,
        )
        return out
