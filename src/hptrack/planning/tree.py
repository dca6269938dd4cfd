"""The search tree as preallocated arrays indexed by node id (no Python object per node), in the
spirit of mctx: state nodes ``s_*`` and action (chance) nodes ``a_*``.

A state node stores its visit count ``N(N^s)``, its first action slot and the number of slots;
an action node stores its action, ``N(N^a)``, ``V(N^a)``, the sum and the sum of squares of
the returns through it (whatever the backup, for their standard error) and, in one column per
chance outcome (as many as the MDP declares, `hptrack.planning.mdp.outcome_count`), the
expansion results (``a_p[:, o]``, the outcome's probability, and ``a_payload[:, o]``, one
integer that the MDP needs to replay the transition, e.g. a duration), the child state node
and the per-outcome statistics of the backups that keep them. States themselves are not
stored: the search rebuilds them from the root by replaying the stored transitions.

`select` is UCB1 (paper Algorithm 1, line 23), the tree's whatever the MDP; the backups
are registered kernels (`hptrack.planning.backups`).

Action slots hold action indices as ``int16``: an MDP may declare up to `MAX_ACTIONS`
actions (the search refuses more).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

UNVISITED = -2
"""``Tree.s_first`` of a state node created but never visited."""
LEAF = -1
"""``Tree.s_first`` of a state node visited once (rolled out, no action slots yet)."""
TERMINAL = -3
"""``Tree.s_first`` of a terminal state node (value cached in ``Tree.s_value``)."""


class Tree(NamedTuple):
    """The search tree as arrays (state nodes ``s_*``, action nodes ``a_*``).

    ``counts`` holds ``[state nodes, action nodes, simulations run, outcomes the world tells
    apart]`` (`hptrack.planning.mdp.observed_count`); ``value_range`` the
    smallest and largest return seen; ``rng`` the random stream's state and the seed it started
    from (the seed of the search's derived streams, `hptrack.planning.stream.substream`).
    """

    s_first: np.ndarray
    s_count: np.ndarray
    s_visits: np.ndarray
    s_value: np.ndarray
    s_mean: np.ndarray
    a_action: np.ndarray
    a_p: np.ndarray
    a_payload: np.ndarray
    a_visits: np.ndarray
    a_value: np.ndarray
    a_child: np.ndarray
    a_out_visits: np.ndarray
    a_out_value: np.ndarray
    a_return_sum: np.ndarray
    a_return_square_sum: np.ndarray
    counts: np.ndarray
    value_range: np.ndarray
    rng: np.ndarray


_FILL = {
    "s_first": (UNVISITED, np.int32),
    "s_count": (0, np.int16),
    "s_visits": (0, np.int32),
    "s_value": (np.nan, np.float64),
    "s_mean": (0.0, np.float64),
    "a_action": (0, np.int16),
    "a_p": (-1.0, np.float64),
    "a_payload": (0, np.int32),
    "a_visits": (0, np.int32),
    "a_value": (0.0, np.float64),
    "a_child": (-1, np.int32),
    "a_out_visits": (0, np.int32),
    "a_out_value": (0.0, np.float64),
    "a_return_sum": (0.0, np.float64),
    "a_return_square_sum": (0.0, np.float64),
}
"""Initial value and dtype of each node array of `Tree` (those in `PER_OUTCOME`: one column
per outcome; ``a_p < 0``: not expanded yet)."""

MAX_ACTIONS = int(np.iinfo(np.int16).max)
"""Most actions an MDP may declare: action slots and a state's slot count are ``int16``."""
PER_OUTCOME = ("a_p", "a_payload", "a_child", "a_out_visits", "a_out_value")
"""The action-node arrays with one column per chance outcome."""


def new_tree(
    seed: int, capacity: int = 1024, n_outcomes: int = 2, n_observed: int | None = None
) -> Tree:
    """An empty tree holding only the root (state node 0), with the random stream seeded, for
    an MDP whose actions have ``n_outcomes`` chance outcomes, the first ``n_observed`` (default
    all) told apart by the world."""
    arrays = {
        name: np.full(
            (capacity, n_outcomes) if name in PER_OUTCOME else capacity, fill, dtype=dtype
        )
        for name, (fill, dtype) in _FILL.items()
    }
    return Tree(
        **arrays,
        counts=np.array(
            [1, 0, 0, n_outcomes if n_observed is None else n_observed], dtype=np.int64
        ),
        value_range=np.array([np.inf, -np.inf]),
        rng=np.array([seed, seed], dtype=np.uint64),
    )


def grow_tree(tree: Tree, n_actions: int) -> Tree:
    """The tree with its state (action) arrays doubled if one more state node (``n_actions``
    more action nodes) might not fit: what one simulation can add at most."""
    arrays = tree._asdict()
    for prefix, size, need in (
        ("s_", tree.s_first.shape[0], tree.counts[0] + 1),
        ("a_", tree.a_action.shape[0], tree.counts[1] + n_actions),
    ):
        if need <= size:
            continue
        extra = max(size, need - size)
        for name, (fill, dtype) in _FILL.items():
            if name.startswith(prefix):
                old = arrays[name]
                arrays[name] = np.concatenate(
                    [old, np.full((extra, *old.shape[1:]), fill, dtype=dtype)]
                )
    return Tree(**arrays)


@numba.njit(cache=True)
def select(tree, s, exploration):
    """UCB1 (Algorithm 1 line 23) over the action slots of state node ``s``: the first unvisited
    action, else ``argmax V_hat + c sqrt(ln N(s) / N(a))`` with values normalised to ``[0, 1]``
    by the smallest and largest return seen so far."""
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
        score = (tree.a_value[x] - low) * scale + exploration * math.sqrt(log_n / tree.a_visits[x])
        if score > best_score:
            best_score = score
            best = x
    return best


@dataclass(frozen=True, eq=False)
class ActionStats:
    """The actions of one state node and their statistics (arrays of equal length).

    Attributes:
        actions: action indices (target indices in the sub-task MDP).
        visits: ``N(N^a)``.
        values: ``V(N^a)``, the mean return (``-U``) over the simulations through the action.
        p: ``(actions, outcomes)``, each outcome's probability (NaN if never expanded); in the
            sub-task MDP outcome 0 is the find, 1 the miss.
        payload: ``(actions, outcomes)``, each outcome's payload (the sub-task MDP: the
            sub-task's duration after that outcome, steps).
        return_sum: the sum of the returns of the simulations through each action.
        return_square_sum: the sum of their squares.
    """

    actions: np.ndarray
    visits: np.ndarray
    values: np.ndarray
    p: np.ndarray
    payload: np.ndarray
    return_sum: np.ndarray
    return_square_sum: np.ndarray

    def standard_errors(self) -> np.ndarray:
        """The standard error of the mean return through each action (the returns' sample
        standard deviation over ``sqrt(N(N^a))``; ``inf`` below two visits)."""
        n = self.visits.astype(float)
        spread = self.return_square_sum - self.return_sum**2 / np.maximum(n, 1.0)
        variance = np.divide(
            np.maximum(spread, 0.0), n * (n - 1.0), out=np.full(n.size, np.inf), where=n > 1
        )
        return np.sqrt(variance)

    def of(self, action: int) -> int | None:
        """The position of ``action`` in these arrays, ``None`` if it is not one of them."""
        at = np.flatnonzero(self.actions == action)
        return int(at[0]) if at.size else None

    @property
    def best(self) -> int | None:
        """``argmax V`` over the visited actions (Algorithm 1 lines 12-13), ``None`` if none."""
        visited = np.flatnonzero(self.visits > 0)
        if visited.size == 0:
            return None
        return int(self.actions[visited[np.argmax(self.values[visited])]])


def merge_stats(stats: list[ActionStats | None]) -> ActionStats | None:
    """The statistics of one node searched in several independent trees (root parallelism):
    visits add up, values are the visit-weighted means; expansion results, which are
    deterministic, are taken from the first tree that expanded the action."""
    present = [s for s in stats if s is not None]
    if not present:
        return None
    actions = np.unique(np.concatenate([s.actions for s in present]))
    n_outcomes = present[0].p.shape[1]
    visits = np.zeros(actions.size, dtype=np.int64)
    weighted = np.zeros(actions.size)
    return_sum = np.zeros(actions.size)
    return_square_sum = np.zeros(actions.size)
    p = np.full((actions.size, n_outcomes), np.nan)
    payload = np.zeros((actions.size, n_outcomes), dtype=np.int64)
    for s in present:
        at = np.searchsorted(actions, s.actions)
        visits[at] += s.visits
        weighted[at] += s.visits * s.values
        return_sum[at] += s.return_sum
        return_square_sum[at] += s.return_square_sum
        new = np.isnan(p[at, 0]) & ~np.isnan(s.p[:, 0])
        p[at[new]], payload[at[new]] = s.p[new], s.payload[new]
    values = np.divide(weighted, visits, out=np.zeros(actions.size), where=visits > 0)
    return ActionStats(actions, visits, values, p, payload, return_sum, return_square_sum)


def node_stats(tree: Tree, s: int) -> ActionStats | None:
    """The statistics of state node ``s``'s actions (``None`` if it has no action slots)."""
    first = int(tree.s_first[s])
    if first < 0:
        return None
    xs = slice(first, first + int(tree.s_count[s]))
    p = tree.a_p[xs].copy()
    p[p[:, 0] < 0.0] = np.nan
    return ActionStats(
        tree.a_action[xs].astype(np.int64),
        tree.a_visits[xs].astype(np.int64),
        tree.a_value[xs].copy(),
        p,
        tree.a_payload[xs].astype(np.int64),
        tree.a_return_sum[xs].copy(),
        tree.a_return_square_sum[xs].copy(),
    )
