"""The backups of the tree search (paper Algorithm 1 lines 31-33 and three alternatives),
registered like the rollout policies (`hptrack.planning.rollout`).

A backup is a ``NamedTuple`` class (its fields are its parameters) registered with
`register_backup` and a compiled kernel ``back(backup, tree, path_state, path_action,
path_outcome, depth, ret)`` that backs the return ``ret`` of one simulation up its path of
``depth`` (state node, action node, outcome index) triples; ``pairs_outcomes`` says whether it
keeps a value per outcome (then the search's later visits of an action take the possible
outcomes not yet visited: the values are combined with the known ``p``, so each is needed).
Compiled code calls `back_up`, dispatched on the backup's class, so the search is compiled
(and cached) once per backup class. The four backups (`BACKUPS`, by their settings' names):

* ``"sampled"``, the paper's (`Sampled`): ``V(N^a)`` is the running mean of the returns
  of the simulations through the action, whose outcomes were drawn from ``p``;
* ``"expected"`` (`Expected`): each action node keeps a running mean per outcome and
  ``V(N^a) = sum_o p_o V_o`` with the known ``p`` (two outcomes: ``p V_find + (1 - p) V_miss``),
  so the outcome draws add no noise;
* ``"max"`` (`Max`): the expected combination of the outcomes' *values*, where a state's
  value is that of its best action (a Bellman backup; a state visited once is worth its
  rollout's return). Mean backups average the returns of every action tried below, which the
  random rollouts drag down; an action whose value is exact from the start (following a target
  to the end of the budget) then looks better than it is at small effort. The max backup
  removes that bias, but the largest of several noisy values is biased upwards, more so as the
  tree grows: with ``max_weight`` ``lambda < 1`` a state is worth ``lambda max_a V(N^a) + (1 -
  lambda)`` times the mean return of the simulations through it (the "mixmax" backup of
  Jacobsen et al., 2014);
* ``"robust"`` (`Robust`): like ``"max"``, but a state is worth its most visited action
  (ties: the better value). At the frontier of the tree, actions are valued by one or a few
  rollouts, and the largest of several noisy values is biased upwards; UCB1 concentrates its
  visits on the best action, so the most visited one is the best without picking a lucky
  rollout.

Every backup counts ``N(N^s) += 1`` and ``N(N^a) += 1`` along the path; `back_up` then adds
the return and its square to each action's sums (for its standard error), widens the observed
return range and counts the simulation.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numba
import numpy as np
from numba.extending import overload

from hptrack._dispatch import registered


class _Registered(NamedTuple):
    back: Callable
    pairs_outcomes: bool


_BACKUPS: dict[type, _Registered] = {}


def register_backup(backup_class: type, back: Callable, pairs_outcomes: bool) -> None:
    """Make ``back`` (a compiled kernel) the backup of ``backup_class``; ``pairs_outcomes``:
    it keeps a value per outcome (module docstring)."""
    _BACKUPS[backup_class] = _Registered(back, bool(pairs_outcomes))


def _registered(backup) -> _Registered:
    return registered(_BACKUPS, backup, "backup")


def back_up(backup, tree, path_state, path_action, path_outcome, depth, ret):
    """Back ``ret`` up the path with ``backup``'s registered kernel, then add it to the path's
    return sums, widen the return range and count the simulation (compiled code only)."""
    raise NotImplementedError


def pairs_outcomes(backup):
    """Whether ``backup`` keeps a value per outcome (compiled code only; a constant)."""
    raise NotImplementedError


@overload(back_up)
def _back_up(backup, tree, path_state, path_action, path_outcome, depth, ret):
    back = _registered(backup).back

    def impl(backup, tree, path_state, path_action, path_outcome, depth, ret):
        back(backup, tree, path_state, path_action, path_outcome, depth, ret)
        for d in range(depth):
            x = path_action[d]
            tree.a_return_sum[x] += ret
            tree.a_return_square_sum[x] += ret * ret
        tree.value_range[0] = min(tree.value_range[0], ret)
        tree.value_range[1] = max(tree.value_range[1], ret)
        tree.counts[2] += 1

    return impl


@overload(pairs_outcomes)
def _pairs_outcomes(backup):
    paired = _registered(backup).pairs_outcomes
    return lambda backup: paired


class Sampled(NamedTuple):
    """The paper's backup: ``V(N^a)`` is the running mean of the returns through the action."""


class Expected(NamedTuple):
    """A running mean per outcome, combined with the known ``p``."""


class Max(NamedTuple):
    """A state is worth ``max_weight`` times its best action's value plus ``1 - max_weight``
    times the mean return through it (1: the pure max)."""

    max_weight: float = 1.0


class Robust(NamedTuple):
    """A state is worth its most visited action's value."""


BACKUPS = ("sampled", "expected", "max", "robust")
"""The backups by their settings' names."""


def backup_of(name: str, max_weight: float = 1.0) -> tuple:
    """The backup instance a setting names (``max_weight``: the max backup's ``lambda``)."""
    if name not in BACKUPS:
        raise ValueError(f"backup must be one of {BACKUPS}, got {name!r}")
    if not 0.0 <= max_weight <= 1.0:
        raise ValueError(f"max_weight must be in [0, 1], got {max_weight}")
    if name == "max":
        return Max(float(max_weight))
    return {"sampled": Sampled, "expected": Expected, "robust": Robust}[name]()


@numba.njit(cache=True, inline="always")
def _count(tree, s, x):
    tree.s_visits[s] += 1
    tree.a_visits[x] += 1


@numba.njit(cache=True)
def _outcome_mean(tree, x):
    """``sum_o p_o V_o`` of action node ``x`` over its visited outcomes (two: ``p V_0 + (1 -
    p) V_1``), renormalised while a possible outcome is still unvisited (the visited outcome's
    value while only one has been visited)."""
    visited = 0
    last = 0
    complete = True
    for o in range(tree.a_p.shape[1]):
        if tree.a_out_visits[x, o] > 0:
            visited += 1
            last = o
        elif tree.a_p[x, o] > 0.0:
            complete = False
    if visited <= 1:
        return tree.a_out_value[x, last]
    total = 0.0
    weight = 0.0
    for o in range(tree.a_p.shape[1]):
        if tree.a_out_visits[x, o] > 0:
            total += tree.a_p[x, o] * tree.a_out_value[x, o]
            weight += tree.a_p[x, o]
    return total if complete else total / weight


@numba.njit(cache=True, inline="always")
def _set_outcome_value(tree, x, o, value):
    """Outcome ``o``'s value of action node ``x`` is ``value``; ``V(N^a)`` follows."""
    tree.a_out_visits[x, o] += 1
    tree.a_out_value[x, o] = value
    tree.a_value[x] = _outcome_mean(tree, x)


@numba.njit(cache=True)
def _best_value(tree, s):
    """The largest ``V(N^a)`` over the visited actions of state node ``s``."""
    best = -np.inf
    for x in range(tree.s_first[s], tree.s_first[s] + tree.s_count[s]):
        if tree.a_visits[x] > 0 and tree.a_value[x] > best:
            best = tree.a_value[x]
    return best


@numba.njit(cache=True)
def _most_visited_value(tree, s):
    """``V(N^a)`` of the most visited action of state node ``s`` (ties: the larger value)."""
    best = -np.inf
    most = 0
    for x in range(tree.s_first[s], tree.s_first[s] + tree.s_count[s]):
        n = tree.a_visits[x]
        if n > most or (n == most and n > 0 and tree.a_value[x] > best):
            most = n
            best = tree.a_value[x]
    return best


@numba.njit(cache=True)
def back_sampled(backup, tree, path_state, path_action, path_outcome, depth, ret):
    """`Sampled`: ``V(N^a) += (ret - V(N^a)) / N(N^a)`` along the path."""
    for d in range(depth - 1, -1, -1):
        x = path_action[d]
        _count(tree, path_state[d], x)
        tree.a_value[x] += (ret - tree.a_value[x]) / tree.a_visits[x]


@numba.njit(cache=True)
def back_expected(backup, tree, path_state, path_action, path_outcome, depth, ret):
    """`Expected`: a running mean per outcome, ``V(N^a)`` their ``p``-weighted sum."""
    for d in range(depth - 1, -1, -1):
        x = path_action[d]
        _count(tree, path_state[d], x)
        o = path_outcome[d]
        tree.a_out_visits[x, o] += 1
        tree.a_out_value[x, o] += (ret - tree.a_out_value[x, o]) / tree.a_out_visits[x, o]
        tree.a_value[x] = _outcome_mean(tree, x)


@numba.njit(cache=True)
def back_max(backup, tree, path_state, path_action, path_outcome, depth, ret):
    """`Max`: the outcome's value is the next state's (mixmax) value."""
    value = ret
    max_weight = backup.max_weight
    for d in range(depth - 1, -1, -1):
        x = path_action[d]
        s = path_state[d]
        _count(tree, s, x)
        _set_outcome_value(tree, x, path_outcome[d], value)
        value = _best_value(tree, s)
        if max_weight < 1.0:
            tree.s_mean[s] += (ret - tree.s_mean[s]) / tree.s_visits[s]
            value = max_weight * value + (1.0 - max_weight) * tree.s_mean[s]


@numba.njit(cache=True)
def back_robust(backup, tree, path_state, path_action, path_outcome, depth, ret):
    """`Robust`: the outcome's value is the next state's most visited action's."""
    value = ret
    for d in range(depth - 1, -1, -1):
        x = path_action[d]
        s = path_state[d]
        _count(tree, s, x)
        _set_outcome_value(tree, x, path_outcome[d], value)
        value = _most_visited_value(tree, s)


register_backup(Sampled, back_sampled, pairs_outcomes=False)
register_backup(Expected, back_expected, pairs_outcomes=True)
register_backup(Max, back_max, pairs_outcomes=True)
register_backup(Robust, back_robust, pairs_outcomes=True)
