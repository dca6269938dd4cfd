"""The sub-task MDP of the global planner (paper Sec. IV-C-1 "Markov Decision Process" and
Sec. IV-C-2 "Node Expansion") as compiled kernels.

Time is counted in whole simulator steps of ``tau`` seconds from the root of the search (step 0);
the budget ends at step ``N = floor(remaining_budget / tau)``.

**State** (paper: history, action list, remaining budget, agent pose, every target's belief). The
belief means never change in this MDP: a "find" is a measurement at the predicted mean, so in
expectation the mean stays on its open-loop prediction ``mean + v t``. A state is therefore fully
described by

* ``step`` ``t`` (remaining budget ``N - t`` steps),
* ``mask``: the action list as a bitmask of the targets not yet missed,
* ``last``: the target found by the previous sub-task (``-1`` if none); choosing it again means
  following it to the end of the budget,
* the agent position (m): the estimated position of the last pursued target at step ``t``,
* per target the covariance right after its last "find" and the step of that find
  (``base_cov``, ``base_step``; never found: the root covariance and step 0). Its covariance at
  any later step follows in closed form (Eq. (1), :func:`hptrack.models.motion.predict_covariance`).

A state is the tuple of arrays ``(si, sf, base_cov, base_step)``: the integer part
``(t, mask, last)`` in an ``int64`` array ``si``, the agent position in a ``float64`` array
``sf``; the kernels mutate them in place. The kernels take ``env = (model, memo)`` first, the
interface :mod:`hptrack.planning.search` expects of an MDP.

**Action** "pursue target a" (node expansion). The agent flies to the belief mean in
``n_i = ceil(t_intercept / tau)`` steps (:func:`hptrack.coverage.intercept.intercept_steps`, the
shared whole-step convention; ``0`` when the mean is already in the footprint) and starts the
spiral coverage from the covariance predicted to step ``t + n_i``. The coverage estimator
(:func:`hptrack.coverage.estimator.coverage_outcome`, Sec. IV-B) gives ``t_cutoff``, ``p_max``
and ``E[T_find]``, truncated to the ``N - t - n_i`` steps left (budget truncation). The action
is available only when ``n_i < N - t``. Outcomes:

* find, probability ``p_find = p_max``: the sub-task lasts ``n_i + round(E[T_find])`` steps
  (nearest step, halves up); the target's belief becomes the posterior of a position measurement
  (noise ``R``) at that step;
* miss, probability ``1 - p_max``: it lasts ``n_i + t_cutoff`` steps and the target leaves the
  action list.

Either way the agent ends at the target's estimated position and every other belief grows by the
time spent. A sub-task lasts at least one step (so a history always advances in time). Choosing the
target found by the previous sub-task again follows it to the end of the budget with its detection
guaranteed: it is measured at every step, its covariance follows the Riccati recursion
(:func:`hptrack.models.riccati.measured_covariance`).

**Dwell** (an option beyond the paper, off by default: ``dwell_steps = 0``). With
``dwell_steps > 0`` the MDP has one more action, index ``n`` ("dwell"): follow the target just
found for ``dwell_steps`` steps only, measured at every step, then choose again with that target
still the last found. A single find fixes a target's position but leaves much of its velocity
uncertain, so its belief grows fast afterwards; a short dwell measures the velocity too. The
action is available when a target was just found and the dwell ends strictly before the budget
(otherwise it is the follow). At the end of the budget, or when no action is
available, the value of the state is ``-U`` with ``U = sum_i log det Sigma^xy_i`` at step ``N``
(Sec. III).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba
import numpy as np

from hptrack.coverage.estimator import coverage_outcome
from hptrack.coverage.intercept import approach_step, intercept_steps
from hptrack.coverage.sharp_estimator import sharp_coverage_outcome
from hptrack.models.beliefs import logdet_xy
from hptrack.models.measurement import update_covariance
from hptrack.models.motion import mean_position_at, position_covariance_after, predict_covariance
from hptrack.models.riccati import measured_covariance, riccati_table
from hptrack.planning.mdp import MdpKernels, register_mdp

if TYPE_CHECKING:
    from hptrack.interface import MissionSpec, Observation

I_STEP, I_MASK, I_LAST = 0, 1, 2
"""Indices of ``t``, the action bitmask and the last found target in the state array ``si``."""

MAX_TARGETS = 62
"""The action list is an ``int64`` bitmask."""

WORK_SLOTS = 5
"""Number of 4x4 scratch matrices the kernels need (:func:`new_work`)."""


class Model(NamedTuple):
    """Everything the kernels need that does not change during a search (arrays are float64).

    Attributes:
        means: ``(n, 4)`` belief means at the root, m and m/s.
        process_noise: ``(n,)`` process noise intensities ``q``, m^2/s^3.
        measurement_noise: ``(2, 2)`` measurement noise covariance ``R``, m^2.
        time_step: ``tau``, s.
        c_per_step: lower-right per-step ``Q`` block over ``q`` (``tau`` or ``1``).
        agent_speed: ``v_a``, m/s.
        sensor_diameter: footprint diameter ``w``, m.
        n_steps: ``N``, the steps left in the budget at the root.
        follow_a, follow_g, follow_h: ``(n, L, 4, 4)`` measured-every-step maps
            (:func:`hptrack.models.riccati.riccati_table`).
        follow_len: ``(n,)`` number of valid entries of each target's maps.
        sharp: expand with the sharp estimator instead of the paper's (see
            :class:`PlanningProblem`).
        dwell_steps: length of the dwell action in steps; 0: no dwell action (the paper).
    """

    means: np.ndarray
    process_noise: np.ndarray
    measurement_noise: np.ndarray
    time_step: float
    c_per_step: float
    agent_speed: float
    sensor_diameter: float
    n_steps: int
    follow_a: np.ndarray
    follow_g: np.ndarray
    follow_h: np.ndarray
    follow_len: np.ndarray
    sharp: bool
    dwell_steps: int


class Memo(NamedTuple):
    """Estimator results for coverages of targets never found since the root, by start step.

    Such a coverage depends only on the target and its start step ``s`` (the covariance is the
    root's grown ``s`` steps, the truncation is ``N - s``), so each ``(target, s)`` is estimated
    once per search. ``cutoff[a, s] < 0``: not computed yet.
    """

    cutoff: np.ndarray
    p_find: np.ndarray
    expected: np.ndarray


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """The root state of a search (paper Sec. IV-C-2) and the model it is planned with.

    Attributes:
        agent_position: ``(2,)`` agent position, m.
        means: ``(n, 4)`` belief means ``[x, y, vx, vy]``, m and m/s.
        covariances: ``(n, 4, 4)`` belief covariances.
        process_noise: ``(n,)`` noise intensities ``q``, m^2/s^3.
        remaining_budget: time left, s (the search plans ``floor(remaining / tau)`` steps).
        time_step: ``tau``, s.
        c_per_step: lower-right per-step ``Q`` block over ``q``: ``tau`` (continuous form) or
            ``1`` (the paper's printed form), see :mod:`hptrack.models.motion`.
        agent_speed: ``v_a``, m/s.
        sensor_diameter: footprint diameter ``w``, m.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
        available: ``(n,)`` targets still in the action list (not missed); default all.
        last_found: the target found by the sub-task that just ended, if any (choosing it again
            follows it to the end of the budget).
        current_action: re-planning mode (Sec. IV-C-4): the target being pursued, fixed as the
            root's only action; ``None`` for a first plan.
        estimator: ``"paper"`` (Sec. IV-B) or ``"sharp"``
            (:mod:`hptrack.coverage.sharp_estimator`: detections on the intercept flight and the
            footprint's reach; the find outcome then lasts the estimated duration from
            departure, and the estimate depends on the approach, so it is not memoised).
        dwell_time: length of the dwell action, s (rounded to whole steps, at least one); 0
            (the paper): no dwell action. With it, action ``n_targets`` is the dwell and
            ``current_action`` may be it.
    """

    agent_position: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    process_noise: np.ndarray
    remaining_budget: float
    time_step: float
    c_per_step: float
    agent_speed: float
    sensor_diameter: float
    measurement_noise: np.ndarray
    available: np.ndarray | None = None
    last_found: int | None = None
    current_action: int | None = None
    estimator: str = "paper"
    dwell_time: float = 0.0

    def __post_init__(self) -> None:
        means = _frozen(self.means, "means")
        n = means.shape[0] if means.ndim == 2 else 0
        if means.shape != (n, 4) or not 1 <= n <= MAX_TARGETS:
            raise ValueError(
                f"means must have shape (n, 4) with 1 <= n <= {MAX_TARGETS}, got {means.shape}"
            )
        checks = {
            "agent_position": (2,),
            "covariances": (n, 4, 4),
            "process_noise": (n,),
            "measurement_noise": (2, 2),
        }
        arrays = {name: _frozen(getattr(self, name), name) for name in checks}
        for name, shape in checks.items():
            if arrays[name].shape != shape:
                raise ValueError(f"{name} must have shape {shape}, got {arrays[name].shape}")
        available = (
            np.ones(n, dtype=bool)
            if self.available is None
            else np.array(self.available, dtype=bool)
        )
        if available.shape != (n,):
            raise ValueError(f"available must have shape ({n},), got {available.shape}")
        available.flags.writeable = False
        for name in (
            "remaining_budget",
            "time_step",
            "agent_speed",
            "sensor_diameter",
            "c_per_step",
        ):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
            object.__setattr__(self, name, value)
        noise = arrays["measurement_noise"]
        if not (np.allclose(noise, noise.T) and np.all(np.linalg.eigvalsh(noise) > 0.0)):
            raise ValueError("measurement_noise must be symmetric positive definite")
        if self.estimator not in ("paper", "sharp"):
            raise ValueError(f"estimator must be 'paper' or 'sharp', got {self.estimator!r}")
        dwell = float(self.dwell_time)
        if not (math.isfinite(dwell) and dwell >= 0.0):
            raise ValueError(f"dwell_time must be a non-negative finite number, got {dwell!r}")
        object.__setattr__(self, "dwell_time", dwell)
        if self.last_found is not None and not (
            0 <= self.last_found < n and available[self.last_found]
        ):
            raise ValueError(f"last_found={self.last_found} is not an available target")
        action = self.current_action
        if action is not None and not (
            (0 <= action < n and available[action])
            or (action == n and self.dwell_steps > 0 and self.last_found is not None)
        ):
            raise ValueError(
                f"current_action={action} is not an available target"
                + (" or the dwell" if self.dwell_steps > 0 else "")
            )
        object.__setattr__(self, "means", means)
        object.__setattr__(self, "available", available)
        for name, array in arrays.items():
            object.__setattr__(self, name, array)

    @classmethod
    def from_mission(
        cls,
        mission: MissionSpec,
        observation: Observation,
        available: np.ndarray | None = None,
        last_found: int | None = None,
        current_action: int | None = None,
        estimator: str = "paper",
        dwell_time: float = 0.0,
    ) -> PlanningProblem:
        """The problem seen from an :class:`~hptrack.interface.Observation` of a mission
        described by a :class:`~hptrack.interface.MissionSpec`."""
        return cls(
            agent_position=observation.agent_position,
            means=observation.means,
            covariances=observation.covariances,
            process_noise=mission.process_noise,
            remaining_budget=observation.remaining_budget,
            time_step=mission.time_step,
            c_per_step=mission.c_per_step,
            agent_speed=mission.agent_speed,
            sensor_diameter=mission.sensor_diameter,
            measurement_noise=mission.measurement_noise,
            available=available,
            last_found=last_found,
            current_action=current_action,
            estimator=estimator,
            dwell_time=dwell_time,
        )

    @property
    def n_targets(self) -> int:
        return self.means.shape[0]

    @property
    def n_steps(self) -> int:
        """``N``: whole steps left in the budget."""
        return steps_left(self.remaining_budget, self.time_step)

    @property
    def dwell_steps(self) -> int:
        """Steps of the dwell action (0: none)."""
        return dwell_steps(self.dwell_time, self.time_step)

    @property
    def n_actions(self) -> int:
        """Actions of the MDP: one per target, and the dwell if there is one."""
        return self.n_targets + (1 if self.dwell_steps > 0 else 0)

    @property
    def mask(self) -> int:
        """The root's action list as a bitmask."""
        return int(sum(1 << i for i in np.flatnonzero(self.available)))

    def model(self) -> Model:
        """The compiled kernels' view of the problem (builds the follow maps of every target)."""
        n_steps = self.n_steps
        tables = [
            riccati_table(
                float(q),
                self.time_step,
                self.c_per_step,
                np.ascontiguousarray(self.measurement_noise),
                n_steps,
            )
            for q in self.process_noise
        ]
        lengths = np.array([t[3] for t in tables], dtype=np.int64)
        stacked = [np.stack([t[k][: lengths.max()] for t in tables]) for k in range(3)]
        return Model(
            np.ascontiguousarray(self.means),
            np.ascontiguousarray(self.process_noise),
            np.ascontiguousarray(self.measurement_noise),
            self.time_step,
            self.c_per_step,
            self.agent_speed,
            self.sensor_diameter,
            n_steps,
            stacked[0],
            stacked[1],
            stacked[2],
            lengths,
            self.estimator == "sharp",
            self.dwell_steps,
        )

    def root_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Fresh state arrays ``(si, sf, base_cov, base_step)`` of the root (``base_step`` 0)."""
        last = -1 if self.last_found is None else self.last_found
        si = np.array([0, self.mask, last], dtype=np.int64)
        return (
            si,
            np.array(self.agent_position, dtype=np.float64),
            np.array(self.covariances, dtype=np.float64),
            np.zeros(self.n_targets, dtype=np.int64),
        )


def steps_left(remaining_budget: float, time_step: float) -> int:
    """Whole steps of ``time_step`` s in ``remaining_budget`` s (``N``)."""
    return int(math.floor(remaining_budget / time_step + 1e-9))


def dwell_steps(dwell_time: float, time_step: float) -> int:
    """Whole steps of a dwell of ``dwell_time`` s (nearest, at least one; 0 for no dwell)."""
    if dwell_time == 0.0:
        return 0
    return max(1, int(math.floor(dwell_time / time_step + 0.5)))


def _frozen(value, name: str) -> np.ndarray:
    array = np.array(value, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    array.flags.writeable = False
    return array


def new_work() -> np.ndarray:
    """Scratch space for the kernels' 4x4 temporaries."""
    return np.empty((WORK_SLOTS, 4, 4))


def new_memo(n_targets: int, n_steps: int) -> Memo:
    """An empty :class:`Memo` for ``n_targets`` targets and ``n_steps`` budget steps."""
    return Memo(
        np.full((n_targets, n_steps + 1), -1, dtype=np.int64),
        np.zeros((n_targets, n_steps + 1)),
        np.zeros((n_targets, n_steps + 1)),
    )


class SubtaskEnv(NamedTuple):
    """The sub-task MDP's ``env`` for the search (:mod:`hptrack.planning.mdp`)."""

    model: Model
    memo: Memo


@numba.njit(cache=True)
def copy_state(env, src, dst):
    """Copy the state ``src`` into the scratch state ``dst`` (both ``(si, sf, base_cov,
    base_step)``)."""
    si, sf, base_cov, base_step = src
    di, df, dcov, dstep = dst
    for i in range(3):
        di[i] = si[i]
    df[0] = sf[0]
    df[1] = sf[1]
    for a in range(base_cov.shape[0]):
        dstep[a] = base_step[a]
        for i in range(4):
            for j in range(4):
                dcov[a, i, j] = base_cov[a, i, j]


@numba.njit(cache=True)
def intercept_of(model, sf, a, t):
    """Whole intercept steps from the agent position ``sf`` at step ``t`` to target ``a``'s
    belief mean (``-1``: the target is faster than the agent)."""
    m = model.means[a]
    x, y = mean_position_at(m, t * model.time_step)
    return intercept_steps(
        sf[0],
        sf[1],
        x,
        y,
        m[2],
        m[3],
        model.agent_speed,
        model.time_step,
        0.5 * model.sensor_diameter,
    )


@numba.njit(cache=True, inline="always")
def is_dwell(model, a):
    """Whether action ``a`` is the dwell (index ``n``, after the targets)."""
    return a == model.means.shape[0]


@numba.njit(cache=True)
def is_available(env, state, a):
    """Whether target ``a`` is an action of the state: in the action list and either followed
    (``a`` was just found) or interceptable strictly before the end of the budget; or, for
    ``a = n``, whether the dwell is (a target was just found, and the dwell ends before the
    budget)."""
    model = env.model
    si, sf = state[0], state[1]
    t = si[I_STEP]
    if t >= model.n_steps:
        return False
    if is_dwell(model, a):
        return si[I_LAST] >= 0 and model.dwell_steps < model.n_steps - t
    if not (si[I_MASK] >> a) & 1:
        return False
    if a == si[I_LAST]:
        return True
    ic = intercept_of(model, sf, a, t)
    return 0 <= ic < model.n_steps - t


@numba.njit(cache=True)
def expand_action(env, state, a, work):
    """Node expansion of "pursue ``a``", an available action of the state (Sec. IV-C-2).

    Returns ``(p_find, find_steps, miss_steps)``: the probability of the find outcome and the
    sub-task's duration for each outcome, in steps. Following (``a`` was just found) has
    ``p_find = 1`` and lasts to the end of the budget; the dwell has ``p_find = 1`` and lasts
    ``dwell_steps``. ``work`` is ``(>= 1, 4, 4)`` scratch.
    """
    model, memo = env.model, env.memo
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    left = model.n_steps - t
    if a == si[I_LAST]:
        return 1.0, left, left
    if is_dwell(model, a):
        return 1.0, model.dwell_steps, model.dwell_steps
    ic = intercept_of(model, sf, a, t)
    start = t + ic
    if model.sharp:
        return _expand_sharp(model, state, a, ic, work[0])
    if base_step[a] == 0 and memo.cutoff[a, start] >= 0:
        cutoff, p, expected = memo.cutoff[a, start], memo.p_find[a, start], memo.expected[a, start]
    else:
        cov = work[0]
        predict_covariance(
            base_cov[a],
            model.process_noise[a],
            start - base_step[a],
            model.time_step,
            model.c_per_step,
            cov,
        )
        k, p, expected = coverage_outcome(
            cov,
            model.process_noise[a],
            model.time_step,
            model.c_per_step,
            model.agent_speed,
            model.sensor_diameter,
            left - ic,
        )
        cutoff = int(k)
        if base_step[a] == 0:
            memo.cutoff[a, start] = cutoff
            memo.p_find[a, start] = p
            memo.expected[a, start] = expected
    find_steps = max(1, ic + int(math.floor(expected + 0.5)))
    miss_steps = max(1, ic + cutoff)
    return p, find_steps, miss_steps


@numba.njit(cache=True)
def _expand_sharp(model, state, a, ic, cov):
    """:func:`expand_action` with the sharp estimator: ``p_find`` includes detections on the
    intercept flight, and a find lasts the estimated duration from departure."""
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    m = model.means[a]
    x, y = mean_position_at(m, t * model.time_step)
    dx, dy = approach_step(sf[0], sf[1], x, y, m[2], m[3], model.agent_speed, model.time_step, ic)
    predict_covariance(
        base_cov[a],
        model.process_noise[a],
        t + ic - base_step[a],
        model.time_step,
        model.c_per_step,
        cov,
    )
    cutoff, p, expected = sharp_coverage_outcome(
        cov,
        model.process_noise[a],
        model.time_step,
        model.c_per_step,
        model.agent_speed,
        model.sensor_diameter,
        model.n_steps - t - ic,
        ic,
        dx,
        dy,
    )
    return p, max(1, int(math.floor(expected + 0.5))), max(1, ic + int(cutoff))


@numba.njit(cache=True)
def apply_outcome(env, state, a, found, payload, work):
    """Move the state through the sub-task "pursue ``a``" lasting ``payload`` steps.

    Found: ``a``'s covariance becomes the posterior of a measurement at the end step (or, when
    following or dwelling, the covariance measured at every step to the end). Missed: ``a``
    leaves the action list. The agent ends at the pursued target's estimated position; other
    beliefs are implicit (they grow from their base). ``work`` is ``(>= 5, 4, 4)`` scratch.
    """
    model = env.model
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    end = t + payload
    if is_dwell(model, a):
        a = si[I_LAST]  # the dwell measures the target just found, which stays the last found
    if found:
        prior = work[4]
        q = model.process_noise[a]
        if a == si[I_LAST]:
            x1 = work[3]
            predict_covariance(base_cov[a], q, 1, model.time_step, model.c_per_step, x1)
            measured_covariance(
                model.follow_a[a],
                model.follow_g[a],
                model.follow_h[a],
                model.follow_len[a],
                payload - 1,
                x1,
                model.measurement_noise,
                prior,
                work,
            )
            for i in range(4):
                for j in range(4):
                    base_cov[a, i, j] = prior[i, j]
        else:
            predict_covariance(
                base_cov[a], q, end - base_step[a], model.time_step, model.c_per_step, prior
            )
            update_covariance(prior, model.measurement_noise, base_cov[a])
        base_step[a] = end
        si[I_LAST] = a
    else:
        si[I_MASK] &= ~(np.int64(1) << a)
        si[I_LAST] = -1
    si[I_STEP] = end
    x, y = mean_position_at(model.means[a], end * model.time_step)
    sf[0] = x
    sf[1] = y


@numba.njit(cache=True)
def terminal_value(env, state):
    """``-U``: minus the sum of the position log-determinants at the end of the budget
    (Sec. III), every belief grown in closed form from its base (Algorithm 1, line 17)."""
    model = env.model
    base_cov, base_step = state[2], state[3]
    total = 0.0
    for i in range(base_cov.shape[0]):
        sxx, sxy, syy = position_covariance_after(
            base_cov[i],
            model.process_noise[i],
            float(model.n_steps - base_step[i]),
            model.time_step,
            model.c_per_step,
        )
        total += logdet_xy(sxx, sxy, syy)
    return -total


register_mdp(
    SubtaskEnv, MdpKernels(copy_state, is_available, expand_action, apply_outcome, terminal_value)
)
