"""Monte Carlo tree search (paper Sec. IV-C-3, Algorithm 1; re-planning Sec. IV-C-4, Algorithm 1
lines 9-12), apart from the MDP it searches and its rollout policy.

The search takes its model as compiled functions, in the spirit of mctx's ``recurrent_fn``. An MDP
with chance nodes of two outcomes is a class of ``env`` (a ``NamedTuple`` of the MDP's constant
data) registered with `hptrack.planning.mdp.register_mdp` and these kernels, all taking
``env`` first:

* ``copy_state(env, src, dst)``: copy a state (a tuple of arrays) into scratch;
* ``is_available(env, state, a) -> bool``; a state without an available action is terminal;
* ``expand(env, state, a, work) -> (p, payload0, payload1)``: the probability of outcome 0 and
  one integer per outcome that ``apply`` needs (deterministic, so it is stored in the tree);
* ``apply(env, state, a, outcome0, payload, work)``: the transition, in place;
* ``value(env, state) -> float``: the return of a terminal state (``-U`` in this project).

An MDP declares its number of actions, at most `MAX_ACTIONS`
(the search refuses more).

The search's options are one record, `SearchOptions`, under the planner settings' names.
Its rollout policy is a class of ``policy`` (a ``NamedTuple`` of its parameters, possibly empty)
registered with `hptrack.planning.rollout.register_policy` and a kernel ``choose(policy,
env, state, rng, candidates) -> a`` (`hptrack.planning.rollout`); its backup likewise
(`hptrack.planning.backups`). Numba compiles one version of the search per (env, policy,
backup) class. Passing the kernels as function arguments would make even the paper's search
uncacheable (several seconds of compilation in every process), so an MDP that wants its search
cached on disk passes its own compiled copy of `run_simulations` (``kernel``), as the
sub-task MDP does (`hptrack.planning.subtask_search`); another MDP's is compiled once per
process.

The search is a pure function of ``(env, root, options, seed, number of simulations)``: the same
inputs give the same tree, whether the simulations ran in one call or in chunks between
wall-clock checks.

**Simulate** (Algorithm 1 lines 15-34), iteratively:

* a state without an available action is terminal: its value is computed once and cached in the
  node (lines 16-17);
* first visit (lines 18-22): the node is expanded and a rollout runs to the end. The expansion is
  deterministic, so it is stored lazily: the action slots are allocated on the second visit and
  each action's ``expand`` is called the first time the action is selected; the tree's statistics
  are the same as with an eager expansion, at a fraction of the cost;
* otherwise UCB1 picks an action (`hptrack.planning.tree.select`), the outcome is drawn
  from ``p`` (line 25), the child state is created on first draw (lines 26-29) and values are
  backed up by the options' backup (`hptrack.planning.backups`; the paper's running
  means, lines 31-33, or another).

States are not stored: the descent rebuilds the state from the root by applying the stored
transitions, only when it is needed (a first visit, opening the action slots, or a first
expansion), so a descent to a cached terminal node costs no transition at all.

**Re-planning** (lines 9-12): the root's only action is the current one (``fixed``), and the
result gives ``argmax V`` over the actions of its find child and of its miss child. As both
answers are needed whatever ``p`` is (it is often above 0.99), the root's outcome is not drawn:
it alternates between find and miss, so each child gets half of the simulations, or with
``root_split="weighted"`` the find gets a share that grows with ``p`` (`_root_outcome`);
below the root everything is as above.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numba
import numpy as np

from hptrack.planning.backups import Sampled, back_up, pairs_outcomes
from hptrack.planning.mdp import mdp_apply, mdp_copy_state, mdp_expand, mdp_is_available, mdp_value
from hptrack.planning.rollout import UniformRandom, choose_action
from hptrack.planning.stream import seed_value, substream, uniform
from hptrack.planning.tree import (
    LEAF,
    MAX_ACTIONS,
    TERMINAL,
    UNVISITED,
    ActionStats,
    Tree,
    grow_tree,
    merge_stats,
    new_tree,
    node_stats,
    select,
)

DEFAULT_EXPLORATION = 0.5
"""UCB1 constant ``c`` on values normalised to the observed return range."""


@numba.njit
def rollout(env, state, forced, policy, rng, candidates, work):
    """Run ``policy`` from ``state`` to a terminal state (Algorithm 1 line 21) and return its
    value; ``forced >= 0`` fixes the first action (re-planning at the root)."""
    while True:
        if forced >= 0:
            a = forced
            forced = -1
        else:
            a = choose_action(policy, env, state, rng, candidates)
            if a < 0:
                break
        p, payload0, payload1 = mdp_expand(env, state, a, work)
        found = uniform(rng) < p
        mdp_apply(env, state, a, found, payload0 if found else payload1, work)
    return mdp_value(env, state)


ROOT_SPLITS = ("even", "weighted")
"""How re-planning shares the root's simulations between the current action's outcomes."""


class SearchOptions(NamedTuple):
    """The search's options, one compiled record under the planner settings' names
    (`hptrack.planning.hierarchical.MctsSettings`); the defaults are the paper's.

    Attributes:
        exploration: UCB1 constant ``c`` on values normalised to the observed return range.
        backup: a registered backup instance (`hptrack.planning.backups`).
        root_split: re-planning: the root's simulations go to the current action's outcomes
            ``"even"``ly or ``"weighted"`` by their probability (`_root_outcome`).
        common_rollouts: a rollout from a new node draws from a stream derived from its parent
            node (common random numbers): the rollouts that value the actions and outcomes of
            one state take the same random decisions wherever they can, so their differences
            are less noisy. Otherwise every draw comes from the tree's single stream (the
            paper's).
        rollout: a registered rollout policy instance (`hptrack.planning.rollout`).
    """

    exploration: float = DEFAULT_EXPLORATION
    backup: tuple = Sampled()
    root_split: str = "even"
    common_rollouts: bool = False
    rollout: tuple = UniformRandom()


PAPER_SEARCH = SearchOptions()
"""The paper's search (Algorithm 1): every option at its default."""


def checked_options(options: SearchOptions) -> SearchOptions:
    """``options`` with its numbers in the compiled types, or ``ValueError`` naming the bad
    field."""
    if not (math.isfinite(options.exploration) and options.exploration > 0.0):
        raise ValueError(f"exploration must be a positive number, got {options.exploration!r}")
    if options.root_split not in ROOT_SPLITS:
        raise ValueError(f"root_split must be one of {ROOT_SPLITS}, got {options.root_split!r}")
    return options._replace(
        exploration=float(options.exploration), common_rollouts=bool(options.common_rollouts)
    )


@numba.njit(cache=True)
def _root_outcome(k, p, weighted):
    """Re-planning: whether simulation ``k`` takes the current action's find outcome at the root.

    Both outcomes need a plan whatever ``p`` is, so the outcome is not drawn: a share ``f`` of
    the simulations goes to the find (``floor((k + 1) f) > floor(k f)``). Evenly (``f = 1/2``,
    the paper's, Algorithm 1 lines 9-12), every other simulation; weighted, ``f = p^(2/3) /
    (p^(2/3) + (1 - p)^(2/3))``, the split that minimises ``p / sqrt(n_find) + (1 - p) /
    sqrt(n_miss)``: each plan's error, shrinking as one over the square root of its
    simulations, weighted by how likely the plan is to be flown.
    """
    f = 0.5
    if weighted:
        a, b = p ** (2.0 / 3.0), (1.0 - p) ** (2.0 / 3.0)
        f = a / (a + b)
    return math.floor((k + 1) * f) > math.floor(k * f)


@numba.njit
def _open_slots(tree, env, s, state, fixed, n_actions):
    """Allocate the action slots of state node ``s`` (its available actions, in order; only
    ``fixed`` at the root in re-planning mode)."""
    first = tree.counts[1]
    count = 0
    for a in range(n_actions):
        if (fixed < 0 or s != 0 or a == fixed) and mdp_is_available(env, state, a):
            x = first + count
            tree.a_action[x] = a
            tree.a_p[x] = -1.0
            count += 1
    tree.counts[1] += count
    tree.s_first[s] = first
    tree.s_count[s] = count


@numba.njit
def _catch_up(tree, env, path_action, path_found, applied, depth, root, state, work):
    """Bring the scratch state from path level ``applied`` (``-1``: not reset yet) to ``depth``
    by re-applying the stored transitions from the root; returns ``depth``."""
    if applied < 0:
        mdp_copy_state(env, root, state)
        applied = 0
    for d in range(applied, depth):
        x = path_action[d]
        found = path_found[d]
        mdp_apply(
            env,
            state,
            np.int64(tree.a_action[x]),
            found,
            tree.a_payload[x, 0 if found else 1],
            work,
        )
    return depth


@numba.njit
def run_simulations(
    tree, env, root, state, work, options, n_actions, max_depth, fixed, n_simulations
):
    """Run up to ``n_simulations`` simulations (Algorithm 1, ``Simulate`` from the root) and
    return how many ran: it stops early when the tree's arrays might not hold one more
    simulation's nodes (`grow_tree` makes room).

    ``root`` is the root state (never modified), ``state`` scratch of the same shapes, ``work``
    the MDP's scratch; ``options`` a `SearchOptions`; ``max_depth`` bounds the number
    of transitions of a history. With a backup that keeps a value per outcome, an action's
    second visit takes the outcome not yet visited (their values are combined with the known
    ``p``, so both are needed, and the draw no longer weights them).
    """
    exploration, policy = options.exploration, options.rollout
    paired = pairs_outcomes(options.backup)
    weighted = options.root_split == "weighted"
    candidates = np.empty(n_actions, dtype=np.int64)
    common = np.empty(1, dtype=np.uint64)
    path_state = np.empty(max_depth, dtype=np.int64)
    path_action = np.empty(max_depth, dtype=np.int64)
    path_found = np.empty(max_depth, dtype=np.bool_)
    cap_s = tree.s_first.shape[0]
    cap_a = tree.a_action.shape[0]
    for sim in range(n_simulations):
        if tree.counts[0] + 1 > cap_s or tree.counts[1] + n_actions > cap_a:
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
                applied = _catch_up(
                    tree, env, path_action, path_found, applied, depth, root, state, work
                )
            if first == UNVISITED:
                live = False
                for a in range(n_actions):
                    if mdp_is_available(env, state, a):
                        live = True
                        break
                if not live:
                    ret = mdp_value(env, state)
                    tree.s_first[s] = TERMINAL
                    tree.s_value[s] = ret
                    break
                tree.s_first[s] = LEAF
                stream = tree.rng
                if options.common_rollouts and depth > 0:
                    substream(tree.rng[1], path_state[depth - 1], common)
                    stream = common
                ret = rollout(env, state, fixed if s == 0 else -1, policy, stream, candidates, work)
                break
            if first == LEAF:
                _open_slots(tree, env, s, state, fixed, n_actions)
            x = select(tree, s, exploration)
            if tree.a_p[x] < 0.0:
                applied = _catch_up(
                    tree, env, path_action, path_found, applied, depth, root, state, work
                )
                p, payload0, payload1 = mdp_expand(env, state, np.int64(tree.a_action[x]), work)
                tree.a_p[x] = p
                tree.a_payload[x, 0] = payload0
                tree.a_payload[x, 1] = payload1
            if s == 0 and fixed >= 0 and 0.0 < tree.a_p[x] < 1.0:
                found = _root_outcome(tree.counts[2], tree.a_p[x], weighted)
            elif (
                paired
                and tree.a_visits[x] > 0
                and 0.0 < tree.a_p[x] < 1.0
                and tree.a_out_visits[x, 0] * tree.a_out_visits[x, 1] == 0
            ):
                found = tree.a_out_visits[x, 0] == 0
            else:
                found = uniform(tree.rng) < tree.a_p[x]
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
        back_up(options.backup, tree, path_state, path_action, path_found, depth, ret)
    return n_simulations


@dataclass(frozen=True, eq=False)
class SearchResult:
    """The outcome of a search.

    Attributes:
        best_action: the action to take (first plan), or the fixed current action
            (re-planning); ``None`` when no action is available.
        root: statistics of the root's actions.
        after_find: re-planning only: the actions after the current one's outcome 0 (find)
            (``None`` when that state was never reached or is terminal).
        after_miss: likewise after outcome 1 (miss).
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
        """Re-planning: the next action if the current one finds its target."""
        return None if self.after_find is None else self.after_find.best

    @property
    def best_after_miss(self) -> int | None:
        """Re-planning: the next action if the current one misses its target."""
        return None if self.after_miss is None else self.after_miss.best


def check_limits(iterations: int | None, time_limit: float | None) -> None:
    if iterations is None and time_limit is None:
        raise ValueError("give iterations, time_limit or both")
    if iterations is not None and iterations < 1:
        raise ValueError(f"iterations must be positive, got {iterations}")
    if time_limit is not None and not time_limit > 0.0:
        raise ValueError(f"time_limit must be positive, got {time_limit}")


def run_search(
    simulate: Callable[[Tree, int], int],
    n_actions: int,
    iterations: int | None,
    time_limit: float | None,
    seed: int | np.random.Generator,
    fixed: int = -1,
    start: float | None = None,
) -> SearchResult:
    """The ``TreeSearch`` loop of Algorithm 1 around a compiled ``simulate(tree, count)``.

    Simulations run in chunks; between chunks the tree grows when full and the wall clock is
    checked (from ``start``, a ``time.perf_counter()`` reading, default now). With both limits,
    whichever comes first stops the search.
    """
    check_limits(iterations, time_limit)
    start = time.perf_counter() if start is None else start
    tree = new_tree(seed_value(seed))
    done = 0
    chunk = 64
    while True:
        todo = chunk if iterations is None else min(chunk, iterations - done)
        ran = simulate(tree, todo)
        if ran < todo:
            tree = grow_tree(tree, n_actions)
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


def search_mdp(
    env: tuple,
    root: tuple,
    n_actions: int,
    max_depth: int,
    work: np.ndarray,
    options: SearchOptions = PAPER_SEARCH,
    *,
    iterations: int | None = None,
    time_limit: float | None = None,
    seed: int | np.random.Generator = 0,
    fixed: int = -1,
    start: float | None = None,
    kernel: Callable = run_simulations,
) -> SearchResult:
    """Search the registered MDP of ``env`` from ``root`` (a tuple of arrays, not modified).

    Args:
        env: the MDP's constant data, an instance of a class registered with
            `hptrack.planning.mdp.register_mdp`.
        root: the root state.
        n_actions: number of actions of the MDP, at most
            `MAX_ACTIONS`.
        max_depth: most transitions of one history.
        work: the MDP's scratch.
        options: the search's options (default the paper's search).
        iterations, time_limit: stop after this many simulations / this wall time (s),
            whichever comes first.
        seed: an integer or a `numpy.random.Generator` (one ``uint64`` is drawn from it).
        fixed: re-planning mode: the root's only action (``-1``: a first plan).
        start: a ``time.perf_counter()`` reading the time limit counts from (default now).
        kernel: the compiled simulation loop, `run_simulations` or an MDP's cached copy
            of it.

    Raises:
        ValueError: more actions than the tree holds, a bad option or limit.
    """
    if not 1 <= n_actions <= MAX_ACTIONS:
        raise ValueError(
            f"the MDP declares {n_actions} actions; the search takes 1 to {MAX_ACTIONS}"
        )
    options = checked_options(options)
    state = tuple(np.array(a, copy=True) for a in root)

    def simulate(tree: Tree, count: int) -> int:
        return kernel(tree, env, root, state, work, options, n_actions, max_depth, fixed, count)

    return run_search(simulate, n_actions, iterations, time_limit, seed, fixed, start)


def merged(results: list[SearchResult], fixed: int) -> SearchResult:
    """One result from root-parallel trees: statistics merged action by action."""
    root = merge_stats([r.root for r in results])
    after_find = merge_stats([r.after_find for r in results]) if fixed >= 0 else None
    after_miss = merge_stats([r.after_miss for r in results]) if fixed >= 0 else None
    return SearchResult(
        best_action=root.best if fixed < 0 else results[0].best_action,
        root=root,
        after_find=after_find,
        after_miss=after_miss,
        simulations=sum(r.simulations for r in results),
        stopped_by=results[0].stopped_by,
        elapsed=max(r.elapsed for r in results),
        state_nodes=sum(r.state_nodes for r in results),
        action_nodes=sum(r.action_nodes for r in results),
        tree_bytes=sum(r.tree_bytes for r in results),
    )


def _result(tree: Tree, fixed: int, stopped_by: str, elapsed: float) -> SearchResult:
    root = node_stats(tree, 0)
    empty = np.zeros(0, dtype=np.int64)
    if root is None:
        root = ActionStats(empty, empty, np.zeros(0), np.zeros(0), empty, empty)
    after_find = after_miss = None
    if fixed >= 0 and root.actions.size:
        children = tree.a_child[int(tree.s_first[0])]
        after_find = None if children[0] < 0 else node_stats(tree, int(children[0]))
        after_miss = None if children[1] < 0 else node_stats(tree, int(children[1]))
    return SearchResult(
        best_action=root.best,
        root=root,
        after_find=after_find,
        after_miss=after_miss,
        simulations=int(tree.counts[2]),
        stopped_by=stopped_by,
        elapsed=elapsed,
        state_nodes=int(tree.counts[0]),
        action_nodes=int(tree.counts[1]),
        tree_bytes=sum(array.nbytes for array in tree),
    )
