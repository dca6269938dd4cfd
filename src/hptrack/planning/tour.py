"""The ``tour`` planner: a revisit tour over the whole remaining budget, scored in the sub-task
MDP (`hptrack.planning.subtask_mdp`), re-planned at every sub-task's end (issue 30, item 1).

A *tour* is a cyclic order of the targets it keeps. Flown in the MDP from the current state, it
pursues the next kept target in the order (skipping the one just found, and letting go of any
whose chance of a find on arrival, ``p_max``, has fallen below ``min_find`` times one pass's
chance of a detection, 1 for the paper's sensor); after a find it
dwells on the target, one dwell of ``dwell`` s at a time, while the target's velocity variance
is above ``settle_variance`` (a target whose velocity is pinned grows slowly and is cheap to find
at the next revisit); when nothing is left to pursue it follows the target just found to the
end. Its score is the MDP's own expected final ``-U`` of that policy (Sec. III), estimated on
``samples`` outcome sequences drawn once per decision and shared by every candidate (common
random numbers), each find or miss drawn with the estimator's ``p_max``.

Which tour (every decision):

1. the order: nearest insertion over the kept targets, then 2-opt and or-opt (segments of one to
   three targets, either way round), on the flight times between the belief means predicted to
   now (distance over ``v_a``, s); entered after the target just found, or at the target nearest
   the agent, in the better of the two directions;
2. the targets kept: each target's gain from leaving it out of the full tour, then the tours
   without the ``k`` best of those with a positive gain, for every ``k``; the best score wins;
3. the dwell: the chosen tour with and without its dwells;
4. the entry: the chosen tour entered at each of its targets (a one-step rollout over the
   tour: the first sub-task that, followed by the tour, scores best).

The planner flies the best tour's first sub-task (a pursuit, a dwell, or the follow), then plans
again. A miss keeps the target in the action list by default (``miss="keep"``, its belief grown,
so the tour may come back to it); with ``miss="drop"`` it leaves the list until it is measured
by chance, and the missed targets return when none is left.
"""

from __future__ import annotations

import math
import time
from typing import Annotated, Literal, NamedTuple

import numba
import numpy as np
from pydantic import Field

from hptrack.interface import CurrentPlan, MissionSpec, Observation, one_vehicle
from hptrack.models.mission import follow_tables, mean_position_on, state_size
from hptrack.models.sensor import sensor_find_factor
from hptrack.models.state import positions, velocity_variance_of
from hptrack.planning.rollout import register_policy
from hptrack.planning.subtask_flight import SubtaskFlight
from hptrack.planning.subtask_mdp import (
    FIND,
    I_LAST,
    I_STEP,
    MISS,
    PlanningProblem,
    SubtaskOptions,
    action_table,
    apply_outcome,
    copy_state,
    expand_action,
    is_available,
    new_work,
    terminal_value,
)
from hptrack.settings import PlannerSettings
from hptrack.subtasks import HOVER, Subtask

LOCAL_SEARCH_ROUNDS = 100
"""Most rounds of 2-opt and or-opt moves on one order (each round improves it or ends)."""
OR_OPT_SEGMENT = 3
"""Longest segment of targets an or-opt move relocates."""


class TourSettings(PlannerSettings):
    """Options of the revisit-tour planner (``tour``; module docstring).

    Attributes:
        dwell: length of one dwell on a target just found, s (the tour dwells again while its
            velocity variance is above ``settle_variance``).
        settle_variance: mean of the two velocity variances, (m/s)^2, below which a found
            target is left.
        min_find: a kept target whose chance of a find on arrival is below this share of one
            pass's chance of a detection (the sensor's find factor: 1 for the paper's sensor)
            is let go (passed over) for that lap.
        samples: outcome sequences each candidate tour is scored on.
        miss: ``"keep"``: a missed target stays in the action list, its belief grown;
            ``"drop"``: it leaves it until measured by chance (the paper's rule).
        estimator: the sub-task estimator of the MDP's outcomes, ``"paper"`` (Sec. IV-B) or
            ``"sharp"`` (`hptrack.coverage.sharp_estimator`).
    """

    dwell: Annotated[float, Field(gt=0.0, le=1e6)] = 10.0
    settle_variance: Annotated[float, Field(gt=0.0)] = 0.05
    min_find: Annotated[float, Field(ge=0.0, le=1.0)] = 0.9
    samples: Annotated[int, Field(ge=1, le=1000)] = 8
    miss: Literal["keep", "drop"] = "keep"
    estimator: Literal["paper", "sharp"] = "paper"

    def subtask_options(self) -> SubtaskOptions:
        """The sub-task MDP the tour is scored in: one dwell action of ``dwell`` s."""
        return SubtaskOptions(estimator=self.estimator, dwell=self.dwell, miss=self.miss)


# --- the order -----------------------------------------------------------------------------
@numba.njit(cache=True)
def nearest_insertion(cost):
    """A closed tour over the nodes of the symmetric ``(m, m)`` ``cost``: from node 0, the node
    nearest the tour inserted where it lengthens the tour least, until all are in."""
    m = cost.shape[0]
    tour = np.empty(m, dtype=np.int64)
    tour[0] = 0
    size = 1
    inside = np.zeros(m, dtype=np.bool_)
    inside[0] = True
    near = cost[0].copy()
    for _ in range(m - 1):
        node, node_cost = -1, np.inf
        for j in range(m):
            if not inside[j] and near[j] < node_cost:
                node, node_cost = j, near[j]
        at, added = 1, np.inf
        for k in range(size):
            i, nxt = tour[k], tour[(k + 1) % size]
            extra = cost[i, node] + cost[node, nxt] - cost[i, nxt]
            if extra < added:
                at, added = k + 1, extra
        for k in range(size, at, -1):
            tour[k] = tour[k - 1]
        tour[at] = node
        size += 1
        inside[node] = True
        for j in range(m):
            near[j] = min(near[j], cost[node, j])
    return tour


@numba.njit(cache=True)
def tour_length(cost, tour):
    """The length of the closed ``tour`` under ``cost``."""
    m = tour.shape[0]
    total = 0.0
    for k in range(m):
        total += cost[tour[k], tour[(k + 1) % m]]
    return total


@numba.njit(cache=True)
def two_opt_move(cost, tour):
    """Apply the first improving 2-opt move to the closed ``tour`` (node at position 0 fixed);
    whether there was one."""
    m = tour.shape[0]
    for i in range(m - 2):
        for j in range(i + 2, m if i > 0 else m - 1):
            a, b, c, d = tour[i], tour[i + 1], tour[j], tour[(j + 1) % m]
            if cost[a, c] + cost[b, d] < cost[a, b] + cost[c, d] - 1e-9:
                tour[i + 1 : j + 1] = tour[i + 1 : j + 1][::-1].copy()
                return True
    return False


@numba.njit(cache=True)
def or_opt_move(cost, tour):
    """Apply the first improving or-opt move to the closed ``tour`` (a segment of one to
    `OR_OPT_SEGMENT` nodes, not the one at position 0, moved elsewhere either way round);
    whether there was one."""
    m = tour.shape[0]
    for length in range(1, min(OR_OPT_SEGMENT, m - 2) + 1):
        for s in range(1, m - length + 1):
            e = s + length - 1
            prev, nxt = tour[s - 1], tour[(e + 1) % m]
            first, last = tour[s], tour[e]
            saved = cost[prev, first] + cost[last, nxt] - cost[prev, nxt]
            for p in range(m):
                if s - 1 <= p <= e:
                    continue
                u, v = tour[p], tour[(p + 1) % m]
                forward = cost[u, first] + cost[last, v] - cost[u, v]
                backward = cost[u, last] + cost[first, v] - cost[u, v]
                if min(forward, backward) < saved - 1e-9:
                    segment = tour[s : e + 1].copy()
                    if backward < forward:
                        segment = segment[::-1].copy()
                    rest = np.concatenate((tour[:s], tour[e + 1 :]))
                    at = p + 1 if p < s else p + 1 - length
                    tour[:] = np.concatenate((rest[:at], segment, rest[at:]))
                    return True
    return False


@numba.njit(cache=True)
def improved_tour(cost):
    """`nearest_insertion`, then 2-opt and or-opt moves until neither improves (at most
    `LOCAL_SEARCH_ROUNDS` rounds)."""
    tour = nearest_insertion(cost)
    for _ in range(LOCAL_SEARCH_ROUNDS):
        if not (two_opt_move(cost, tour) or or_opt_move(cost, tour)):
            break
    return tour


# --- the score -----------------------------------------------------------------------------
@numba.njit(cache=True)
def tour_dwells(env, state, settle):
    """Whether the tour dwells now: a dwell action exists and is available, and the target just
    found has a velocity variance above ``settle`` (``np.inf``: never)."""
    si, base_cov = state[0], state[2]
    last = si[I_LAST]
    return (
        env.stay_steps.shape[0] > 0
        and last >= 0
        and velocity_variance_of(base_cov[last]) > settle
        and is_available(env, state, env.means.shape[0])
    )


@numba.njit(cache=True)
def next_pursuit(env, state, order, at, min_find, gone, work):
    """The tour's next pursuit: the first target of the cyclic ``order`` from position ``at``
    that is not the one just found, not ``gone``, available, and found on arrival with chance
    ``p_max >= min_find eta`` (``eta`` the sensor's find factor, one pass's chance of a
    detection: 1 for the paper's sensor, so that a detector that misses does not make every
    target too unlikely to pursue); every target passed over for its low chance is marked
    ``gone``. Returns ``(target, p_max, find steps, miss steps, position after it)``; target
    ``-1``: none left."""
    m = order.shape[0]
    last = state[0][I_LAST]
    threshold = min_find * sensor_find_factor(env.mission.sensor)
    for k in range(m):
        a = order[(at + k) % m]
        if a == last or gone[a] or not is_available(env, state, a):
            continue
        p, find_steps, miss_steps = expand_action(env, state, a, work)
        if p >= threshold:
            return a, p, find_steps, miss_steps, (at + k + 1) % m
        gone[a] = True
    return -1, 0.0, 0, 0, at


@numba.njit(cache=True)
def fly_tour(env, state, order, start, settle, min_find, draws, gone, work):
    """Fly the tour ``order`` (target indices, cyclic, entered at position ``start``) in the MDP
    from ``state`` (changed in place) to the end of the budget, each outcome drawn from
    ``draws`` (uniforms, at least one per sub-task); dwells after a find while `tour_dwells`.
    A target whose chance of a find falls below ``min_find`` is let go for the rest of the
    flight (unmeasured, its belief only grows); ``gone`` is ``(n,)`` bool scratch. Returns
    ``(-U, first action)`` (``-1``: nothing to do)."""
    si = state[0]
    gone[:] = False
    dwell = env.means.shape[0]
    at, drawn, first = start, 0, -1
    while si[I_STEP] < env.n_steps:
        last = si[I_LAST]
        if tour_dwells(env, state, settle):
            _, steps, _ = expand_action(env, state, dwell, work)
            apply_outcome(env, state, dwell, FIND, steps, work)
            first = dwell if first < 0 else first
            continue
        pick, p, find_steps, miss_steps, at = next_pursuit(
            env, state, order, at, min_find, gone, work
        )
        if pick < 0:
            if last >= 0:  # nothing left to pursue: follow the target just found
                first = last if first < 0 else first
                apply_outcome(env, state, last, FIND, env.n_steps - si[I_STEP], work)
            break
        first = pick if first < 0 else first
        if draws[drawn] < p:
            apply_outcome(env, state, pick, FIND, find_steps, work)
        else:
            apply_outcome(env, state, pick, MISS, miss_steps, work)
        drawn += 1
    return terminal_value(env, state), first


@numba.njit(cache=True)
def tour_score(env, root, scratch, order, start, settle, min_find, draws, gone, work):
    """The tour's mean ``-U`` over the outcome sequences ``draws`` (one row each) from the state
    ``root``, and its first action (`fly_tour`); ``scratch`` is a state to fly in, ``gone``
    `fly_tour`'s scratch."""
    total, first = 0.0, -1
    for r in range(draws.shape[0]):
        copy_state(env, root, scratch)
        value, first = fly_tour(env, scratch, order, start, settle, min_find, draws[r], gone, work)
        total += value
    return total / draws.shape[0], first


# --- the plan ------------------------------------------------------------------------------
class TourPlan(NamedTuple):
    """The best tour from one MDP state (`plan_tour`).

    Attributes:
        order: ``(k,)`` the kept targets in their cyclic order, entered at position 0.
        settle: the velocity variance below which a found target is left, (m/s)^2
            (``inf``: the tour does not dwell).
        first: its first action (`hptrack.subtasks.ActionTable` index; ``-1``: none).
        value: its mean ``-U`` over the outcome sequences it was scored on.
    """

    order: np.ndarray
    settle: float
    first: int
    value: float


def cyclic_order(
    where: np.ndarray, agent: np.ndarray, kept: np.ndarray, last_found: int | None, speed: float
) -> np.ndarray:
    """The cyclic order of the ``kept`` targets (nearest insertion, 2-opt, or-opt on the
    flight times at ``speed`` m/s between their positions ``where``, ``(n, 2)`` m), entered
    after ``last_found`` when it is kept, else at the target nearest ``agent`` (m)."""
    if kept.size == 0:
        return kept
    at = where[kept]
    gaps = at[:, None, :] - at[None, :, :]
    cycle = kept[improved_tour(np.hypot(gaps[..., 0], gaps[..., 1]) / speed)]
    if last_found is not None and last_found in cycle:
        start = int(np.flatnonzero(cycle == last_found)[0]) + 1
    else:
        start = int(np.argmin(np.hypot(*(at - agent).T)))
        start = int(np.flatnonzero(cycle == kept[start])[0])
    return np.roll(cycle, -start)


def plan_tour(
    env,
    root: tuple,
    order: np.ndarray,
    settings: TourSettings,
    draws: np.ndarray,
    work: np.ndarray,
    entry: int | None = None,
) -> TourPlan:
    """The best tour from the MDP state ``root`` (not changed) over the cyclic ``order``
    (`cyclic_order`), scored on the outcome sequences ``draws`` (``(samples, N + 1)``
    uniforms; module docstring: the direction, the targets kept, the dwells, the entry).
    ``entry``: the target the tour must begin with (kept, and the entry not searched), or
    ``None``: the planner's choice."""
    scratch = tuple(np.array(a, copy=True) for a in root)
    gone = np.zeros(env.means.shape[0], dtype=bool)

    def score(o: np.ndarray, settle: float, start: int = 0) -> tuple[float, int]:
        value, first = tour_score(
            env, root, scratch, o, start, settle, settings.min_find, draws, gone, work
        )
        return float(value), int(first)

    def entered(o: np.ndarray) -> np.ndarray:
        return o if entry is None else np.roll(o, -int(np.flatnonzero(o == entry)[0]))

    last = int(root[0][I_LAST])
    orders = [entered(order), entered(np.roll(order[::-1], -1 if last in order else 1))]
    scored = [score(o, settings.settle_variance) for o in orders]
    k = int(np.argmax([v for v, _ in scored]))
    order, (best, first) = orders[k], scored[k]
    gains = np.array(
        [
            -np.inf
            if order[i] == entry
            else score(np.delete(order, i), settings.settle_variance)[0] - best
            for i in range(order.size)
        ]
    )
    ranked = np.argsort(-gains, kind="stable")
    full = order
    for count in range(1, int((gains > 0).sum()) + 1):
        candidate = np.delete(full, ranked[:count])
        value, action = score(candidate, settings.settle_variance)
        if value > best:
            order, best, first = candidate, value, action
    settle = settings.settle_variance
    value, action = score(order, math.inf)
    if value > best:
        best, first, settle = value, action, math.inf
    start = 0
    for at in range(1, order.size if entry is None else 1):
        value, action = score(order, settle, at)
        if value > best:
            best, first, start = value, action, at
    return TourPlan(np.roll(order, -start), settle, first, best)


def predicted_positions(env, state: tuple) -> np.ndarray:
    """``(n, 2)`` the belief means' positions at the MDP ``state``'s step, m."""
    t = float(state[0][I_STEP]) * env.mission.time_step
    return np.array([mean_position_on(env.mission, m, t) for m in env.means])


# --- the tour as the search's base policy ---------------------------------------------------
class TourRollout(NamedTuple):
    """Rollouts that fly one tour (`plan_tour`'s, planned at the search's decision) to the end
    of the budget: the tour as the search's base policy and the value of its leaves
    (`tour_choice`). ``order`` empty: follow the target just found, or stop.

    Attributes:
        order: the tour's targets in their cyclic order, entered at position 0.
        settle: `TourPlan.settle`, (m/s)^2.
        min_find: `TourSettings.min_find`.
    """

    order: np.ndarray = np.zeros(0, dtype=np.int64)
    settle: float = 0.05
    min_find: float = 0.9


@numba.njit(cache=True)
def tour_position(env, state, order):
    """Where in ``order`` a state of the tour stands: after the target whose predicted mean
    the agent is at (every sub-task ends there), else at the start (the root of a search)."""
    si, sf = state[0], state[1]
    t = si[I_STEP]
    if t == 0:
        return 0
    elapsed = t * env.mission.time_step
    m = order.shape[0]
    for k in range(m):
        x, y = mean_position_on(env.mission, env.means[order[k]], elapsed)
        if x == sf[0] and y == sf[1]:
            return (k + 1) % m
    return 0


@numba.njit(cache=True)
def tour_choice(env, state, order, settle, min_find):
    """The tour's action in ``state`` (`fly_tour`'s rule, its position read off the state by
    `tour_position`): dwell, the next pursuit, else follow the target just found; ``-1``:
    nothing to do (or no budget left)."""
    if tour_dwells(env, state, settle):
        return env.means.shape[0]
    gone = np.zeros(env.means.shape[0], dtype=np.bool_)
    work = np.empty((1, state[2].shape[1], state[2].shape[1]))
    at = tour_position(env, state, order)
    pick = next_pursuit(env, state, order, at, min_find, gone, work)[0]
    if pick >= 0:
        return pick
    last = state[0][I_LAST]
    return last if last >= 0 and is_available(env, state, last) else -1


@numba.njit(cache=True)
def tour_rollout(policy, env, state, rng, candidates):
    """`TourRollout`'s decision (deterministic: the outcomes are the only draws)."""
    return tour_choice(env, state, policy.order, policy.settle, policy.min_find)


register_policy(TourRollout, tour_rollout)


# --- the planner ---------------------------------------------------------------------------
class TourPlanner:
    """Revisit-tour planner (name ``"tour"``); see the module docstring and `TourSettings`."""

    name = "tour"

    def __init__(self, settings: TourSettings | None = None) -> None:
        self.settings = settings or TourSettings()
        self.subtask_options = self.settings.subtask_options()

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        one_vehicle(self.name, mission)
        self._mission = mission
        self._record = mission.record
        self._follow_tables = follow_tables(self._record)
        self._rng = rng
        self._available = np.ones(mission.n_targets, dtype=bool)
        self._table = action_table(mission.n_targets, mission.time_step, self.subtask_options)
        self._work = new_work(state_size(mission.record))
        self._flight: SubtaskFlight | None = None
        self._log: list[Subtask] = []
        self._decisions: list[dict] = []
        self._next(observation, None)

    # --- planning -------------------------------------------------------------------------
    def plan(self, observation: Observation, last_found: int | None) -> tuple[int, dict]:
        """The first action (`hptrack.subtasks.ActionTable` index; ``-1``: none) of the best
        tour from ``observation``, and what was chosen (kept targets in order, with dwells)."""
        problem = PlanningProblem.from_observation(
            self._record,
            observation,
            available=self._available,
            last_found=last_found,
            follow=self._follow_tables,
        )
        env = problem.env(self.subtask_options)
        draws = self._rng.random((self.settings.samples, problem.n_steps + 1))
        kept = np.flatnonzero(self._available).astype(np.int64)
        order = cyclic_order(
            positions(observation.means),
            observation.agent_position,
            kept,
            last_found,
            self._mission.agent_speed,
        )
        plan = plan_tour(env, problem.root_state(), order, self.settings, draws, self._work)
        return plan.first, {
            "order": plan.order.tolist(),
            "dwells": math.isfinite(plan.settle),
            "expected_u": -plan.value,
        }

    # --- flying ---------------------------------------------------------------------------
    def _next(self, observation: Observation, last_found: int | None) -> None:
        """Plan and start the next sub-task (the best tour's first)."""
        if not self._available.any() and last_found is None:
            self._available[:] = True  # every target missed: they all return
        index = -1
        if observation.remaining_budget > 0 and self._available.any():
            began, cpu = time.perf_counter(), time.process_time()
            index, chosen = self.plan(observation, last_found)
            chosen.update(
                step=observation.step,
                elapsed_s=time.perf_counter() - began,
                cpu_s=time.process_time() - cpu,
            )
            self._decisions.append(chosen)
        if index < 0:
            index = last_found if last_found is not None else -1
        action = HOVER if index < 0 else self._table.action(index, last_found) or HOVER
        self._flight = SubtaskFlight(action, observation, self._mission)
        self._log.append(self._flight.record)

    def act(self, observation: Observation) -> np.ndarray:
        self._available |= observation.detected
        flight = self._flight
        assert flight is not None  # started by reset
        kind, target = flight.action.kind, flight.action.target
        if kind in ("pursue", "dwell") and flight.done(observation):
            found = kind == "dwell" or flight.found(observation)
            outcome = None if kind == "dwell" else ("found" if found else "missed")
            self._log[-1] = self._log[-1].ended(observation.step, outcome)
            if not found and self.settings.miss == "drop":
                self._available[target] = False
            self._next(observation, target if found else None)
        assert self._flight is not None
        return self._flight.waypoint(observation)

    def current_plan(self) -> CurrentPlan:
        """The sub-task being flown; nothing while hovering."""
        if self._flight is None or self._flight.action.kind == "hover":
            return CurrentPlan()
        return CurrentPlan(self._log[-1])

    def episode_info(self) -> dict:
        """The sub-tasks flown (`hptrack.subtasks.Subtask.to_json`), every decision's tour
        (its kept targets in order, whether it dwells, its expected ``U``, step, wall and CPU
        time)
        and the settings."""
        return {
            "settings": self.settings.as_json(),
            "subtasks": [entry.to_json() for entry in self._log],
            "tours": self._decisions,
        }
