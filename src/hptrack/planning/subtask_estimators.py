"""The sub-task MDP's outcome estimators (paper Sec. IV-B and one beyond it), registered like the
rollout policies and the backups (`hptrack.planning.rollout`, `hptrack.planning.backups`).

An estimator is a ``NamedTuple`` class (its fields are its parameters) registered with
`register_estimator` under its settings' name, with a compiled kernel
``outcome(estimator, env, state, a, t, ic, work) -> (p_find, find_steps, miss_steps)``: the
outcome of pursuing target ``a`` from the sub-task MDP's ``state`` at step ``t``, its intercept
taking ``ic`` steps (``work``: 4x4 scratch). Compiled code calls `estimate_pursuit`,
dispatched at compile time on the estimator's class, so the search is compiled (and cached on
disk) once per estimator class.

* ``"paper"`` (`PaperEstimator`, Sec. IV-B): `hptrack.coverage.estimator.coverage_outcome`
  from the covariance predicted to the spiral's start; a find lasts the intercept plus the
  rounded ``E[T_find]``, a miss the intercept plus ``t_cutoff``. The result of a target never
  found since the root depends only on its start step, so it is memoised per search;
  where a fence keeps the vehicle from covering part of the searched ellipse, the chance of a
  find loses that part (`hptrack.models.mission.visible_find`, both estimators), and under a
  coverage limit (``coverage_limit``) the coverage is truncated there as at the budget's end
  (`coverage_room`, both estimators);
* ``"sharp"`` (`SharpEstimator`): `hptrack.coverage.sharp_estimator.sharp_coverage_outcome`,
  which counts detections on the intercept flight and the footprint's reach; a find lasts the
  estimated duration from departure. Its estimate depends on the approach: not memoised.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numba
from numba.extending import overload

from hptrack._dispatch import registered
from hptrack.coverage.estimator import coverage_outcome
from hptrack.coverage.sharp_estimator import sharp_coverage_outcome
from hptrack.models.mission import approach_step_to, predict_covariance_on, visible_find

_ESTIMATORS: dict[type, Callable] = {}
ESTIMATORS: dict[str, type] = {}
"""The registered estimator classes by their settings' names."""


def register_estimator(name: str, estimator_class: type, outcome: Callable) -> None:
    """Make ``outcome`` (a compiled kernel, module docstring) the estimate of
    ``estimator_class``, chosen in settings as ``name``."""
    _ESTIMATORS[estimator_class] = outcome
    ESTIMATORS[name] = estimator_class


def estimator_of(name: str) -> tuple:
    """The estimator instance a setting names.

    Raises:
        ValueError: no estimator of that name.
    """
    if name not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {tuple(ESTIMATORS)}, got {name!r}")
    return ESTIMATORS[name]()


def estimate_pursuit(estimator, env, state, a, t, ic, work):
    """The registered ``outcome`` of ``estimator``'s class (compiled code only)."""
    raise NotImplementedError


@overload(estimate_pursuit)
def _estimate_pursuit(estimator, env, state, a, t, ic, work):
    return registered(_ESTIMATORS, estimator, "estimator").py_func


class PaperEstimator(NamedTuple):
    """The paper's estimator (Sec. IV-B), memoised per search."""


class SharpEstimator(NamedTuple):
    """Detections on the intercept flight and the footprint's reach (module docstring)."""


@numba.njit(cache=True)
def coverage_room(env, steps):
    """The coverage steps a pursuit may fly when ``steps`` are left in the budget after its
    intercept: ``steps``, or fewer under the env's ``coverage_steps``."""
    if env.coverage_steps < 0:
        return steps
    return min(steps, env.coverage_steps)


@numba.njit(cache=True)
def paper_outcome(estimator, env, state, a, t, ic, work):
    """`PaperEstimator`'s outcome of pursuing ``a`` (module docstring)."""
    mission, memo = env.mission, env.memo
    base_cov, base_step = state[2], state[3]
    left = env.n_steps - t
    start = t + ic
    if base_step[a] == 0 and memo.cutoff[a, start] >= 0:
        cutoff, p, expected = memo.cutoff[a, start], memo.p_find[a, start], memo.expected[a, start]
    else:
        q = mission.process_noise[a]
        predict_covariance_on(mission, base_cov[a], q, start - base_step[a], work)
        k, p, expected = coverage_outcome(mission, work, q, coverage_room(env, left - ic))
        cutoff = int(k)
        p = visible_find(mission, env.means[a], start * mission.time_step, work, q, p, cutoff)
        if base_step[a] == 0:
            memo.cutoff[a, start] = cutoff
            memo.p_find[a, start] = p
            memo.expected[a, start] = expected
    find_steps = max(1, ic + int(math.floor(expected + 0.5)))
    miss_steps = max(1, ic + cutoff)
    return p, find_steps, miss_steps


@numba.njit(cache=True)
def sharp_outcome(estimator, env, state, a, t, ic, work):
    """`SharpEstimator`'s outcome of pursuing ``a``: ``p_find`` includes detections on the
    intercept flight, and a find lasts the estimated duration from departure."""
    mission = env.mission
    sf, base_cov, base_step = state[1], state[2], state[3]
    dx, dy = approach_step_to(mission, sf[0], sf[1], env.means[a], ic, t * mission.time_step)
    q = mission.process_noise[a]
    predict_covariance_on(mission, base_cov[a], q, t + ic - base_step[a], work)
    room = coverage_room(env, env.n_steps - t - ic)
    cutoff, p, expected = sharp_coverage_outcome(mission, work, q, room, ic, dx, dy)
    p = visible_find(mission, env.means[a], (t + ic) * mission.time_step, work, q, p, cutoff)
    return p, max(1, int(math.floor(expected + 0.5))), max(1, ic + int(cutoff))


register_estimator("paper", PaperEstimator, paper_outcome)
register_estimator("sharp", SharpEstimator, sharp_outcome)
