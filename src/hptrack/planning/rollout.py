"""Rollout policies of the tree search (paper Algorithm 1, line 21: a random policy).

A policy is a ``NamedTuple`` class (its fields are the policy's parameters; the paper's has none)
registered with `register_policy` and a compiled kernel
``choose(policy, env, state, rng, candidates) -> a``: the action to take in ``state`` (``-1``
when none is available), drawing from the search's stream ``rng``
(`hptrack.planning.stream`); ``candidates`` is ``int64`` scratch of one entry per action.
Compiled code calls it as `choose_action`, dispatched on the policy's class (so the search
is compiled, and cached, once per policy class).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numba
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.planning.mdp import mdp_is_available
from hptrack.planning.stream import uniform

_POLICIES: dict[type, Callable] = {}


def register_policy(policy_class: type, choose: Callable) -> None:
    """Make ``choose`` (a compiled kernel) the rollout decision of ``policy_class``."""
    _POLICIES[policy_class] = choose


def choose_action(policy, env, state, rng, candidates):
    """The registered ``choose`` of ``policy``'s class (compiled code only)."""
    raise NotImplementedError


@overload(choose_action)
def _choose_action(policy, env, state, rng, candidates):
    return registered(_POLICIES, policy, "rollout policy").py_func


class UniformRandom(NamedTuple):
    """The paper's rollout policy: an available action drawn uniformly at random."""


@numba.njit
def available_actions(env, state, candidates):
    """Write the available actions of ``state`` (in order) to ``candidates``; their number.

    Not cached on disk, like every kernel generic in the MDP: its cache index would record the
    MDP classes it ran on (test toys too), and a process that cannot import one of them could
    not load the index. The cached search compiles it in."""
    count = 0
    for a in range(candidates.shape[0]):
        if mdp_is_available(env, state, a):
            candidates[count] = a
            count += 1
    return count


@numba.njit
def uniform_random(policy, env, state, rng, candidates):
    """`UniformRandom`'s decision."""
    count = available_actions(env, state, candidates)
    if count == 0:
        return -1
    return candidates[int(uniform(rng) * count)]


register_policy(UniformRandom, uniform_random)
