"""Anytime Reduced Value Iteration (ARVI) as a step-level baseline.

Schlotfeldt, Thakur, Atanasov, Kumar, Pappas, "Anytime Planning for Decentralized Multirobot
Active Information Gathering", IEEE RA-L 2018, built on Reduced Value Iteration (Atanasov et al.,
"Information acquisition with sensing robots: algorithms and error bounds", ICRA 2014), with the
seed paper's modification (Sec. V-B): the step cost is the change of the total uncertainty, so
the cost of a plan is the total ``log det Sigma^xy`` at the end of the horizon minus the one now.
Set-up and defaults: ``docs/baselines.md``.

One pass is a forward search, level by level over the horizon, on the deterministic covariance
sequences of `hptrack.baselines.information`. Every kept node of a level is expanded with
every control (all at once, compiled), the children are sorted by accumulated cost and pruned
greedily: a child is dropped when a kept child of the same level lies closer than ``delta`` to
it and is at least as good up to ``epsilon``, ``Sigma_kept <= Sigma_new + epsilon I`` in the
positive-semidefinite order on every target's block. ``delta = 0`` is exact value iteration;
``delta = inf`` with ``epsilon = inf`` keeps one node per level (the greedy pass). The anytime
loop runs the passes of a schedule from coarse to fine and keeps the best plan of all of them.
The distance test is strict so that ``delta`` equal to a primitive's length (150 m) still keeps
the four axis-aligned children of a level whose costs all tie; with ``<=`` the hover child,
first among ties, would prune every other one and the pass would never leave the spot.

Per-decision effort is bounded deterministically by the schedule and ``max_nodes_per_level``
(the best nodes of a level by cost are kept when more survive pruning); ``time_limit_s``
optionally stops starting further passes once that much wall time is spent.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Self

import numba
import numpy as np
from pydantic import Field, model_validator

from hptrack.baselines.controls import DecisionStats, PrimitivePlanner, PrimitiveSettings, Schedule
from hptrack.baselines.information import (
    CostKind,
    child_covariances,
    expand,
    expand_uncertainty,
    mean_positions,
    step_costs,
)
from hptrack.models.beliefs import position_logdet
from hptrack.settings import Iterations, TimeLimit

if TYPE_CHECKING:
    from hptrack.interface import Observation

_MAX_GRID_CELLS = 512
"""Largest number of pruning-grid cells per axis (the cells grow beyond ``delta`` if needed)."""


class ArviSettings(PrimitiveSettings):
    """ARVI settings (defaults: ``docs/baselines.md``).

    Attributes:
        horizon: planning horizon in motion primitives (count; 12 x 5 s = 60 s).
        delta_schedule_m: the anytime schedule of position-pruning radii ``delta``, m, coarse to
            fine; ``inf`` is the greedy pass (one node per level).
        epsilon_schedule: covariance slack ``epsilon`` of each pass, in the covariance's units
            (m^2 on the position block, (m/s)^2 on the velocity block, as ``epsilon I`` in
            Atanasov et al. 2014); one value applies to every pass; ``inf`` prunes on
            position alone.
        max_nodes_per_level: most nodes kept per level after pruning (count), the
            deterministic bound on a pass's effort.
        time_limit_s: optional wall time per decision, s: no further pass starts once it is
            spent (``None``: run the whole schedule, reproducible on any machine).
        cost: step cost, ``"difference"`` (seed paper) or ``"sum"`` (original ARVI).
    """

    horizon: Annotated[int, Field(ge=1, le=1000)] = 12
    delta_schedule_m: Schedule = (math.inf, 150.0, 100.0, 75.0, 50.0)
    epsilon_schedule: Schedule = (math.inf,)
    max_nodes_per_level: Iterations = 2000
    time_limit_s: TimeLimit | None = None
    cost: CostKind = "difference"

    effort_fields = {"time_limit": "time_limit_s"}

    @model_validator(mode="after")
    def _schedules(self) -> Self:
        if len(self.epsilon_schedule) not in (1, len(self.delta_schedule_m)):
            raise ValueError(
                "option epsilon_schedule needs one value or one per "
                f"delta_schedule_m entry, got {list(self.epsilon_schedule)}"
            )
        return self

    def passes(self) -> list[tuple[float, float]]:
        """``(delta_m, epsilon)`` of each anytime pass, in order."""
        eps = self.epsilon_schedule * (len(self.delta_schedule_m) // len(self.epsilon_schedule))
        return list(zip(self.delta_schedule_m, eps, strict=True))


@numba.njit(cache=True)
def _dominated(kept: np.ndarray, new: np.ndarray, epsilon: float) -> bool:
    """Whether ``kept <= new + epsilon I`` on every target block ``(n, d, d)``."""
    d = kept.shape[1]
    diff = np.empty((d, d))
    for i in range(kept.shape[0]):
        scale = 1.0
        for r in range(d):
            for c in range(d):
                diff[r, c] = new[i, r, c] - kept[i, r, c]
                scale = max(scale, abs(new[i, r, c]), abs(kept[i, r, c]))
            diff[r, r] += epsilon
        if np.linalg.eigvalsh(diff)[0] < -1e-12 * scale:
            return False
    return True


@numba.njit(cache=True)
def _prune(positions, covariances, order, delta, epsilon, max_keep):
    """Greedy (epsilon, delta) pruning of nodes visited in ``order``; kept indices, in order.

    Kept nodes are hashed on a grid of cells at least ``delta`` wide, so the kept nodes within
    ``delta`` of a node lie in its cell or the 8 around it.
    """
    x0, y0 = positions[0, 0], positions[0, 1]
    x1, y1 = x0, y0
    for j in range(positions.shape[0]):
        x0, x1 = min(x0, positions[j, 0]), max(x1, positions[j, 0])
        y0, y1 = min(y0, positions[j, 1]), max(y1, positions[j, 1])
    extent = max(x1 - x0, y1 - y0)
    cell = max(delta, extent / _MAX_GRID_CELLS, 1e-6)
    n_cells = 1 if cell == np.inf else int(min(extent / cell, _MAX_GRID_CELLS)) + 1
    if n_cells == 1:
        cell = extent + 1.0
    head = np.full(n_cells * n_cells, -1, dtype=np.int64)
    nxt = np.full(positions.shape[0], -1, dtype=np.int64)
    kept = np.empty(min(max_keep, order.shape[0]), dtype=np.int64)
    n_kept = 0
    delta2 = delta * delta
    for j in order:
        if n_kept == max_keep:
            return kept, True
        cx = min(int((positions[j, 0] - x0) / cell), n_cells - 1)
        cy = min(int((positions[j, 1] - y0) / cell), n_cells - 1)
        redundant = False
        for gx in range(max(cx - 1, 0), min(cx + 2, n_cells)):
            for gy in range(max(cy - 1, 0), min(cy + 2, n_cells)):
                k = head[gx * n_cells + gy]
                while k >= 0 and not redundant:
                    dx = positions[k, 0] - positions[j, 0]
                    dy = positions[k, 1] - positions[j, 1]
                    if dx * dx + dy * dy < delta2 and (
                        epsilon == np.inf or _dominated(covariances[k], covariances[j], epsilon)
                    ):
                        redundant = True
                    k = nxt[k]
        if not redundant:
            kept[n_kept] = j
            n_kept += 1
            nxt[j] = head[cx * n_cells + cy]
            head[cx * n_cells + cy] = j
    return kept[:n_kept], False


def prune(
    positions: np.ndarray,
    costs: np.ndarray,
    covariances: np.ndarray | None,
    delta_m: float,
    epsilon: float,
    max_keep: int,
) -> tuple[np.ndarray, bool]:
    """Reduced-value-iteration pruning of one level (Atanasov et al. 2014, Alg. 2).

    Nodes are visited by increasing cost (stable, so earlier nodes win ties), those of infinite
    cost (not candidates: a primitive the fenced vehicle may not fly) never; a node is kept
    unless a kept node lies closer than ``delta_m`` to it and ``Sigma_kept <= Sigma + epsilon I``
    on every target block (all eigenvalues, not only the diagonal). The cheapest node is
    therefore always kept, and first.

    Args:
        positions: ``(M, 2)`` agent positions, m.
        costs: ``(M,)`` accumulated costs (``inf``: not a candidate).
        covariances: ``(M, n, d, d)`` target covariances (``None`` when ``epsilon`` is
            ``inf``).
        delta_m: position radius, m (``0`` prunes nothing; ``inf`` keeps only the cheapest
            node when ``epsilon`` is ``inf``).
        epsilon: covariance slack (``inf`` ignores covariances).
        max_keep: most nodes kept (count).

    Returns:
        Kept indices ordered by cost, and whether ``max_keep`` cut off further nodes.
    """
    order = np.argsort(costs, kind="stable")
    order = order[np.isfinite(costs[order])]
    if covariances is None:
        if not math.isinf(epsilon):
            raise ValueError("a finite epsilon needs the covariances")
        covariances = np.empty((0, 0, 1, 1))
    return _prune(
        np.ascontiguousarray(positions),
        np.ascontiguousarray(covariances),
        order,
        float(delta_m),
        float(epsilon),
        int(max_keep),
    )


@dataclass(frozen=True)
class PassResult:
    """One ARVI pass: the best leaf's control sequence and cost, and the pass's effort."""

    plan: np.ndarray
    cost: float
    nodes_expanded: int
    capped: bool


class ArviPlanner(PrimitivePlanner):
    """ARVI over motion primitives (``--planner arvi``); see the module docstring."""

    name = "arvi"
    settings_type = ArviSettings
    settings: ArviSettings

    def search(self, observation: Observation) -> tuple[np.ndarray, DecisionStats]:
        """Run the anytime schedule from ``observation``; the best plan over all passes."""
        start = time.perf_counter()
        horizon = self.horizon_primitives(observation, self.settings.horizon)
        means = mean_positions(
            np.asarray(observation.means, dtype=float),
            self.mission.motion,
            horizon * self.settings.control_steps,
        )
        best: PassResult | None = None
        expanded, passes, capped = 0, 0, False
        for delta, epsilon in self.settings.passes():
            limit = self.settings.time_limit_s
            if passes and limit is not None and time.perf_counter() - start >= limit:
                break
            result = self.run_pass(observation, means, horizon, delta, epsilon)
            expanded += result.nodes_expanded
            capped |= result.capped
            passes += 1
            if best is None or result.cost < best.cost:
                best = result
        assert best is not None
        return best.plan, DecisionStats(observation.step, 0.0, expanded, passes, capped, best.cost)

    def run_pass(
        self,
        observation: Observation,
        means: np.ndarray,
        horizon: int,
        delta_m: float,
        epsilon: float,
    ) -> PassResult:
        """One reduced value iteration pass with pruning ``(delta_m, epsilon)``.

        ``means`` are the predicted mean positions of every sub-step of the ``horizon``
        primitives (`mean_positions`).
        """
        k = self.settings.control_steps
        n_controls = self.step_displacements.shape[0]
        positions = np.asarray(observation.agent_position, dtype=float)[None, :]
        covariances = np.asarray(observation.covariances, dtype=float)[None]
        uncertainty = np.array([float(np.sum(position_logdet(covariances[0])))])
        costs = np.zeros(1)
        parents: list[np.ndarray] = []
        controls: list[np.ndarray] = []
        expanded, capped = 0, False
        for level in range(horizon):
            level_means = means[level * k : (level + 1) * k + 1]
            if math.isinf(epsilon):
                child_pos, child_unc = expand_uncertainty(
                    self.mission, self.step_displacements, level_means, positions, covariances
                )
                child_covs = None
            else:
                child_pos, child_covs, child_unc = expand(
                    self.mission, self.step_displacements, level_means, positions, covariances
                )
            expanded += positions.shape[0]
            child_costs = np.repeat(costs, n_controls) + step_costs(
                np.repeat(uncertainty, n_controls), child_unc, self.settings.cost
            )
            if level == horizon - 1:
                keep = np.array([int(np.argmin(child_costs))])
            else:
                keep, level_capped = prune(
                    child_pos,
                    child_costs,
                    child_covs,
                    delta_m,
                    epsilon,
                    self.settings.max_nodes_per_level,
                )
                capped |= level_capped
                covariances = (
                    child_covs[keep]
                    if child_covs is not None
                    else child_covariances(
                        self.mission,
                        self.step_displacements,
                        level_means,
                        positions,
                        covariances,
                        keep,
                    )
                )
            parents.append(keep // n_controls)
            controls.append(keep % n_controls)
            positions, costs, uncertainty = child_pos[keep], child_costs[keep], child_unc[keep]
        plan = np.empty(horizon, dtype=np.int64)
        node = 0
        for level in range(horizon - 1, -1, -1):
            plan[level] = controls[level][node]
            node = parents[level][node]
        return PassResult(plan, float(costs[0]), expanded, capped)
