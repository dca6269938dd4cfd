"""Rollout policies for the sub-task MDP (alternatives to the paper's random one).

`UniformNoFollow` is the paper's uniform draw without one action: following the target
just found, which ends the history (it keeps every other belief growing to the end of the
budget). A uniform rollout takes it with probability ``1 / k`` after each find (``k`` available
actions), so most random rollouts end in an early follow and value their state as if the
mission stopped there; without it, the rollout estimates the state under random pursuit of the
other targets. It follows only when no other action is available.

`MostUncertain` pursues, with probability ``1 - epsilon``, the available target whose
position uncertainty ``log det Sigma^xy`` is largest when the agent would reach its belief mean
(the rule of the ``greedy`` baseline, `hptrack.baselines.greedy`, applied inside the MDP), and
otherwise an available action drawn uniformly. It follows the target just found only when no
other action is available, so a rollout does not end its history early by chance. Informed
rollouts can also mislead the search (their errors are systematic); the benchmark in
``docs/results/search-options.md`` measures it against the random policy.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from hptrack.models.beliefs import logdet_xy
from hptrack.models.mission import position_covariance_on
from hptrack.models.state import velocity_variance_of
from hptrack.planning.rollout import available_actions, register_policy
from hptrack.planning.stream import uniform
from hptrack.planning.subtask_mdp import I_LAST, I_STEP, intercept_of, is_dwell


class UniformNoFollow(NamedTuple):
    """Uniformly random rollouts that do not follow the target just found (module docstring)."""


@numba.njit(cache=True)
def uniform_no_follow(policy, env, state, rng, candidates):
    """`UniformNoFollow`'s decision (``-1`` when no action is available)."""
    count = available_actions(env, state, candidates)
    if count == 0:
        return -1
    last = state[0][I_LAST]  # available whenever any action is: it is in the action list
    if last < 0 or count == 1:
        return candidates[int(uniform(rng) * count)]
    k = int(uniform(rng) * (count - 1))  # the k-th available action other than ``last``
    return candidates[k + 1] if candidates[k] >= last else candidates[k]


@numba.njit(cache=True)
def epsilon_greedy(epsilon, env, state, rng, candidates, uncertainty):
    """With probability ``epsilon`` an available action drawn uniformly, otherwise the best
    available target other than the one just found (neither its follow nor its dwell; the lower
    index on a tie): the one whose position ``log det Sigma^xy`` is largest when the agent
    reaches its belief mean (``uncertainty``), or the one reached in the fewest intercept steps.
    ``-1`` when no action is available; the first available action when no other target is."""
    count = available_actions(env, state, candidates)
    if count == 0:
        return -1
    if uniform(rng) < epsilon:
        return candidates[int(uniform(rng) * count)]
    return best_other(env, state, candidates, count, uncertainty)


@numba.njit(cache=True)
def best_other(env, state, candidates, count, uncertainty):
    """`epsilon_greedy`'s choice among the ``count`` available ``candidates``, without the
    random draw."""
    mission = env.mission
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    best = -1
    best_score = -np.inf
    for k in range(count):
        a = candidates[k]
        if a == si[I_LAST] or is_dwell(env, a):  # the follow, the dwell
            continue
        steps = intercept_of(env, sf, a, t)
        if uncertainty:
            sxx, sxy, syy = position_covariance_on(
                mission, base_cov[a], mission.process_noise[a], float(t + steps - base_step[a])
            )
            score = logdet_xy(sxx, sxy, syy)
        else:
            score = -float(steps)
        if score > best_score:
            best_score = score
            best = a
    return candidates[0] if best < 0 else best


class Nearest(NamedTuple):
    """Rollouts that pursue, with probability ``1 - epsilon``, the available target other than
    the one just found that the agent reaches first (fewest intercept steps), and otherwise an
    available action drawn uniformly: a local tour, the opposite bias of
    `MostUncertain`.

    Attributes:
        epsilon: probability of a uniformly random available action instead, in ``[0, 1]``.
    """

    epsilon: float = 0.1


@numba.njit(cache=True)
def nearest(policy, env, state, rng, candidates):
    """`Nearest`'s decision (`epsilon_greedy` on intercept steps)."""
    return epsilon_greedy(policy.epsilon, env, state, rng, candidates, False)


class MostUncertain(NamedTuple):
    """Most-uncertain-on-arrival rollouts (module docstring).

    Attributes:
        epsilon: probability of a uniformly random available action instead, in ``[0, 1]``.
    """

    epsilon: float = 0.1


@numba.njit(cache=True)
def most_uncertain(policy, env, state, rng, candidates):
    """`MostUncertain`'s decision (`epsilon_greedy` on the uncertainty on
    arrival)."""
    return epsilon_greedy(policy.epsilon, env, state, rng, candidates, True)


class UniformNoDwell(NamedTuple):
    """The paper's uniform draw over the available targets (the follow included), never a
    dwell: the dwell actions are left to the tree. With several dwell lengths a uniform
    rollout would spend most of its decisions after a find dwelling, and value every state as
    if the mission were mostly spent dwelling."""


@numba.njit(cache=True)
def uniform_no_dwell(policy, env, state, rng, candidates):
    """`UniformNoDwell`'s decision (``-1`` when no action is available)."""
    count = available_actions(env, state, candidates)
    targets = 0
    while targets < count and not is_dwell(env, candidates[targets]):
        targets += 1  # the dwells come last
    if targets == 0:
        return candidates[int(uniform(rng) * count)] if count > 0 else -1
    return candidates[int(uniform(rng) * targets)]


class Tour(NamedTuple):
    """Tour rollouts: with probability ``1 - epsilon``, dwell on the target just found while its
    velocity is uncertain, else pursue the nearest other target; otherwise an available action
    drawn uniformly.

    A single find fixes a target's position but not its velocity, so its belief grows back fast
    (``docs/planner-improvements.md``, the dwell action); a target measured for a while grows
    slowly and is cheap to find again. The tour measures each target it meets until its
    velocity variance is below ``settle_velocity_variance`` (a dwell drawn uniformly among the
    available lengths; none without dwell actions), then moves to the target it reaches first.

    Attributes:
        epsilon: probability of a uniformly random available action instead, in ``[0, 1]``.
        settle_velocity_variance: mean of the two velocity variances, (m/s)^2, below which a
            found target is left.
    """

    epsilon: float = 0.1
    settle_velocity_variance: float = 0.05


@numba.njit(cache=True)
def tour(policy, env, state, rng, candidates):
    """`Tour`'s decision (``-1`` when no action is available)."""
    count = available_actions(env, state, candidates)
    if count == 0:
        return -1
    if uniform(rng) < policy.epsilon:
        return candidates[int(uniform(rng) * count)]
    si, base_cov = state[0], state[2]
    last = si[I_LAST]
    if last >= 0:
        if velocity_variance_of(base_cov[last]) > policy.settle_velocity_variance:
            dwells = 0
            for k in range(count):
                if is_dwell(env, candidates[k]):
                    dwells += 1
            if dwells > 0:
                return candidates[count - dwells + int(uniform(rng) * dwells)]
    return best_other(env, state, candidates, count, False)


register_policy(UniformNoFollow, uniform_no_follow)
register_policy(Tour, tour)
register_policy(UniformNoDwell, uniform_no_dwell)
register_policy(Nearest, nearest)
register_policy(MostUncertain, most_uncertain)
