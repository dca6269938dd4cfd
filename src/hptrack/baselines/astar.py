"""A* with an information heuristic as a step-level baseline.

Schlotfeldt, Atanasov, Pappas, "Maximum Information Bounds for Planning Active Sensing
Trajectories", IROS 2019 (the seed paper's reference 8968147), with the seed paper's
modification (Sec. V-B): the step cost is the change of the total uncertainty
``sum_i log det Sigma_i^xy`` and the heuristic is changed to match. Set-up and defaults:
``docs/baselines.md``.

Best-first search over the tree of motion-primitive sequences (the one ARVI searches), on the
deterministic covariance sequences of `hptrack.baselines.information`: ``g`` is the
accumulated step cost and ``h`` the `RiccatiBound` lower
bound on the cost still to come, so ``f = g + h`` is admissible and the first complete
horizon-length node popped is optimal. With the difference cost the costs telescope and ``f`` is
the bound on the total ``log det`` at the end of the horizon. Ties in ``f`` go to the
lexicographically smallest control sequence, hover (control 0) first, so a search in which
nothing is reachable hovers. There is no duplicate pruning (the reference library has none).

Each expansion (the rollouts of all controls and their bounds) is one compiled call; only the
priority queue is Python. Per-decision effort is bounded deterministically by
``max_expansions`` and optionally by ``time_limit_s``; when either binds, the plan is the most
promising open node's sequence (least ``f``), padded with hover.

Behaviour to expect: the difference cost judges a plan only by the uncertainty at the end of
the horizon, which values a measurement of a second target late in the horizon as much as an
early one. Between a tracked target and a second one within reach, the optimal plan therefore
often stays first and leaves later, and replanning after every primitive postpones the switch
again; A* leaves only once a few more measurements of the tracked target are worth less than an
earlier arrival at the other, so it dwells far longer on one target than ARVI does.
"""

from __future__ import annotations

import heapq
import math
import time
from typing import TYPE_CHECKING, Annotated

import numba
import numpy as np
from pydantic import Field

from hptrack.baselines.controls import HOVER, DecisionStats, PrimitivePlanner, PrimitiveSettings
from hptrack.baselines.information import (
    CostKind,
    RiccatiBound,
    bound_children,
    mean_positions,
    rollout_children,
)
from hptrack.models.beliefs import position_logdet
from hptrack.settings import TimeLimit

if TYPE_CHECKING:
    from hptrack.interface import MissionSpec, Observation


class AStarSettings(PrimitiveSettings):
    """A* settings (defaults: ``docs/baselines.md``).

    Attributes:
        horizon: planning horizon in motion primitives (count; 6 x 5 s = 30 s).
        max_expansions: most node expansions per decision (count), the deterministic bound.
        heuristic_weight: factor on ``h`` (dimensionless; 1 keeps the search optimal).
        time_limit_s: optional wall time per decision, s; ``None`` for none (reproducible).
        cost: step cost, ``"difference"`` (seed paper) or ``"sum"`` (original A*).
    """

    horizon: Annotated[int, Field(ge=1, le=100)] = 6
    max_expansions: Annotated[int, Field(ge=1, le=10_000_000)] = 2000
    heuristic_weight: Annotated[float, Field(ge=0.0)] = 1.0
    time_limit_s: TimeLimit | None = None
    cost: CostKind = "difference"

    effort_fields = {"iterations": "max_expansions", "time_limit": "time_limit_s"}


@numba.njit(cache=True)
def _expand_node(
    node, first, nodes, f, step_displacements, all_means, n_steps, horizon, cost, mission, follow
):
    """Expand ``node`` into the node slots ``first .. first + C - 1`` and write their ``f``.

    ``nodes`` is the node arrays ``(positions, covariances, uncertainty, g, levels, parents,
    controls)``; ``cost`` is ``(difference, heuristic weight)``; ``mission`` the mission record
    and ``follow`` its Riccati tables (the heuristic's)."""
    positions, covariances, uncertainty, g, levels, parents, controls = nodes
    difference, weight = cost
    n_controls = step_displacements.shape[0]
    level = levels[node]
    last = first + n_controls
    rollout_children(
        mission,
        positions[node : node + 1],
        covariances[node : node + 1],
        np.arange(n_controls),
        step_displacements,
        all_means[level * n_steps : (level + 1) * n_steps + 1],
        True,
        covariances[first:last],
        uncertainty[first:last],
    )
    for c in range(n_controls):
        j = first + c
        positions[j, 0] = positions[node, 0] + n_steps * step_displacements[c, 0]
        positions[j, 1] = positions[node, 1] + n_steps * step_displacements[c, 1]
        step = uncertainty[j] - uncertainty[node] if difference else uncertainty[j]
        g[j] = g[node] + step
        levels[j] = level + 1
        parents[j] = node
        controls[j] = c
        f[c] = g[j]
    if level + 1 == horizon:
        return
    if difference:
        boundaries = np.array([horizon * n_steps])
    else:
        boundaries = np.arange(level + 2, horizon + 1) * n_steps
    bounds = np.zeros((n_controls, boundaries.shape[0]))
    bound_children(
        mission,
        follow,
        positions[first:last],
        covariances[first:last],
        (level + 1) * n_steps,
        boundaries,
        all_means,
        bounds,
    )
    for c in range(n_controls):
        if uncertainty[first + c] == np.inf:  # not a candidate (`rollout_children`)
            continue
        h = bounds[c, 0] - uncertainty[first + c] if difference else np.sum(bounds[c])
        f[c] += weight * h


class AStarPlanner(PrimitivePlanner):
    """A* over motion primitives (``--planner astar``); see the module docstring."""

    name = "astar"
    settings_type = AStarSettings
    settings: AStarSettings

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        """Start a mission: precompute the heuristic's Riccati maps for the horizon."""
        super().reset(mission, observation, rng)
        self.bound = RiccatiBound(mission, self.settings.horizon * self.settings.control_steps)

    def search(self, observation: Observation) -> tuple[np.ndarray, DecisionStats]:
        """A* from ``observation``: the optimal sequence, or the best open one if capped."""
        start = time.perf_counter()
        params, mission = self.settings, self.mission
        horizon = self.horizon_primitives(observation, params.horizon)
        k = params.control_steps
        n_controls = self.step_displacements.shape[0]
        means = mean_positions(
            np.asarray(observation.means, dtype=float), mission.motion, horizon * k
        )
        difference = params.cost == "difference"
        capacity = 1 + n_controls * params.max_expansions
        n_targets = observation.covariances.shape[0]
        positions = np.empty((capacity, 2))
        d = observation.covariances.shape[1]
        covariances = np.empty((capacity, n_targets, d, d))
        uncertainty, g = np.empty(capacity), np.empty(capacity)
        levels, parents, controls = (np.empty(capacity, dtype=np.int64) for _ in range(3))
        positions[0] = observation.agent_position
        covariances[0] = observation.covariances
        uncertainty[0] = float(np.sum(position_logdet(covariances[0])))
        g[0], levels[0], parents[0], controls[0] = 0.0, 0, -1, HOVER
        boundaries = np.array([horizon * k]) if difference else k * np.arange(1, horizon + 1)
        root_bounds = self.bound.lower_bounds(positions[:1], covariances[:1], 0, boundaries, means)[
            0
        ]
        h = root_bounds[0] - uncertainty[0] if difference else root_bounds.sum()
        f = np.empty(n_controls)
        nodes = (positions, covariances, uncertainty, g, levels, parents, controls)
        cost = (difference, float(params.heuristic_weight))
        # Entries (f, sequence code, node): the code orders sequences lexicographically with
        # hover first and a prefix before its extensions, so ties in f prefer hover.
        radix = n_controls + 1
        heap = [(params.heuristic_weight * float(h), 0, 0)]
        n_nodes, expansions, capped = 1, 0, False
        while True:
            _, code, node = heapq.heappop(heap)
            level = int(levels[node])
            if level == horizon:
                break
            if expansions >= params.max_expansions or (
                params.time_limit_s is not None
                and time.perf_counter() - start >= params.time_limit_s
            ):
                capped = True
                break
            expansions += 1
            _expand_node(
                node,
                n_nodes,
                nodes,
                f,
                self.step_displacements,
                means,
                k,
                horizon,
                cost,
                mission.record,
                self.bound.follow,
            )
            place = radix ** (horizon - 1 - level)
            for c, f_child in enumerate(f.tolist()):
                if f_child != math.inf:  # inf: a primitive the fenced vehicle may not fly
                    heapq.heappush(heap, (f_child, code + (c + 1) * place, n_nodes + c))
            n_nodes += n_controls
        plan = np.full(horizon, HOVER, dtype=np.int64)
        plan_cost = float(g[node])
        for depth in range(int(levels[node]), 0, -1):
            plan[depth - 1] = controls[node]
            node = int(parents[node])
        return plan, DecisionStats(observation.step, 0.0, expansions, 1, capped, plan_cost)
