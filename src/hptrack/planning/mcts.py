"""Monte Carlo tree search over the sub-task MDP (paper Sec. IV-C-3, Algorithm 1; re-planning
Sec. IV-C-4, Algorithm 1 lines 9-12).

The search is a pure function of ``(problem, seed, number of simulations)``: the same inputs
give the same tree and the same plan, whether the simulations ran in one call or in chunks
between wall-clock checks.

**Tree.** Preallocated arrays indexed by node id (:class:`Tree`), doubled when full; no Python
object per node. A state node stores its visit count ``N(N^s)``, its first action slot and the
number of slots; an action node stores the target, the expansion results (``p_find`` and the
sub-task's duration for each outcome, in steps), ``N(N^a)``, ``V(N^a)`` and its two children
(find, miss). States are not stored: the descent rebuilds the state from the root by applying the
stored transitions (O(1) per level, :mod:`hptrack.planning.mdp`), so memory stays small at
millions of simulations.

**Simulate** (Algorithm 1 lines 15-34), iteratively:

* a state at the end of the budget, or without any available action, is terminal: its value
  ``-U`` is computed once and cached in the node (lines 16-17);
* first visit (lines 18-22): the node is expanded and a rollout with the uniformly random policy
  runs to the end of the budget. The expansion is deterministic, so it is stored lazily: the
  action slots are allocated on the second visit and each action's estimator call is made the
  first time the action is selected; the tree's statistics are the same as with an eager
  expansion, at a fraction of the cost (most leaves are never visited twice);
* otherwise UCB1 (line 23) picks ``argmax V_hat(N^a) + c sqrt(ln N(N^s) / N(N^a))``, unvisited
  actions first (in target order). Values ``V = -U`` are normalised to ``[0, 1]`` by the smallest
  and largest return seen so far in this search, ``V_hat = (V - min) / (max - min)``, so ``c``
  (``exploration``) is relative to the observed value range and does not depend on the number
  of targets or the scale of ``U``;
* the outcome is drawn from ``p_find`` (line 25) and the child state created on first draw
  (lines 26-29); values are backed up as running means (lines 31-33).

**Re-planning** (lines 9-12): the root's only action is the current one, and the result gives
``argmax V`` over the actions of its find child and of its miss child. As both answers are
needed whatever ``p_find`` is (it is often above 0.99), the root's outcome alternates between
find and miss instead of being drawn, so each child gets half of the simulations; below the
root everything is as above. (The root's own value then weighs both outcomes equally; it is
not used for any decision.)

**Randomness.** A splitmix64 stream seeded from the caller's seed drives the rollouts and the
outcome draws; its state lives in the search, not in a global generator.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numba
import numpy as np

from hptrack.planning.mdp import (
    I_STEP,
    WORK_SLOTS,
    PlanningProblem,
    apply_outcome,
    expand_action,
    is_available,
    new_memo,
    terminal_value,
)

DEFAULT_EXPLORATION = 0.5
"""UCB1 constant ``c`` on values normalised to the observed return range."""

UNVISITED = -2
"""``Tree.s_first`` of a state node created but never visited."""
LEAF = -1
"""``Tree.s_first`` of a state node visited once (rolled out, no action slots yet)."""
TERMINAL = -3
"""``Tree.s_first`` of a terminal state node (value cached in ``Tree.s_value``)."""

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)


class Tree(NamedTuple):
    """The search tree as arrays (state nodes ``s_*``, action nodes ``a_*``).

    ``counts`` holds ``[state nodes, action nodes, simulations run]``; ``value_range`` the
    smallest and largest return seen; ``rng`` the random stream's state.
    """

    s_first: np.ndarray
    s_count: np.ndarray
    s_visits: np.ndarray
    s_value: np.ndarray
    a_target: np.ndarray
    a_p: np.ndarray
    a_find: np.ndarray
    a_miss: np.ndarray
    a_visits: np.ndarray
    a_value: np.ndarray
    a_child: np.ndarray
    counts: np.ndarray
    value_range: np.ndarray
    rng: np.ndarray


_FILL = {
    "s_first": (UNVISITED, np.int32), "s_count": (0, np.int8), "s_visits": (0, np.int32),
    "s_value": (np.nan, np.float64), "a_target": (0, np.int8), "a_p": (-1.0, np.float64),
    "a_find": (0, np.int32), "a_miss": (0, np.int32), "a_visits": (0, np.int32),
    "a_value": (0.0, np.float64), "a_child": (-1, np.int32),
}
"""Initial value and dtype of each node array of :class:`Tree`."""


def new_tree(seed: int, capacity: int = 1024) -> Tree:
    """An empty tree holding only the root (state node 0), with the random stream seeded."""
    arrays = {name: np.full((capacity, 2) if name == "a_child" else capacity, fill, dtype=dtype)
              for name, (fill, dtype) in _FILL.items()}
    return Tree(**arrays, counts=np.array([1, 0, 0], dtype=np.int64),
                value_range=np.array([np.inf, -np.inf]), rng=np.array([seed], dtype=np.uint64))


def grow_tree(tree: Tree, n_targets: int) -> Tree:
    """The tree with its state (action) arrays doubled if one more state node (``n_targets``
    more action nodes) might not fit: what one simulation can add at most."""
    arrays = tree._asdict()
    for prefix, size, need in (("s_", tree.s_first.shape[0], tree.counts[0] + 1),
                               ("a_", tree.a_target.shape[0], tree.counts[1] + n_targets)):
        if need <= size:
            continue
        extra = max(size, need - size)
        for name, (fill, dtype) in _FILL.items():
            if name.startswith(prefix):
                old = arrays[name]
                arrays[name] = np.concatenate(
                    [old, np.full((extra, *old.shape[1:]), fill, dtype=dtype)])
    return Tree(**arrays)


@numba.njit(cache=True)
def _uniform(rng):
    """Next double in ``[0, 1)`` of the splitmix64 stream ``rng`` (one ``uint64``)."""
    rng[0] += _GOLDEN
    z = rng[0]
    z = (z ^ (z >> np.uint64(30))) * _MIX1
    z = (z ^ (z >> np.uint64(27))) * _MIX2
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True)
def _select(tree, s, exploration):
    """UCB1 (Algorithm 1 line 23) over the action slots of state node ``s``: the first unvisited
    action, else ``argmax V_hat + c sqrt(ln N(s) / N(a))`` with normalised values."""
    first = tree.s_first[s]
    count = tree.s_count[s]
    for x in range(first, first + count):
        if tree.a_visits[x] == 0:
            return x
    low, high = tree.value_range[0], tree.value_range[1]
    scale = 1.0 / (high - low) if high > low else 0.0
    log_n = math.log(tree.s_visits[s])
    best = first
    best_score = -np.inf
    for x in range(first, first + count):
        score = ((tree.a_value[x] - low) * scale
                 + exploration * math.sqrt(log_n / tree.a_visits[x]))
        if score > best_score:
            best_score = score
            best = x
    return best


@numba.njit(cache=True)
def _rollout(model, memo, si, sf, base_cov, base_step, forced, rng, candidates, work):
    """Random policy from the state to the end of the budget (Algorithm 1 line 21); returns
    ``-U``. ``forced >= 0`` fixes the first action (re-planning at the root)."""
    n = base_cov.shape[0]
    while si[I_STEP] < model.n_steps:
        if forced >= 0:
            a = forced
            forced = -1
        else:
            count = 0
            for i in range(n):
                if is_available(model, si, sf, i):
                    candidates[count] = i
                    count += 1
            if count == 0:
                break
            a = candidates[int(_uniform(rng) * count)]
        _, p, find_steps, miss_steps = expand_action(model, memo, si, sf, base_cov, base_step, a,
                                                     work)
        found = _uniform(rng) < p
        apply_outcome(model, si, sf, base_cov, base_step, a, found,
                      find_steps if found else miss_steps, work)
    return terminal_value(model, base_cov, base_step)


@numba.njit(cache=True)
def _open_slots(tree, model, s, si, sf, fixed):
    """Allocate the action slots of state node ``s`` (its available actions, in target order;
    only ``fixed`` at the root in re-planning mode)."""
    n = model.means.shape[0]
    first = tree.counts[1]
    count = 0
    for a in range(n):
        if (fixed < 0 or s != 0 or a == fixed) and is_available(model, si, sf, a):
            x = first + count
            tree.a_target[x] = a
            tree.a_p[x] = -1.0
            count += 1
    tree.counts[1] += count
    tree.s_first[s] = first
    tree.s_count[s] = count


@numba.njit(cache=True)
def _catch_up(tree, model, path_action, path_found, applied, depth, root_cov, root_si, root_sf,
              si, sf, base_cov, base_step, work):
    """Bring the scratch state from path level ``applied`` (``-1``: not reset yet) to ``depth``
    by re-applying the stored transitions from the root; returns ``depth``."""
    if applied < 0:
        for i in range(3):
            si[i] = root_si[i]
        sf[0] = root_sf[0]
        sf[1] = root_sf[1]
        for a in range(base_cov.shape[0]):
            base_step[a] = 0
            for i in range(4):
                for j in range(4):
                    base_cov[a, i, j] = root_cov[a, i, j]
        applied = 0
    for d in range(applied, depth):
        x = path_action[d]
        found = path_found[d]
        apply_outcome(model, si, sf, base_cov, base_step, np.int64(tree.a_target[x]), found,
                      tree.a_find[x] if found else tree.a_miss[x], work)
    return depth


@numba.njit(cache=True)
def run_simulations(tree, model, memo, root_cov, root_si, root_sf, fixed, exploration,
                    n_simulations):
    """Run up to ``n_simulations`` simulations (Algorithm 1, ``Simulate`` from the root) and
    return how many ran: it stops early when the tree's arrays might not hold one more
    simulation's nodes (:func:`grow_tree` makes room).

    The state along the descent is rebuilt only when it is needed (a first visit, opening the
    action slots, or a first estimator call): a descent to a cached terminal node costs no
    transition at all.
    """
    n = root_cov.shape[0]
    si = np.empty(3, dtype=np.int64)
    sf = np.empty(2)
    base_cov = np.empty((n, 4, 4))
    base_step = np.empty(n, dtype=np.int64)
    candidates = np.empty(n, dtype=np.int64)
    work = np.empty((WORK_SLOTS, 4, 4))
    path_state = np.empty(model.n_steps + 2, dtype=np.int64)
    path_action = np.empty(model.n_steps + 2, dtype=np.int64)
    path_found = np.empty(model.n_steps + 2, dtype=np.bool_)
    cap_s = tree.s_first.shape[0]
    cap_a = tree.a_target.shape[0]
    for sim in range(n_simulations):
        if tree.counts[0] + 1 > cap_s or tree.counts[1] + n > cap_a:
            return sim
        s = 0
        depth = 0
        applied = -1
        while True:
            first = tree.s_first[s]
            if first == TERMINAL:
                ret = tree.s_value[s]
                break
            if first < 0:
                applied = _catch_up(tree, model, path_action, path_found, applied, depth,
                                    root_cov, root_si, root_sf, si, sf, base_cov, base_step,
                                    work)
            if first == UNVISITED:
                live = False
                for a in range(n):
                    if is_available(model, si, sf, a):
                        live = True
                        break
                if not live:
                    ret = terminal_value(model, base_cov, base_step)
                    tree.s_first[s] = TERMINAL
                    tree.s_value[s] = ret
                    break
                tree.s_first[s] = LEAF
                ret = _rollout(model, memo, si, sf, base_cov, base_step,
                               fixed if s == 0 else -1, tree.rng, candidates, work)
                break
            if first == LEAF:
                _open_slots(tree, model, s, si, sf, fixed)
            x = _select(tree, s, exploration)
            if tree.a_p[x] < 0.0:
                applied = _catch_up(tree, model, path_action, path_found, applied, depth,
                                    root_cov, root_si, root_sf, si, sf, base_cov, base_step,
                                    work)
                _, p, find_steps, miss_steps = expand_action(
                    model, memo, si, sf, base_cov, base_step, np.int64(tree.a_target[x]), work)
                tree.a_p[x] = p
                tree.a_find[x] = find_steps
                tree.a_miss[x] = miss_steps
            if s == 0 and fixed >= 0 and 0.0 < tree.a_p[x] < 1.0:
                found = tree.counts[2] % 2 == 1  # re-planning: both outcomes need a plan
            else:
                found = _uniform(tree.rng) < tree.a_p[x]
            path_state[depth] = s
            path_action[depth] = x
            path_found[depth] = found
            depth += 1
            outcome = 0 if found else 1
            child = tree.a_child[x, outcome]
            if child < 0:
                child = tree.counts[0]
                tree.counts[0] += 1
                tree.a_child[x, outcome] = child
            s = child
        for d in range(depth):
            x = path_action[d]
            tree.s_visits[path_state[d]] += 1
            tree.a_visits[x] += 1
            tree.a_value[x] += (ret - tree.a_value[x]) / tree.a_visits[x]
        tree.value_range[0] = min(tree.value_range[0], ret)
        tree.value_range[1] = max(tree.value_range[1], ret)
        tree.counts[2] += 1
    return n_simulations


@dataclass(frozen=True, eq=False)
class ActionStats:
    """The actions of one state node and their statistics (arrays of equal length).

    Attributes:
        actions: target indices.
        visits: ``N(N^a)``.
        values: ``V(N^a)``, the mean of ``-U`` over the simulations through the action.
        p_find: estimated probability of finding the target (NaN if never expanded).
        find_steps: the sub-task's duration if the target is found, steps.
        miss_steps: its duration if it is missed, steps.
    """

    actions: np.ndarray
    visits: np.ndarray
    values: np.ndarray
    p_find: np.ndarray
    find_steps: np.ndarray
    miss_steps: np.ndarray

    @property
    def best(self) -> int | None:
        """``argmax V`` over the visited actions (Algorithm 1 lines 12-13), ``None`` if none."""
        visited = np.flatnonzero(self.visits > 0)
        if visited.size == 0:
            return None
        return int(self.actions[visited[np.argmax(self.values[visited])]])


@dataclass(frozen=True, eq=False)
class SearchResult:
    """The outcome of :func:`search`.

    Attributes:
        best_action: the target to pursue (first plan), or the fixed current action
            (re-planning); ``None`` when no action is available.
        root: statistics of the root's actions.
        after_find: re-planning only: the actions after the current one finds its target
            (``None`` when that state was never reached or is terminal).
        after_miss: likewise after a miss.
        simulations: number of simulations run.
        stopped_by: ``"iterations"`` or ``"time_limit"``.
        elapsed: wall time of the search, s.
        state_nodes: state nodes in the tree.
        action_nodes: action nodes in the tree.
        tree_bytes: memory held by the tree's arrays (allocated capacity), bytes.
    """

    best_action: int | None
    root: ActionStats
    after_find: ActionStats | None
    after_miss: ActionStats | None
    simulations: int
    stopped_by: Literal["iterations", "time_limit"]
    elapsed: float
    state_nodes: int
    action_nodes: int
    tree_bytes: int

    @property
    def best_after_find(self) -> int | None:
        """Re-planning: the next target if the current sub-task finds its target."""
        return None if self.after_find is None else self.after_find.best

    @property
    def best_after_miss(self) -> int | None:
        """Re-planning: the next target if the current sub-task misses its target."""
        return None if self.after_miss is None else self.after_miss.best


def _stats(tree: Tree, s: int) -> ActionStats | None:
    first = int(tree.s_first[s])
    if first < 0:
        return None
    xs = slice(first, first + int(tree.s_count[s]))
    p = tree.a_p[xs].copy()
    p[p < 0.0] = np.nan
    return ActionStats(tree.a_target[xs].astype(np.int64), tree.a_visits[xs].astype(np.int64),
                       tree.a_value[xs].copy(), p, tree.a_find[xs].astype(np.int64),
                       tree.a_miss[xs].astype(np.int64))


def _seed_value(seed: int | np.random.Generator) -> int:
    if isinstance(seed, np.random.Generator):
        return int(seed.integers(0, 2**63, dtype=np.uint64))
    return int(np.random.SeedSequence(seed).generate_state(1, np.uint64)[0])


def search(problem: PlanningProblem, iterations: int | None = None,
           time_limit: float | None = None, seed: int | np.random.Generator = 0,
           exploration: float = DEFAULT_EXPLORATION) -> SearchResult:
    """Plan from ``problem``'s root state with Algorithm 1 (``TreeSearch``).

    Args:
        problem: root state and model; with ``current_action`` set, re-planning mode: the root's
            only action is the current one and the result gives the best next action after
            each of its outcomes (Algorithm 1 lines 9-12).
        iterations: stop after this many simulations.
        time_limit: stop once this wall time (s) has passed, checked between chunks of
            simulations. With both limits, whichever comes first.
        seed: an integer or a :class:`numpy.random.Generator` (one ``uint64`` is drawn from it).
            The same seed and number of simulations give the same tree and plan.
        exploration: UCB1 constant ``c`` on values normalised to the observed return range.

    Raises:
        ValueError: no limit given, a limit not positive, or a current action that cannot be
            carried out in the remaining budget.
    """
    if iterations is None and time_limit is None:
        raise ValueError("give iterations, time_limit or both")
    if iterations is not None and iterations < 1:
        raise ValueError(f"iterations must be positive, got {iterations}")
    if time_limit is not None and not time_limit > 0.0:
        raise ValueError(f"time_limit must be positive, got {time_limit}")
    start = time.perf_counter()
    model = problem.model()
    memo = new_memo(problem.n_targets, problem.n_steps)
    root_si, root_sf, root_cov, _ = problem.root_state()
    fixed = -1 if problem.current_action is None else problem.current_action
    if fixed >= 0 and not is_available(model, root_si, root_sf, fixed):
        raise ValueError(f"current action {fixed} cannot be carried out in the remaining budget")
    tree = new_tree(_seed_value(seed))
    done = 0
    chunk = 64
    while True:
        todo = chunk if iterations is None else min(chunk, iterations - done)
        ran = run_simulations(tree, model, memo, root_cov, root_si, root_sf, fixed,
                              float(exploration), todo)
        if ran < todo:
            tree = grow_tree(tree, problem.n_targets)
        done += ran
        if iterations is not None and done >= iterations:
            stopped_by = "iterations"
            break
        if time_limit is not None:
            elapsed = time.perf_counter() - start
            left = time_limit - elapsed
            if left <= 0.0:
                stopped_by = "time_limit"
                break
            chunk = max(1, min(8 * chunk, int(done / elapsed * min(left, 0.05)) + 1))
        else:
            chunk = min(8 * chunk, 65536)
    return _result(tree, fixed, stopped_by, time.perf_counter() - start)


def _result(tree: Tree, fixed: int, stopped_by: str, elapsed: float) -> SearchResult:
    root = _stats(tree, 0)
    empty = np.zeros(0, dtype=np.int64)
    if root is None:
        root = ActionStats(empty, empty, np.zeros(0), np.zeros(0), empty, empty)
    after_find = after_miss = None
    if fixed >= 0 and root.actions.size:
        children = tree.a_child[int(tree.s_first[0])]
        after_find = None if children[0] < 0 else _stats(tree, int(children[0]))
        after_miss = None if children[1] < 0 else _stats(tree, int(children[1]))
    return SearchResult(
        best_action=root.best, root=root, after_find=after_find, after_miss=after_miss,
        simulations=int(tree.counts[2]), stopped_by=stopped_by, elapsed=elapsed,
        state_nodes=int(tree.counts[0]), action_nodes=int(tree.counts[1]),
        tree_bytes=sum(array.nbytes for array in tree))
