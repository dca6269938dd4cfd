"""Monte Carlo tree search (paper Sec. IV-C-3, Algorithm 1; re-planning Sec. IV-C-4, Algorithm 1
lines 9-12), apart from the MDP it searches and its rollout policy.

The search takes its model as compiled functions, in the spirit of mctx's ``recurrent_fn``. An MDP
is a class of ``env`` (a ``NamedTuple`` of the MDP's constant data) registered with
`hptrack.planning.mdp.register_mdp` and these kernels, all taking ``env`` first:

* ``copy_state(env, src, dst)``: copy a state (a tuple of arrays) into scratch;
* ``is_available(env, state, a) -> bool``; a state without an available action is terminal;
* ``expand(env, state, a, p, payload, work)``: write each chance outcome ``o``'s probability
  ``p[o]`` (they sum to 1) and one integer ``payload[o]`` that ``apply`` needs (deterministic, so
  both are stored in the tree);
* ``apply(env, state, a, outcome, payload, work)``: the transition after ``outcome``, in place;
* ``value(env, state) -> float``: the return of a terminal state (``-U`` in this project).

An MDP declares its number of actions, at most `hptrack.planning.tree.MAX_ACTIONS` (the search
refuses more), and the number of chance outcomes of an action
(`hptrack.planning.mdp.outcome_count`; the sub-task MDP's are the find and the miss, and the
false find when it models one), of which the first `hptrack.planning.mdp.observed_count` are
told apart by the world.

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
result gives ``argmax V`` over the actions of the child after each of its outcomes (the find
child and the miss child). As every answer is needed whatever ``p`` is (a find is often above
0.99), the root's outcome is not drawn: the simulations are shared out among the possible
outcomes, evenly (two outcomes alternate) or with ``root_split="weighted"`` by a share that grows
with ``p`` (`_root_outcome`); below the root everything is as above.
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
from hptrack.planning.mdp import (
    mdp_apply,
    mdp_copy_state,
    mdp_expand,
    mdp_is_available,
    mdp_value,
    observed_count,
    outcome_count,
)
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


@numba.njit(cache=True, inline="always")
def draw_outcome(p, u):
    """The outcome whose share of ``[0, 1)`` holds ``u``, outcome 0's first (Algorithm 1 line
    25: with two outcomes, 0 iff ``u < p[0]``); the last one takes what rounding leaves."""
    last = p.shape[0] - 1
    total = 0.0
    for o in range(last):
        total += p[o]
        if u < total:
            return o
    return last


@numba.njit
def rollout(env, state, forced, policy, rng, candidates, p, payload, work):
    """Run ``policy`` from ``state`` to a terminal state (Algorithm 1 line 21) and return its
    value; ``forced >= 0`` fixes the first action (re-planning at the root). ``p`` and
    ``payload`` are scratch of one entry per outcome."""
    while True:
        if forced >= 0:
            a = forced
            forced = -1
        else:
            a = choose_action(policy, env, state, rng, candidates)
            if a < 0:
                break
        mdp_expand(env, state, a, p, payload, work)
        o = draw_outcome(p, uniform(rng))
        mdp_apply(env, state, a, o, payload[o], work)
    return mdp_value(env, state)


ROOT_SPLITS = ("even", "weighted")
"""How re-planning shares the root's simulations among the current action's outcomes."""


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


@numba.njit(cache=True, inline="always")
def _share_weight(p, weighted):
    """An outcome's weight in the root's share-out: 1 (even) or ``p^(2/3)`` (weighted); 0 for
    an impossible outcome."""
    if p <= 0.0:
        return 0.0
    return p ** (2.0 / 3.0) if weighted else 1.0


@numba.njit(cache=True)
def _root_outcome(k, p, weighted):
    """Re-planning: the outcome of the current action that simulation ``k`` takes at the root.

    Every possible outcome needs a plan whatever ``p`` is, so the outcome is not drawn: outcome
    ``o`` gets a share ``f_o`` of the simulations, taken in turn: simulation ``k`` goes to
    outcome 0 when ``floor((k + 1) f_0) > floor(k f_0)``, else the rest are shared the same way
    among the later outcomes (the ``k - floor(k f_0)``-th of them). Evenly (the paper's,
    Algorithm 1 lines 9-12) every possible outcome gets the same share: with two, every other
    simulation. Weighted, ``f_o`` is proportional to ``p_o^(2/3)``, the split that minimises
    ``sum_o p_o / sqrt(n_o)``: each plan's error, shrinking as one over the square root of its
    simulations, weighted by how likely the plan is to be flown.
    """
    last = p.shape[0] - 1
    while last > 0 and p[last] <= 0.0:
        last -= 1
    j = k
    for o in range(last):
        w = _share_weight(p[o], weighted)
        if w == 0.0:
            continue
        rest = 0.0
        for r in range(o, p.shape[0]):
            rest += _share_weight(p[r], weighted)
        f = w / rest
        if math.floor((j + 1) * f) > math.floor(j * f):
            return o
        j -= int(math.floor(j * f))
    return last


@numba.njit(cache=True, inline="always")
def _uncertain(p):
    """Whether more than one outcome is possible."""
    possible = 0
    for o in range(p.shape[0]):
        if p[o] > 0.0:
            possible += 1
    return possible > 1


@numba.njit(cache=True)
def _first_unvisited(tree, x):
    """The first possible outcome of action node ``x`` not visited yet, ``-1`` if none or if
    only one outcome is possible."""
    if not _uncertain(tree.a_p[x]):
        return -1
    for o in range(tree.a_p.shape[1]):
        if tree.a_p[x, o] > 0.0 and tree.a_out_visits[x, o] == 0:
            return o
    return -1


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
            tree.a_p[x, 0] = -1.0
            count += 1
    tree.counts[1] += count
    tree.s_first[s] = first
    tree.s_count[s] = count


@numba.njit
def _catch_up(tree, env, path_action, path_outcome, applied, depth, root, state, work):
    """Bring the scratch state from path level ``applied`` (``-1``: not reset yet) to ``depth``
    by re-applying the stored transitions from the root; returns ``depth``."""
    if applied < 0:
        mdp_copy_state(env, root, state)
        applied = 0
    for d in range(applied, depth):
        x = path_action[d]
        o = path_outcome[d]
        mdp_apply(env, state, np.int64(tree.a_action[x]), o, tree.a_payload[x, o], work)
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
    later visits take the possible outcomes not yet visited, in order (their values are
    combined with the known ``p``, so each is needed, and the draw no longer weights them).
    """
    exploration, policy = options.exploration, options.rollout
    paired = pairs_outcomes(options.backup)
    weighted = options.root_split == "weighted"
    observed = tree.counts[3]
    candidates = np.empty(n_actions, dtype=np.int64)
    common = np.empty(1, dtype=np.uint64)
    p_scratch = np.empty(tree.a_p.shape[1])
    payload_scratch = np.empty(tree.a_p.shape[1], dtype=tree.a_payload.dtype)
    path_state = np.empty(max_depth, dtype=np.int64)
    path_action = np.empty(max_depth, dtype=np.int64)
    path_outcome = np.empty(max_depth, dtype=np.int64)
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
                    tree, env, path_action, path_outcome, applied, depth, root, state, work
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
                ret = rollout(
                    env,
                    state,
                    fixed if s == 0 else -1,
                    policy,
                    stream,
                    candidates,
                    p_scratch,
                    payload_scratch,
                    work,
                )
                break
            if first == LEAF:
                _open_slots(tree, env, s, state, fixed, n_actions)
            x = select(tree, s, exploration)
            if tree.a_p[x, 0] < 0.0:
                applied = _catch_up(
                    tree, env, path_action, path_outcome, applied, depth, root, state, work
                )
                a = np.int64(tree.a_action[x])
                mdp_expand(env, state, a, tree.a_p[x], tree.a_payload[x], work)
            outcome = -1
            if s == 0 and fixed >= 0 and _uncertain(tree.a_p[x, :observed]):
                outcome = _root_outcome(tree.counts[2], tree.a_p[x, :observed], weighted)
            elif paired and tree.a_visits[x] > 0:
                outcome = _first_unvisited(tree, x)
            if outcome < 0:
                outcome = draw_outcome(tree.a_p[x], uniform(tree.rng))
            path_state[depth] = s
            path_action[depth] = x
            path_outcome[depth] = outcome
            depth += 1
            child = tree.a_child[x, outcome]
            if child < 0:
                child = tree.counts[0]
                tree.counts[0] += 1
                tree.a_child[x, outcome] = child
            s = child
        back_up(options.backup, tree, path_state, path_action, path_outcome, depth, ret)
    return n_simulations


StoppedBy = Literal["iterations", "time_limit"]
"""Which limit stopped a search."""


@dataclass(frozen=True, eq=False)
class SearchResult:
    """The outcome of a search.

    Attributes:
        best_action: the action to take (first plan), or the fixed current action
            (re-planning); ``None`` when no action is available.
        root: statistics of the root's actions.
        after: re-planning only (empty otherwise): per outcome of the current action, the
            statistics of the actions after it (``None`` when that state was never reached or
            is terminal); in the sub-task MDP ``after[0]`` follows the find, ``after[1]`` the
            miss.
        simulations: number of simulations run.
        stopped_by: ``"iterations"`` or ``"time_limit"``.
        elapsed: wall time of the search, s.
        state_nodes: state nodes in the tree.
        action_nodes: action nodes in the tree.
        tree_bytes: memory held by the tree's arrays (allocated capacity), bytes.
    """

    best_action: int | None
    root: ActionStats
    after: tuple[ActionStats | None, ...]
    simulations: int
    stopped_by: StoppedBy
    elapsed: float
    state_nodes: int
    action_nodes: int
    tree_bytes: int

    def best_after(self, outcome: int) -> int | None:
        """Re-planning: the next action if the current one has ``outcome`` (``None`` when
        none was searched)."""
        stats = self.after[outcome] if outcome < len(self.after) else None
        return None if stats is None else stats.best


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
    n_outcomes: int = 2,
    n_observed: int | None = None,
) -> SearchResult:
    """The ``TreeSearch`` loop of Algorithm 1 around a compiled ``simulate(tree, count)`` on a
    tree for actions of ``n_outcomes`` chance outcomes (the first ``n_observed``, default all,
    told apart by the world: a re-planning root shares its simulations among those).

    Simulations run in chunks; between chunks the tree grows when full and the wall clock is
    checked (from ``start``, a ``time.perf_counter()`` reading, default now). With both limits,
    whichever comes first stops the search.
    """
    check_limits(iterations, time_limit)
    start = time.perf_counter() if start is None else start
    tree = new_tree(seed_value(seed), n_outcomes=n_outcomes, n_observed=n_observed)
    done = 0
    chunk = 64
    while True:
        todo = chunk if iterations is None else min(chunk, iterations - done)
        ran = simulate(tree, todo)
        if ran < todo:
            tree = grow_tree(tree, n_actions)
        done += ran
        if iterations is not None and done >= iterations:
            stopped_by: StoppedBy = "iterations"
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
        ValueError: more actions than the tree holds, no outcome, a bad option or limit.
    """
    if not 1 <= n_actions <= MAX_ACTIONS:
        raise ValueError(
            f"the MDP declares {n_actions} actions; the search takes 1 to {MAX_ACTIONS}"
        )
    n_outcomes = outcome_count(env)
    n_observed = observed_count(env)
    options = checked_options(options)
    state = tuple(np.array(a, copy=True) for a in root)

    def simulate(tree: Tree, count: int) -> int:
        return kernel(tree, env, root, state, work, options, n_actions, max_depth, fixed, count)

    return run_search(
        simulate, n_actions, iterations, time_limit, seed, fixed, start, n_outcomes, n_observed
    )


def merged(results: list[SearchResult], fixed: int) -> SearchResult:
    """One result from root-parallel trees: statistics merged action by action."""
    root = merge_stats([r.root for r in results])
    if root is None:
        raise ValueError("no search results to merge")
    outcomes = max(len(r.after) for r in results) if fixed >= 0 else 0
    after = tuple(
        merge_stats([r.after[o] if o < len(r.after) else None for r in results])
        for o in range(outcomes)
    )
    return SearchResult(
        best_action=root.best if fixed < 0 else results[0].best_action,
        root=root,
        after=after,
        simulations=sum(r.simulations for r in results),
        stopped_by=results[0].stopped_by,
        elapsed=max(r.elapsed for r in results),
        state_nodes=sum(r.state_nodes for r in results),
        action_nodes=sum(r.action_nodes for r in results),
        tree_bytes=sum(r.tree_bytes for r in results),
    )


def _result(tree: Tree, fixed: int, stopped_by: StoppedBy, elapsed: float) -> SearchResult:
    root = node_stats(tree, 0)
    if root is None:
        empty, n_outcomes = np.zeros(0, dtype=np.int64), tree.a_p.shape[1]
        root = ActionStats(
            empty,
            empty,
            np.zeros(0),
            np.zeros((0, n_outcomes)),
            np.zeros((0, n_outcomes), dtype=np.int64),
            np.zeros(0),
            np.zeros(0),
        )
    after: tuple[ActionStats | None, ...] = ()
    if fixed >= 0 and root.actions.size:
        children = tree.a_child[int(tree.s_first[0])]
        after = tuple(None if c < 0 else node_stats(tree, int(c)) for c in children)
    return SearchResult(
        best_action=root.best,
        root=root,
        after=after,
        simulations=int(tree.counts[2]),
        stopped_by=stopped_by,
        elapsed=elapsed,
        state_nodes=int(tree.counts[0]),
        action_nodes=int(tree.counts[1]),
        tree_bytes=sum(array.nbytes for array in tree),
    )
