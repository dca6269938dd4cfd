"""The interface between the tree search and an MDP (see `hptrack.planning.search`).

An MDP is a class of ``env`` (a ``NamedTuple`` of its constant data) registered with
`register_mdp` and its compiled kernels (`MdpKernels`). Compiled code calls them as
``mdp_*(env, ...)``, dispatched at compile time on ``env``'s class, so that the search compiles
one version per MDP. An MDP declares its number of actions to the search, at most
`hptrack.planning.tree.MAX_ACTIONS` (the search refuses more), and how many chance outcomes
an action has (`outcome_count`): the tree sizes its per-outcome arrays from it. Some outcomes
may be the model's only, reported by the world as another (`observed_count`: the first ones are
those the world tells apart); a re-planning search plans only for those.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

from numba.extending import overload

from hptrack._dispatch import registered


class MdpKernels(NamedTuple):
    """The compiled kernels of an MDP (signatures in `hptrack.planning.search`), its
    number of chance outcomes per action (an integer, or a function of ``env`` returning one)
    and how many of the first ones the world tells apart (``None``: all)."""

    copy_state: Callable
    is_available: Callable
    expand: Callable
    apply: Callable
    value: Callable
    n_outcomes: int | Callable[[Any], int] = 2
    n_observed: int | None = None


_MDPS: dict[type, MdpKernels] = {}


def register_mdp(env_class: type, kernels: MdpKernels) -> None:
    """Make the search run on environments of ``env_class`` with ``kernels`` (register before
    the first search of that class in a process)."""
    _MDPS[env_class] = kernels


def outcome_count(env: tuple) -> int:
    """How many chance outcomes an action of ``env``'s registered MDP has.

    Raises:
        ValueError: no MDP registered for ``env``'s class, or a count below 1.
    """
    if type(env) not in _MDPS:
        raise ValueError(f"no MDP registered for {type(env).__name__}")
    declared = _MDPS[type(env)].n_outcomes
    count = declared(env) if callable(declared) else declared
    if count < 1:
        raise ValueError(f"the MDP declares {count} outcomes; the search takes at least 1")
    return int(count)


def observed_count(env: tuple) -> int:
    """How many of the first outcomes of ``env``'s actions the world tells apart (at most
    `outcome_count`)."""
    count = outcome_count(env)
    declared = _MDPS[type(env)].n_observed
    return count if declared is None else min(int(declared), count)


def _kernel(env, field: str):
    return getattr(registered(_MDPS, env, "MDP"), field).py_func


def mdp_copy_state(env, src, dst):
    """The registered ``copy_state`` of ``env``'s MDP (compiled code only)."""
    raise NotImplementedError


def mdp_is_available(env, state, a):
    """The registered ``is_available`` of ``env``'s MDP (compiled code only)."""
    raise NotImplementedError


def mdp_expand(env, state, a, p, payload, work):
    """The registered ``expand`` of ``env``'s MDP (compiled code only)."""
    raise NotImplementedError


def mdp_apply(env, state, a, outcome, payload, work):
    """The registered ``apply`` of ``env``'s MDP (compiled code only)."""
    raise NotImplementedError


def mdp_value(env, state):
    """The registered ``value`` of ``env``'s MDP (compiled code only)."""
    raise NotImplementedError


@overload(mdp_copy_state)
def _copy_state(env, src, dst):
    return _kernel(env, "copy_state")


@overload(mdp_is_available)
def _is_available(env, state, a):
    return _kernel(env, "is_available")


@overload(mdp_expand)
def _expand(env, state, a, p, payload, work):
    return _kernel(env, "expand")


@overload(mdp_apply)
def _apply(env, state, a, outcome, payload, work):
    return _kernel(env, "apply")


@overload(mdp_value)
def _value(env, state):
    return _kernel(env, "value")
