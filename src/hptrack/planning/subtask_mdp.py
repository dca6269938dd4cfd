"""The sub-task MDP of the global planner (paper Sec. IV-C-1 "Markov Decision Process" and
Sec. IV-C-2 "Node Expansion") as compiled kernels.

Time is counted in whole simulator steps of ``tau`` seconds from the root of the search (step 0);
the budget ends at step ``N = floor(remaining_budget / tau)``.

**State** (paper: history, action list, remaining budget, agent pose, every target's belief). The
belief means never change in this MDP: a "find" is a measurement at the predicted mean, so in
expectation the mean stays on its open-loop prediction ``mean + v t``. A state is therefore fully
described by

* ``step`` ``t`` (remaining budget ``N - t`` steps),
* the action list: the targets not yet missed, as a bitmask in 63-bit words (`in_list`),
* ``last``: the target found by the previous sub-task (``-1`` if none); choosing it again means
  following it to the end of the budget,
* the agent position (m): the estimated position of the last pursued target at step ``t``,
* per target the covariance right after its last "find" and the step of that find
  (``base_cov``, ``base_step``; never found: the root covariance and step 0). Its covariance at
  any later step follows in closed form (Eq. (1), `hptrack.models.motion.predict_covariance`).

A state is the tuple of arrays ``(si, sf, base_cov, base_step)``: the integer part
``(t, word 0, last, word 1, word 2, ...)`` in an ``int64`` array ``si`` (`int_size`; one word,
``(t, mask, last)``, up to 63 targets), the agent position in a ``float64`` array ``sf``; the
kernels mutate them in place. The kernels take ``env`` (`SubtaskEnv`: the mission record, its
Riccati tables, the root's means, the options, the memo) first, the interface
`hptrack.planning.search` expects of an MDP.

**Action** "pursue target a" (node expansion). The agent flies to the belief mean in
``n_i = ceil(t_intercept / tau)`` steps (`hptrack.coverage.intercept.intercept_steps`, the
shared whole-step convention; ``0`` when the mean is already in the footprint) and starts the
spiral coverage from the covariance predicted to step ``t + n_i``. The coverage estimator
(`hptrack.coverage.estimator.coverage_outcome`, Sec. IV-B) gives ``t_cutoff``, ``p_max``
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
(`hptrack.models.riccati.measured_covariance`).

**Dwell** (an option beyond the paper, off by default: ``dwell = 0``). With dwell lengths
``stay_steps`` the MDP has one more action per length, index ``n + j`` for the ``j``-th
(`hptrack.subtasks.ActionTable`, the one place that numbers the actions): follow the target
just found for ``stay_steps[j]`` steps only, measured at every step, then choose again
with that target still the last found. A single find
fixes a target's position but leaves much of its velocity uncertain, so its belief grows fast
afterwards; a short dwell measures the velocity too. A dwell is available when a target was
just found and it ends strictly before the budget (otherwise it is the follow).

**Kept misses** (``miss="keep"``, beyond the paper): a miss leaves the target in the action
list, its belief unmeasured (its base unchanged), so it may be pursued again.

**Passes credited** (``passes="credit"``, beyond the paper; the paper's ``"ignore"`` credits a
sub-task with its own target only): every sub-task is taken as the straight flight from the
agent's position to where it ends, and each other target whose belief that flight crosses with
probability at least `PASS_CREDIT` (`pass_probability`) counts as measured at the
closest approach, its covariance updated there, and back in the action list if it was missed.

**Negative information** (the scenario's ``sensor.negative_information``, beyond the paper): a
pursuit that ends in a miss says the target was not where the spiral swept. Its covariance
predicted to the miss's end is scaled by the closed form of a look over the Mahalanobis disc the
spiral covered (`hptrack.models.miss_update.search_miss_scale`: ``a = -ln(1 - p_find) / eta``,
detected there with ``p_find / (1 - e^-a)``), and that is its base from then on, so
``miss="keep"`` re-pursues it with the belief the miss left (and ``"drop"`` scores it so).

**False finds** (``false_finds="model"``, beyond the paper; only with the mission's clutter,
`hptrack.models.mission.Mission.false_alarm_density`): a pursuit has a third outcome, the
tracker taking a false alarm for the target before the search finds it or gives up
(`hptrack.coverage.false_finds`: the find and the miss each lose the chance of a take first).
It lasts the intercept and the mean search before the take, the target's belief is left as it
was (the update went to a false alarm, so nothing was learnt) and the target leaves the action
list as after a miss. The world reports a false find as a find: the search's plans after it
are never flown, and a re-planning search shares its simulations among the find and the miss
only (`OBSERVED`). The tour and the exact solver (`hptrack.planning.tour`,
`hptrack.planning.subtask_optimum`) plan with the find and the miss.

At the end of the budget, or when no action is available, the value of the state is ``-U``
with ``U = sum_i log det Sigma^xy_i`` at step ``N``
(Sec. III).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numba
import numpy as np

from hptrack.coverage.false_finds import false_find_split, take_rate
from hptrack.coverage.passes import pass_probability
from hptrack.models.beliefs import logdet_xy
from hptrack.models.mission import (
    MAX_TARGETS,
    FollowTables,
    Mission,
    follow_tables,
    intercept_steps_to,
    mean_position_on,
    mean_state_on,
    position_covariance_on,
    predict_covariance_on,
    reachable_before_budget,
    state_size,
    state_size_on,
    steps_left,
)
from hptrack.models.riccati import measured_covariance
from hptrack.models.sensor import (
    footprint_radius,
    sensor_informs,
    sensor_search_missed,
    sensor_update_covariance,
)
from hptrack.models.state import velocity_of
from hptrack.planning.mdp import MdpKernels, register_mdp
from hptrack.planning.subtask_estimators import estimate_pursuit, estimator_of
from hptrack.subtasks import ActionTable, dwell_number, is_dwell_index

if TYPE_CHECKING:
    from hptrack.interface import Observation

I_STEP, I_MASK, I_LAST = 0, 1, 2
"""Indices of ``t``, the action list's first word and the last found target in the state array
``si``; the list's further words follow ``I_LAST`` (`int_size`)."""

WORD_BITS = 63
"""Targets per word of the action list: target ``a`` is bit ``a % 63`` of word ``a // 63``, an
``int64`` without its sign bit (so a word is never negative)."""

OUTCOMES = ("find", "miss", "false find")
"""A sub-task's chance outcomes, by index (the search's outcome ``o``). The false find is an
outcome only when the MDP models false finds (`SubtaskEnv.false_alarm_density` above 0); the
world reports it as a find, so the plans made after it are never flown (`OBSERVED`)."""
FIND, MISS, FALSE_FIND = 0, 1, 2
OBSERVED = 2
"""The outcomes the world tells apart (find and miss): a re-planning search shares its
simulations among these."""

WORK_SLOTS = 5
"""Number of 4x4 scratch matrices the kernels need (`new_work`)."""


class SubtaskOptions(NamedTuple):
    """The sub-task MDP's options under the planner settings' names (defaults: the paper's).

    Attributes:
        estimator: ``"paper"`` (Sec. IV-B) or ``"sharp"``
            (`hptrack.coverage.sharp_estimator`: detections on the intercept flight and the
            footprint's reach; the find outcome then lasts the estimated duration from
            departure, and the estimate depends on the approach, so it is not memoised).
        dwell: length of the dwell action, s (rounded to whole steps, at least one,
            `dwell_steps`), or several lengths, one dwell action each (`stay_steps`);
            0 (the paper): no dwell action.
        miss: what a miss does to the missed target: ``"drop"`` (the paper) takes it out of
            the action list; ``"keep"`` leaves it in, its belief grown by the time spent, so
            the search may pursue it again.
        passes: ``"ignore"`` (the paper): a sub-task measures its own target only;
            ``"credit"``: also the other targets its flight passes over (module docstring).
        false_finds: ``"ignore"`` (the paper): a pursuit ends in a find or a miss;
            ``"model"``: under the mission's clutter (`Mission.false_alarm_density`) also in a
            false find (module docstring).
        coverage_limit: the longest spiral a pursuit flies, s (rounded to whole steps, at
            least one, `coverage_steps`): its coverage ends at ``t_cutoff`` or after this
            long, whichever comes first, and the estimate is truncated there as at the
            budget's end; 0 (the paper): ``t_cutoff`` alone.
    """

    estimator: str = "paper"
    dwell: float | tuple[float, ...] = 0.0
    miss: str = "drop"
    passes: str = "ignore"
    false_finds: str = "ignore"
    coverage_limit: float = 0.0


PAPER_SUBTASK = SubtaskOptions()
"""The paper's sub-task MDP."""


class Memo(NamedTuple):
    """Estimator results for coverages of targets never found since the root, by start step.

    Such a coverage depends only on the target and its start step ``s`` (the covariance is the
    root's grown ``s`` steps, the truncation is ``N - s``), so each ``(target, s)`` is estimated
    once per search. ``cutoff[a, s] < 0``: not computed yet.
    """

    cutoff: np.ndarray
    p_find: np.ndarray
    expected: np.ndarray


class SubtaskEnv(NamedTuple):
    """The sub-task MDP's ``env`` for the search (`hptrack.planning.mdp`): everything the
    kernels need that does not change during a search, and the memo they write.

    Attributes:
        mission: the mission record.
        follow: the targets' Riccati tables (measured at every step).
        means: ``(n, d)`` belief means at the root, m and m/s (m/s^2).
        n_steps: ``N``, the steps left in the budget at the root.
        estimator: the outcome estimator, a registered instance
            (`hptrack.planning.subtask_estimators`).
        stay_steps: ``(k,)`` lengths of the dwell actions in steps (action ``n + j`` dwells
            ``stay_steps[j]``); empty: no dwell action (the paper).
        keep_missed: a miss leaves the target in the action list (``miss="keep"``).
        credit_passes: other targets a sub-task's flight passes over are measured
            (``passes="credit"``).
        memo: the estimator results of this search.
        false_alarm_density: ``lambda`` of the false finds modelled, per m^2 per look
            (``false_finds="model"``: the mission's; 0: no false find outcome).
        coverage_steps: the longest coverage of a pursuit in steps (``coverage_limit``);
            -1: none (the paper's ``t_cutoff`` alone).
    """

    mission: Mission
    follow: FollowTables
    means: np.ndarray
    n_steps: int
    estimator: tuple
    stay_steps: np.ndarray
    keep_missed: bool
    credit_passes: bool
    memo: Memo
    false_alarm_density: float = 0.0
    coverage_steps: int = -1


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """The root of a search (paper Sec. IV-C-2): the mission, the root beliefs and the current
    action.

    Attributes:
        mission: the mission record (`hptrack.interface.MissionSpec.record`).
        agent_position: ``(2,)`` agent position, m.
        means: ``(n, d)`` belief means ``[x, y, vx, vy]`` (with ``[ax, ay]`` when ``d = 6``,
            the mission's `hptrack.models.mission.state_size`), m, m/s, m/s^2.
        covariances: ``(n, d, d)`` belief covariances.
        remaining_budget: time left, s (the search plans `steps_left` steps).
        available: ``(n,)`` targets still in the action list (not missed); default all.
        last_found: the target found by the sub-task that just ended, if any (choosing it again
            follows it to the end of the budget).
        current_action: re-planning mode (Sec. IV-C-4): the target being pursued (or a
            dwell, `hptrack.subtasks.ActionTable`), fixed as the root's only action; ``None``
            for a first plan.
        follow: the mission's Riccati tables (`hptrack.models.mission.follow_tables`),
            built once per mission and shared; default built here.
    """

    mission: Mission
    agent_position: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    remaining_budget: float
    available: np.ndarray | None = None
    last_found: int | None = None
    current_action: int | None = None
    follow: FollowTables | None = None

    def __post_init__(self) -> None:
        n = self.mission.process_noise.shape[0]
        d = state_size(self.mission)
        checks = {"agent_position": (2,), "means": (n, d), "covariances": (n, d, d)}
        arrays = {name: _frozen(getattr(self, name), name) for name in checks}
        if not 1 <= n <= MAX_TARGETS:
            raise ValueError(f"the mission must have 1 to {MAX_TARGETS} targets, got {n}")
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
        remaining = float(self.remaining_budget)
        if not (math.isfinite(remaining) and remaining > 0.0):
            raise ValueError(
                f"remaining_budget must be a positive finite number, got {remaining!r}"
            )
        if self.last_found is not None and not (
            0 <= self.last_found < n and available[self.last_found]
        ):
            raise ValueError(f"last_found={self.last_found} is not an available target")
        action = self.current_action
        if action is not None and not (
            (0 <= action < n and available[action])
            or (is_dwell_index(n, action) and self.last_found is not None)
        ):
            raise ValueError(f"current_action={action} is not an available target or the dwell")
        object.__setattr__(self, "remaining_budget", remaining)
        object.__setattr__(self, "available", available)
        for name, array in arrays.items():
            object.__setattr__(self, name, array)
        if self.follow is None:
            object.__setattr__(self, "follow", follow_tables(self.mission, self.n_steps))

    @classmethod
    def from_observation(
        cls,
        mission: Mission,
        observation: Observation,
        available: np.ndarray | None = None,
        last_found: int | None = None,
        current_action: int | None = None,
        follow: FollowTables | None = None,
    ) -> PlanningProblem:
        """The problem seen from an `Observation` of the mission."""
        return cls(
            mission,
            observation.agent_position,
            observation.means,
            observation.covariances,
            observation.remaining_budget,
            available,
            last_found,
            current_action,
            follow,
        )

    @property
    def n_targets(self) -> int:
        return self.means.shape[0]

    @property
    def n_steps(self) -> int:
        """``N``: whole steps left in the budget."""
        return steps_left(self.mission.time_step, self.remaining_budget)

    def env(self, options: SubtaskOptions = PAPER_SUBTASK) -> SubtaskEnv:
        """The compiled kernels' view of the problem with ``options``, with a fresh memo.

        Raises:
            ValueError: an unknown estimator or miss rule, or a negative dwell or coverage limit.
        """
        estimator = estimator_of(options.estimator)
        if options.miss not in MISS_RULES:
            raise ValueError(f"miss must be one of {MISS_RULES}, got {options.miss!r}")
        if options.passes not in PASS_RULES:
            raise ValueError(f"passes must be one of {PASS_RULES}, got {options.passes!r}")
        if options.false_finds not in FALSE_FIND_RULES:
            raise ValueError(
                f"false_finds must be one of {FALSE_FIND_RULES}, got {options.false_finds!r}"
            )
        n_steps = self.n_steps
        stays = stay_steps(self.mission.time_step, options.dwell)
        if self.current_action is not None and self.current_action >= self.n_targets + len(stays):
            raise ValueError(f"current_action={self.current_action} is not a dwell of {stays}")
        follow = self.follow
        assert follow is not None  # built in __post_init__ when not given
        return SubtaskEnv(
            self.mission,
            follow,
            np.ascontiguousarray(self.means),
            n_steps,
            estimator,
            np.array(stays, dtype=np.int64),
            options.miss == "keep",
            options.passes == "credit",
            new_memo(self.n_targets, n_steps),
            self.mission.false_alarm_density if options.false_finds == "model" else 0.0,
            coverage_steps(self.mission.time_step, options.coverage_limit),
        )

    def root_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Fresh state arrays ``(si, sf, base_cov, base_step)`` of the root (``base_step`` 0)."""
        last = -1 if self.last_found is None else self.last_found
        return (
            int_state(0, np.asarray(self.available), last),
            np.array(self.agent_position, dtype=np.float64),
            np.array(self.covariances, dtype=np.float64),
            np.zeros(self.n_targets, dtype=np.int64),
        )


MISS_RULES = ("drop", "keep")
"""What a miss does to the missed target (`SubtaskOptions.miss`)."""

FALSE_FIND_RULES = ("ignore", "model")
"""Whether a pursuit may end in a false find (`SubtaskOptions.false_finds`)."""

PASS_RULES = ("ignore", "credit")
"""What a sub-task's flight does to the other targets it passes over
(`SubtaskOptions.passes`)."""

PASS_CREDIT = 0.5
"""With ``passes="credit"``, the least probability of a pass (`pass_probability`) that
counts as a measurement: the MDP's state holds one belief per target, so a pass either
measures a target or does not."""


def n_actions(n_targets: int, options: SubtaskOptions) -> int:
    """Actions of the MDP: one per target, and one per dwell length (`action_table`)."""
    return n_targets + len(dwell_lengths(options.dwell))


def _whole_steps(time_step: float, seconds: float, name: str) -> int:
    """Whole steps nearest to ``seconds`` s, at least one (0 for 0 s).

    Raises:
        ValueError: a negative or non-finite duration, named ``name``.
    """
    if not (math.isfinite(seconds) and seconds >= 0.0):
        raise ValueError(f"{name} must be a non-negative finite number, got {seconds!r}")
    if seconds == 0.0:
        return 0
    return max(1, int(math.floor(seconds / time_step + 0.5)))


def dwell_steps(time_step: float, dwell: float) -> int:
    """Whole steps of a dwell of ``dwell`` s (nearest, at least one; 0 for no dwell)."""
    return _whole_steps(time_step, dwell, "dwell")


def coverage_steps(time_step: float, limit: float) -> int:
    """Whole steps of a pursuit's longest coverage of ``limit`` s (nearest, at least one; -1
    for no limit, 0 s: the paper's ``t_cutoff`` alone).

    Raises:
        ValueError: a negative or non-finite limit.
    """
    return _whole_steps(time_step, limit, "coverage_limit") or -1


def dwell_lengths(dwell: float | tuple[float, ...]) -> tuple[float, ...]:
    """The dwell actions' lengths, s: the one given, or each of several (none for a dwell of 0).

    Raises:
        ValueError: a zero among several lengths.
    """
    lengths = (float(dwell),) if isinstance(dwell, int | float) else tuple(map(float, dwell))
    if 0.0 in lengths and len(lengths) > 1:
        raise ValueError(f"dwell lengths must be positive, got {dwell!r}")
    return tuple(d for d in lengths if d != 0.0)


def stay_steps(time_step: float, dwell: float | tuple[float, ...]) -> tuple[int, ...]:
    """The dwell actions' lengths in whole steps (`dwell_steps` of each length)."""
    return tuple(dwell_steps(time_step, d) for d in dwell_lengths(dwell))


def action_table(n_targets: int, time_step: float, options: SubtaskOptions) -> ActionTable:
    """The MDP's actions with ``options`` (`hptrack.subtasks.ActionTable`): one per target,
    one per dwell length."""
    return ActionTable(n_targets, stay_steps(time_step, options.dwell))


def _frozen(value, name: str) -> np.ndarray:
    array = np.array(value, dtype=np.float64)
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be finite")
    array.flags.writeable = False
    return array


def new_work(state_size: int = 4) -> np.ndarray:
    """Scratch space for the kernels' ``d x d`` temporaries (``d = state_size``, the
    mission's `hptrack.models.mission.state_size`)."""
    return np.empty((WORK_SLOTS, state_size, state_size))


def new_memo(n_targets: int, n_steps: int) -> Memo:
    """An empty `Memo` for ``n_targets`` targets and ``n_steps`` budget steps."""
    return Memo(
        np.full((n_targets, n_steps + 1), -1, dtype=np.int64),
        np.zeros((n_targets, n_steps + 1)),
        np.zeros((n_targets, n_steps + 1)),
    )


@numba.njit(cache=True)
def int_size(n_targets):
    """Length of the state's integer part ``si`` for ``n_targets`` targets: ``t``, ``last`` and
    one word of the action list per `WORD_BITS` targets (3 up to 63 targets)."""
    return 2 + max(1, (n_targets + WORD_BITS - 1) // WORD_BITS)


@numba.njit(cache=True, inline="always")
def _word_bit(a):
    """Index in ``si`` of the action-list word holding target ``a``, and ``a``'s bit in it."""
    if a < WORD_BITS:
        return I_MASK, a
    return I_LAST + a // WORD_BITS, a % WORD_BITS


@numba.njit(cache=True, inline="always")
def in_list(si, a):
    """Whether target ``a`` is in the action list of the state's integer part ``si``."""
    w, b = _word_bit(a)
    return (si[w] >> b) & 1 == 1


@numba.njit(cache=True, inline="always")
def drop_from_list(si, a):
    """Take target ``a`` out of the action list of ``si``."""
    w, b = _word_bit(a)
    si[w] &= ~(np.int64(1) << b)


@numba.njit(cache=True, inline="always")
def add_to_list(si, a):
    """Put target ``a`` in the action list of ``si``."""
    w, b = _word_bit(a)
    si[w] |= np.int64(1) << b


@numba.njit(cache=True)
def int_state(step, available, last):
    """The state's integer part ``si`` at ``step`` with the action list ``available``
    (``(n,)`` bool) and the last found target ``last`` (``-1``: none)."""
    si = np.zeros(int_size(available.shape[0]), dtype=np.int64)
    si[I_STEP] = step
    si[I_LAST] = last
    for a in range(available.shape[0]):
        if available[a]:
            add_to_list(si, a)
    return si


@numba.njit(cache=True)
def copy_state(env, src, dst):
    """Copy the state ``src`` into the scratch state ``dst`` (both ``(si, sf, base_cov,
    base_step)``)."""
    si, sf, base_cov, base_step = src
    di, df, dcov, dstep = dst
    for i in range(si.shape[0]):
        di[i] = si[i]
    df[0] = sf[0]
    df[1] = sf[1]
    d = state_size_on(env.mission)
    for a in range(base_cov.shape[0]):
        dstep[a] = base_step[a]
        for i in range(d):
            for j in range(d):
                dcov[a, i, j] = base_cov[a, i, j]


@numba.njit(cache=True)
def intercept_of(env, sf, a, t):
    """Whole intercept steps from the agent position ``sf`` at step ``t`` to target ``a``'s
    belief mean (``-1``: the target is faster than the agent)."""
    mission = env.mission
    return intercept_steps_to(mission, sf[0], sf[1], env.means[a], t * mission.time_step)


@numba.njit(cache=True)
def subtask_feasible(mission, means, stays, a, si, agent_x, agent_y, elapsed, left):
    """Whether action index ``a`` (`hptrack.subtasks.ActionTable`) can be flown with ``left``
    whole steps of budget: the one feasibility rule of the MDP, the planner and the sub-task
    environment.

    ``si`` is the state's integer part (its action list and last found target, `int_state`).
    A dwell (``stays``: the dwell lengths in steps) needs a target just found
    (``si[I_LAST] >= 0``) and ends strictly before the budget. A target needs to be in the
    action list (`in_list`); the target just found is followed; any other must be
    interceptable strictly before the budget ends from the agent at ``(agent_x, agent_y)`` m,
    its belief mean (row of ``means``) predicted ``elapsed`` s ahead, and slower than the agent
    unless the agent is already over it."""
    if left <= 0:
        return False
    n = means.shape[0]
    last = si[I_LAST]
    if is_dwell_index(n, a):
        return last >= 0 and stays[dwell_number(n, a)] < left
    if not in_list(si, a):
        return False
    if a == last:
        return True
    m = means[a]
    steps = intercept_steps_to(mission, agent_x, agent_y, m, elapsed)
    vx, vy = velocity_of(m)
    return reachable_before_budget(steps, left) and (
        steps > 0 or math.hypot(vx, vy) < mission.vehicle.speed
    )


@numba.njit(cache=True, inline="always")
def is_dwell(env, a):
    """Whether action ``a`` is a dwell (`hptrack.subtasks.is_dwell_index`)."""
    return is_dwell_index(env.means.shape[0], a)


@numba.njit(cache=True, inline="always")
def dwell_length(env, a):
    """Steps of dwell action ``a``."""
    return env.stay_steps[dwell_number(env.means.shape[0], a)]


@numba.njit(cache=True)
def is_available(env, state, a):
    """Whether ``a`` is an action of the state (`subtask_feasible` at the state's step)."""
    si, sf = state[0], state[1]
    t = si[I_STEP]
    return subtask_feasible(
        env.mission,
        env.means,
        env.stay_steps,
        a,
        si,
        sf[0],
        sf[1],
        t * env.mission.time_step,
        env.n_steps - t,
    )


@numba.njit(cache=True)
def expand_action(env, state, a, work):
    """Node expansion of "pursue ``a``", an available action of the state (Sec. IV-C-2).

    Returns ``(p_find, find_steps, miss_steps)``: the probability of the find outcome and the
    sub-task's duration for each outcome, in steps. Following (``a`` was just found) has
    ``p_find = 1`` and lasts to the end of the budget; the dwell has ``p_find = 1`` and lasts
    ``dwell_steps``. ``work`` is ``(>= 1, d, d)`` scratch.
    """
    si, sf = state[0], state[1]
    t = si[I_STEP]
    left = env.n_steps - t
    if a == si[I_LAST]:
        return 1.0, left, left
    if is_dwell(env, a):
        d = dwell_length(env, a)
        return 1.0, d, d
    ic = intercept_of(env, sf, a, t)
    return estimate_pursuit(env.estimator, env, state, a, t, ic, work[0])


@numba.njit(cache=True)
def expand_outcomes(env, state, a, p, payload, work):
    """`expand_action` as the search asks of an MDP: ``p`` and ``payload`` of outcome
    `FIND` then `MISS` (the miss's probability ``1 - p_find``), and `FALSE_FIND` when ``p``
    has room for it (`expand_false_finds`)."""
    if p.shape[0] > FALSE_FIND:
        expand_false_finds(env, state, a, p, payload, work)
        return
    p_find, find_steps, miss_steps = expand_action(env, state, a, work)
    p[FIND] = p_find
    p[MISS] = 1.0 - p_find
    payload[FIND] = find_steps
    payload[MISS] = miss_steps


@numba.njit(cache=True)
def expand_false_finds(env, state, a, p, payload, work):
    """`expand_outcomes` with the false find: a pursuit's find and miss split by the false
    alarms its search takes (`hptrack.coverage.false_finds`, at the rate of the belief
    predicted to the spiral's start), the false find lasting the intercept and the mean search
    before the first take. Following and dwelling measure the target just found: no false
    find."""
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    p[FALSE_FIND] = 0.0
    if a == si[I_LAST] or is_dwell(env, a):
        p_find, find_steps, miss_steps = expand_action(env, state, a, work)
        p[FIND], p[MISS] = p_find, 1.0 - p_find
        payload[FIND], payload[MISS], payload[FALSE_FIND] = find_steps, miss_steps, miss_steps
        return
    mission = env.mission
    ic = intercept_of(env, sf, a, t)
    p_find, find_steps, miss_steps = estimate_pursuit(env.estimator, env, state, a, t, ic, work[0])
    cov = work[1]
    predict_covariance_on(
        mission, base_cov[a], mission.process_noise[a], t + ic - base_step[a], cov
    )
    r = mission.sensor.measurement_noise
    rate = take_rate(
        env.false_alarm_density,
        footprint_radius(mission.sensor),
        cov[0, 0],
        cov[0, 1],
        cov[1, 1],
        r[0, 0],
        r[0, 1],
        r[1, 1],
    )
    p_true, p_miss, p_false, looks = false_find_split(
        p_find, max(find_steps - ic, 0), miss_steps - ic, rate
    )
    p[FIND], p[MISS], p[FALSE_FIND] = p_true, p_miss, p_false
    payload[FIND], payload[MISS] = find_steps, miss_steps
    payload[FALSE_FIND] = max(1, ic + int(math.floor(looks + 0.5)))


@numba.njit(cache=True)
def apply_outcome(env, state, a, outcome, payload, work):
    """Move the state through the sub-task "pursue ``a``" lasting ``payload`` steps, after
    ``outcome`` (`FIND`, `MISS` or `FALSE_FIND`).

    Found: ``a``'s covariance becomes the posterior of a measurement at the end step (or, when
    following or dwelling, the covariance measured at every step to the end). Missed: ``a``
    leaves the action list (``miss="drop"``); with a sensor that ``informs``
    (``negative_information``), its covariance predicted to the end step takes the sensor's
    ``search_missed`` of the pursuit's ``p_find`` there. The agent ends at the pursued target's
    estimated position; other beliefs are implicit (they grow from their base). A false find
    ends the search with nothing learnt about ``a`` (the tracker's update went to a false
    alarm): ``a`` leaves the action list as after a miss, but no look that saw nothing updates
    it. ``work`` is ``(>= 5, d, d)`` scratch.
    """
    mission = env.mission
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    end = t + payload
    if sensor_informs(mission.sensor) and outcome == MISS and not is_dwell(env, a):
        if a != si[I_LAST]:  # a pursuit (following is never missed)
            p_find = expand_action(env, state, a, work)[0]
            missed = work[4]
            q = mission.process_noise[a]
            predict_covariance_on(mission, base_cov[a], q, end - base_step[a], missed)
            sensor_search_missed(mission.sensor, p_find, missed)
            d = state_size_on(mission)
            for i in range(d):
                for j in range(d):
                    base_cov[a, i, j] = missed[i, j]
            base_step[a] = end
    if is_dwell(env, a):
        a = si[I_LAST]  # the dwell measures the target just found, which stays the last found
    if outcome == FIND:
        prior = work[4]
        q = mission.process_noise[a]
        if a == si[I_LAST]:
            x1 = work[3]
            predict_covariance_on(mission, base_cov[a], q, 1, x1)
            follow = env.follow
            measured_covariance(
                follow.a[a],
                follow.g[a],
                follow.h[a],
                follow.length[a],
                payload - 1,
                x1,
                mission.sensor.measurement_noise,
                prior,
                work,
            )
            d = state_size_on(mission)
            for i in range(d):
                for j in range(d):
                    base_cov[a, i, j] = prior[i, j]
        else:
            predict_covariance_on(mission, base_cov[a], q, end - base_step[a], prior)
            sensor_update_covariance(mission.sensor, prior, base_cov[a])
        base_step[a] = end
        si[I_LAST] = a
    else:
        if not env.keep_missed:
            drop_from_list(si, a)
        si[I_LAST] = -1
    x, y = mean_position_on(mission, env.means[a], end * mission.time_step)
    if env.credit_passes:
        credit_passes(env, state, a, x, y, end, work[4])
    si[I_STEP] = end
    sf[0] = x
    sf[1] = y


@numba.njit(cache=True)
def credit_passes(env, state, a, end_x, end_y, end, prior):
    """Measure every target other than ``a`` that the flight from the agent's position (at the
    state's step) to ``(end_x, end_y)`` (at step ``end``) passes over with probability at least
    `PASS_CREDIT`, at the step of the closest approach to its belief mean, and put it back
    in the action list (``passes="credit"``). ``prior`` is ``d x d`` scratch."""
    mission = env.mission
    si, sf, base_cov, base_step = state
    t = si[I_STEP]
    tau = mission.time_step
    duration = (end - t) * tau
    vx, vy = (end_x - sf[0]) / duration, (end_y - sf[1]) / duration
    for b in range(base_cov.shape[0]):
        if b == a:
            continue
        m = env.means[b]
        mx, my, mvx, mvy = mean_state_on(mission, m, t * tau)
        # the agent relative to b's mean: from (ox, oy), at (rx, ry) m/s
        ox, oy, rx, ry = sf[0] - mx, sf[1] - my, vx - mvx, vy - mvy
        speed = math.sqrt(rx * rx + ry * ry)
        if speed * duration > 1e-9:
            dx, dy = rx / speed, ry / speed
            closest = min(max(-(ox * dx + oy * dy) / speed, 0.0), duration)
        else:
            dx, dy, closest = 1.0, 0.0, 0.5 * duration
        k = t + int(math.floor(closest / tau + 0.5))
        if k <= base_step[b]:
            continue
        q = mission.process_noise[b]
        sxx, sxy, syy = position_covariance_on(mission, base_cov[b], q, float(k - base_step[b]))
        p = pass_probability(
            ox, oy, dx, dy, speed * duration, sxx, sxy, syy, footprint_radius(mission.sensor)
        )
        if p >= PASS_CREDIT:
            predict_covariance_on(mission, base_cov[b], q, k - base_step[b], prior)
            sensor_update_covariance(mission.sensor, prior, base_cov[b])
            base_step[b] = k
            add_to_list(si, b)


@numba.njit(cache=True)
def terminal_value(env, state):
    """``-U``: minus the sum of the position log-determinants at the end of the budget
    (Sec. III), every belief grown in closed form from its base (Algorithm 1, line 17)."""
    mission = env.mission
    base_cov, base_step = state[2], state[3]
    total = 0.0
    for i in range(base_cov.shape[0]):
        sxx, sxy, syy = position_covariance_on(
            mission, base_cov[i], mission.process_noise[i], float(env.n_steps - base_step[i])
        )
        total += logdet_xy(sxx, sxy, syy)
    return -total


def outcomes_of(env: SubtaskEnv) -> int:
    """The outcomes of ``env``'s actions: find and miss, and the false find when modelled."""
    return len(OUTCOMES) if env.false_alarm_density > 0.0 else OBSERVED


register_mdp(
    SubtaskEnv,
    MdpKernels(
        copy_state,
        is_available,
        expand_outcomes,
        apply_outcome,
        terminal_value,
        outcomes_of,
        OBSERVED,
    ),
)
