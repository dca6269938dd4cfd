"""One coverage sub-task (paper Sec. IV-C, "Markov Decision Process"): intercept, then spiral.

When the agent pursues target ``a`` it flies straight at full speed to intercept the belief mean
(`hptrack.coverage.intercept`), then flies the shifting spiral of Sec. IV-A
(`hptrack.coverage.spiral`) until the target is detected or ``t_cutoff`` of Sec. IV-B is
reached, or the budget ends. Its outcome is estimated by the paper's estimator
(`CoverageSubtask.estimate`) and by the sharp one (`CoverageSubtask.sharp_estimate`,
`hptrack.coverage.sharp_estimator`). `CoverageSubtask` is the plan the hierarchical
planner executes inside its ``Planner.act`` loop (and the ``coverage`` planner of
`hptrack.baselines.coverage` flies on its own).

Step bookkeeping: a sub-task built at step ``s`` (the observation it was planned from) has its
planned positions ``path[j]`` for steps ``s + j``: ``path[0]`` is the agent's position, the
intercept flight takes ``j = 0 .. n`` and spiral step ``m`` is ``path[n + m]``. It ends at step
``s + n + t_cutoff`` (or at the budget's end).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import cached_property

import numpy as np

from hptrack.coverage.estimator import CoverageEstimate, estimate_coverage
from hptrack.coverage.intercept import (
    Intercept,
    intercept_path,
    intercept_waypoint,
    plan_intercept,
)
from hptrack.coverage.sharp_estimator import SharpEstimate, estimate_sharp
from hptrack.coverage.spiral import ShiftingSpiral
from hptrack.interface import MissionSpec, Observation
from hptrack.models.mission import approach_step_to, visible_find
from hptrack.models.state import velocities
from hptrack.models.vehicle import flies_straight, flown_path
from hptrack.subtasks import Subtask


class CoverageSubtask:
    """Intercept and spiral coverage of one target's belief, with its planned outcome.

    Args:
        agent_position: ``(2,)`` agent position when the sub-task starts, m.
        mean: ``(d,)`` pursued target's belief mean now (m, m/s, m/s^2; ``d`` the motion's
            state size).
        covariance: ``(d, d)`` its belief covariance now.
        q: its process noise intensity, m^2/s^3.
        mission: the mission facts (speed, footprint, time step, ``Q`` form).
        remaining_budget: budget left now, s; ``None`` for a coverage that runs to
            ``t_cutoff`` whatever the budget (the estimator-accuracy experiment).
        target_index: the target's index in observations (to see its detections).
        start_step: the step of the observation the sub-task is planned from.
        coverage_steps: the longest spiral, in steps: the coverage ends at ``t_cutoff`` or
            after this many steps, whichever comes first, its estimate truncated there as at
            the budget's end; ``None`` (the paper): ``t_cutoff`` alone.

    Raises:
        ValueError: bad belief or inputs, or a target not slower than the agent.
    """

    def __init__(
        self,
        agent_position: np.ndarray,
        mean: np.ndarray,
        covariance: np.ndarray,
        q: float,
        mission: MissionSpec,
        remaining_budget: float | None,
        target_index: int = 0,
        start_step: int = 0,
        coverage_steps: int | None = None,
    ) -> None:
        self.mission = mission
        self.target_index = int(target_index)
        self.start_step = int(start_step)
        self.q = float(q)
        if not (0 <= self.target_index < mission.n_targets):
            raise ValueError(
                f"target_index {target_index} out of range for {mission.n_targets} targets"
            )
        mean = np.asarray(mean, dtype=float)
        d = mission.motion.state_size
        if mean.shape != (d,) or not np.all(np.isfinite(mean)):
            raise ValueError(f"mean must be {d} finite numbers (a state), got {mean!r}")
        if remaining_budget is not None and math.isnan(remaining_budget):
            raise ValueError("remaining_budget is NaN")
        if coverage_steps is not None and coverage_steps < 1:
            raise ValueError(f"coverage_steps must be at least 1, got {coverage_steps}")
        m = mission
        self.mean = mean.copy()
        self.remaining_budget = remaining_budget
        self.agent_position = np.asarray(agent_position, dtype=float).copy()
        self.intercept: Intercept = plan_intercept(m.record, self.agent_position, mean)
        n = self.intercept.steps
        means, covs = m.motion.predict(
            mean[None, :], np.asarray(covariance, dtype=float)[None], self.q, n * m.time_step
        )
        self.start_covariance = covs[0]
        self.coverage_time = _coverage_time(
            None if remaining_budget is None else remaining_budget - n * m.time_step,
            None if coverage_steps is None else coverage_steps * m.time_step,
        )
        self.estimate: CoverageEstimate = estimate_coverage(
            self.start_covariance, self.q, m, self.coverage_time
        )
        self.straight = flies_straight(m.record.vehicle)
        if not self.straight:
            est = self.estimate
            seen = visible_find(
                m.record, mean, n * m.time_step, covs[0], self.q, est.p_find, est.cutoff_steps
            )
            self.estimate = replace(self.estimate, p_find=float(seen))
        self.spiral = ShiftingSpiral(
            self.intercept.start,
            velocities(mean) if m.motion.straight else velocities(means[0]),
            self.start_covariance[:2, :2],
            m.agent_speed,
            m.time_step,
            m.sensor_diameter,
            None if m.motion.straight else self._mean_offsets,
        )
        self.total_steps = n + self.estimate.cutoff_steps
        if remaining_budget is not None:
            budget_steps = math.floor(remaining_budget / m.time_step + 1e-9)
            self.total_steps = min(self.total_steps, max(budget_steps, 0))

    def _mean_offsets(self, spiral_steps: np.ndarray) -> np.ndarray:
        """The predicted mean's displacement from the spiral's centre at ``spiral_steps``
        ``(m,)`` steps into the coverage, ``(m, 2)``, m (a mean that does not move straight)."""
        tau, n = self.mission.time_step, self.intercept.steps
        elapsed = (n + np.asarray(spiral_steps, dtype=float)) * tau
        path = self.mission.motion.mean_positions(self.mean, np.append(n * tau, elapsed))
        return path[1:] - path[0]

    @classmethod
    def from_observation(
        cls,
        observation: Observation,
        target_index: int,
        mission: MissionSpec,
        coverage_steps: int | None = None,
    ) -> CoverageSubtask:
        """Plan a sub-task on target ``target_index`` from the current observation (with the
        longest spiral ``coverage_steps``, steps; ``None``: the paper's ``t_cutoff``)."""
        i = int(target_index)
        return cls(
            observation.agent_position,
            observation.means[i],
            observation.covariances[i],
            float(mission.process_noise[i]),
            mission,
            observation.remaining_budget,
            i,
            observation.step,
            coverage_steps,
        )

    # --- the planned estimate ---------------------------------------------------------------
    @cached_property
    def sharp_estimate(self) -> SharpEstimate:
        """The sharp estimator's outcome of this sub-task (flight detections included, expected
        duration from its start; `hptrack.coverage.sharp_estimator`)."""
        m, n, mean = self.mission, self.intercept.steps, self.mean
        approach = approach_step_to(
            m.record, self.agent_position[0], self.agent_position[1], mean, n
        )
        sharp = estimate_sharp(self.start_covariance, self.q, m, n, approach, self.coverage_time)
        if self.straight:
            return sharp
        cutoff = self.estimate.cutoff_steps
        seen = visible_find(
            m.record, mean, n * m.time_step, self.start_covariance, self.q, sharp.p_find, cutoff
        )
        return replace(sharp, p_find=float(seen))

    @property
    def intercept_time(self) -> float:
        """Intercept flight in whole steps, s."""
        return self.intercept.duration

    @property
    def cutoff_time(self) -> float:
        """``t_cutoff``, s from the start of the coverage."""
        return self.estimate.cutoff_time

    @property
    def p_find(self) -> float:
        """Estimated probability of finding the target during the spiral, ``p_max``."""
        return self.estimate.p_find

    @property
    def expected_time(self) -> float:
        """``E[T_find]``, s from the start of the coverage."""
        return self.estimate.expected_time

    @property
    def end_step(self) -> int:
        """The step at which the sub-task ends if the target is not detected."""
        return self.start_step + self.total_steps

    def record(self) -> Subtask:
        """The plan as a pursuit's sub-task record (times in s)."""
        return Subtask(
            "pursue",
            self.target_index,
            self.start_step,
            intercept_time=self.intercept_time,
            t_cutoff=self.cutoff_time,
            p_find=self.p_find,
            expected_time=self.expected_time,
            budget_limited=self.estimate.budget_limited,
        )

    # --- execution --------------------------------------------------------------------------
    def waypoint(self, j: int) -> np.ndarray:
        """Planned position ``(2,)`` at ``j`` steps after the start, m (the spiral never ends)."""
        if j < 0:
            raise ValueError(f"step offset must be non-negative, got {j}")
        n = self.intercept.steps
        if j <= n and not self.straight:  # a fenced vehicle finds its own way to the meeting
            return self.intercept.start.copy()
        if j <= n:
            return intercept_waypoint(
                self.agent_position, self.intercept, self.mission.step_length, j
            )
        return self.spiral.position(j - n)

    def planned_positions(self, n_steps: int | None = None) -> np.ndarray:
        """Planned positions ``(n_steps, 2)`` from the start; by default up to ``t_cutoff`` or
        the budget's end, whichever comes first (``total_steps + 1`` positions), m; a fenced
        vehicle's are where it flies when sent to the waypoints (`flown_path`)."""
        count = self.total_steps + 1 if n_steps is None else int(n_steps)
        n = self.intercept.steps
        head = intercept_path(
            self.agent_position,
            self.intercept,
            self.mission.step_length,
            np.arange(min(count, n + 1)),
        )
        planned = (
            head if count <= n + 1 else np.concatenate([head, self.spiral.positions(count - n)[1:]])
        )
        if self.straight:
            return planned
        sent = np.array([self.waypoint(j) for j in range(count)])
        flown = np.empty_like(sent)
        flown_path(self.mission.record.vehicle, self.agent_position, sent, flown)
        return flown

    def next_waypoint(self, observation: Observation) -> np.ndarray:
        """Where to fly for the step after ``observation``, m."""
        return self.waypoint(observation.step - self.start_step + 1)

    def found(self, observation: Observation) -> bool:
        """Whether the pursued target is measured at this observation."""
        return bool(observation.detected[self.target_index])

    def done(self, observation: Observation) -> bool:
        """The target is detected, ``t_cutoff`` is reached, or the budget is spent."""
        return (
            self.found(observation)
            or observation.step >= self.end_step
            or observation.remaining_budget <= 0.0
        )


def _coverage_time(budget_left: float | None, limit: float | None) -> float | None:
    """The time a coverage may last, s: the budget left when it starts, or the coverage
    limit when that is shorter (``None``: neither)."""
    if limit is None:
        return budget_left
    return limit if budget_left is None else min(budget_left, limit)
