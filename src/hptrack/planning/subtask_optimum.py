"""The exact optimum of the sub-task MDP for a few targets, by exhaustive expectimax.

The tree search (paper Algorithm 1) estimates ``max over policies of E[-U]`` in the sub-task MDP
(`hptrack.planning.subtask_mdp`) from sampled histories. When the problem is small (two or
three targets, a short budget) the expectation can be computed exactly instead: the value of a
state is ``-U`` when no action is available (Sec. III), otherwise the maximum over its available
actions of

    p_find V(state after the find) + (1 - p_find) V(state after the miss),

with the transitions and ``p_find`` of the MDP's own kernels. Every history is enumerated (states
are not merged), so the cost grows as the number of available actions to the power of the number
of decisions; `optimal_plan` refuses a problem past ``max_nodes``. It is a yardstick: what
the MDP says is best, to tell a search that has not found the best plan from an MDP whose best
plan is poor (``benchmarks/search_diagnostics.py optimum``).
"""

from __future__ import annotations

from dataclasses import dataclass

from hptrack.models.mission import state_size
from hptrack.planning.subtask_mdp import (
    FIND,
    MISS,
    PAPER_SUBTASK,
    PlanningProblem,
    SubtaskOptions,
    apply_outcome,
    expand_action,
    is_available,
    new_work,
    terminal_value,
)


@dataclass(frozen=True)
class OptimalPlan:
    """The MDP's best policy from a problem's root.

    Attributes:
        value: its expected return ``E[-U]`` (``U``: sum of log det Sigma^xy at the budget's end).
        action_values: the exact value of each available root action (followed by the best
            policy), by action.
        actions: the best actions along the history where every pursuit finds its target
            (target indices; the target just found again follows it to the end; dwells are
            ``n`` and after).
        p_find: each of those actions' probability of the find (1 for a follow or a dwell).
        steps: each of those actions' duration when it finds, in steps of ``tau``.
        nodes: state nodes enumerated.
    """

    value: float
    action_values: dict[int, float]
    actions: tuple[int, ...]
    p_find: tuple[float, ...]
    steps: tuple[int, ...]
    nodes: int


class _Expectimax:
    """The recursion of the module docstring on one MDP ``env``, counting state nodes."""

    def __init__(self, env, max_nodes: int) -> None:
        self.env, self.max_nodes, self.nodes = env, max_nodes, 0
        self.work = new_work(state_size(env.mission))
        self.n_actions = env.means.shape[0] + env.stay_steps.shape[0]

    def solve(self, state, actions=None) -> tuple[dict[int, float], list[tuple[int, float, int]]]:
        """The exact values of ``state``'s available ``actions`` (default all) and the best
        actions along its all-find history (empty when none is available)."""
        env, work = self.env, self.work
        self.nodes += 1
        if self.nodes > self.max_nodes:
            raise ValueError(
                f"the exact optimum needs more than max_nodes={self.max_nodes} state nodes"
            )
        values, best_rest, best = {}, [], None
        for a in range(self.n_actions) if actions is None else actions:
            if not is_available(env, state, a):
                continue
            p, find_steps, miss_steps = expand_action(env, state, a, work)
            after = tuple(x.copy() for x in state)
            apply_outcome(env, after, a, FIND, find_steps, work)
            v_find, rest = self.value(after)
            v = p * v_find
            if p < 1.0:
                after = tuple(x.copy() for x in state)
                apply_outcome(env, after, a, MISS, miss_steps, work)
                v += (1.0 - p) * self.value(after)[0]
            values[a] = v
            if best is None or v > values[best]:
                best, best_rest = a, [(a, p, find_steps), *rest]
        return values, best_rest

    def value(self, state) -> tuple[float, list[tuple[int, float, int]]]:
        """``V(state)`` and the best actions along its all-find history."""
        values, plan = self.solve(state)
        if not values:
            return float(terminal_value(self.env, state)), []
        return max(values.values()), plan


def action_values(env, state, max_nodes: int = 1_000_000) -> dict[int, float]:
    """The exact value of each available action of ``state`` in the MDP ``env``
    (`env`), each followed by the best
    policy.

    Raises:
        ValueError: the enumeration needs more than ``max_nodes`` state nodes.
    """
    return _Expectimax(env, max_nodes).solve(state)[0]


def optimal_plan(
    problem: PlanningProblem,
    options: SubtaskOptions = PAPER_SUBTASK,
    max_nodes: int = 1_000_000,
) -> OptimalPlan:
    """The exact optimum of the sub-task MDP with ``options`` from ``problem``'s root (module
    docstring). With ``problem.current_action`` set, the root's only action is that one.

    Raises:
        ValueError: the enumeration needs more than ``max_nodes`` state nodes.
    """
    solver = _Expectimax(problem.env(options), max_nodes)
    fixed = problem.current_action
    values, plan = solver.solve(problem.root_state(), None if fixed is None else [fixed])
    if not values:
        raise ValueError("the root has no available action")
    return OptimalPlan(
        max(values.values()),
        {int(a): float(v) for a, v in values.items()},
        tuple(int(a) for a, _, _ in plan),
        tuple(float(p) for _, p, _ in plan),
        tuple(int(s) for _, _, s in plan),
        solver.nodes,
    )
