"""The ``clairvoyant`` reference: a planner that READS THE TRUE TARGET STATES.

It measures how far a planner is from perfect information, not a planner that can fly: only the
simulator knows the truth, and hands it only to a planner that declares it reads it
(`hptrack.interface.TruthReader`); the flight controller refuses it.

A *visit* flies straight at the point where the true target will be met (its true position and
velocity, the footprint's edge reached at ``v_a``), then stays on it, measured every step, for a
chosen time. As a visit ends (or at the start) the planner scores every plan of two visits
``(target, stay)`` then ``(other target, stay)``, stays from `STAYS`, by the decrease of
``U`` at the end of the budget that the two visits buy (each belief predicted to its arrival,
updated at every step of its stay, predicted to the end; Eq. (1) and the Kalman update) per second
the plan takes, and flies the first visit of the best plan. A plan of one visit is scored the same
way.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from hptrack.interface import CurrentPlan, InputError, MissionSpec, Observation, one_vehicle
from hptrack.models.beliefs import position_logdet
from hptrack.models.mission import STEP_TOLERANCE
from hptrack.models.state import positions, velocities
from hptrack.models.vehicle import reach_times
from hptrack.settings import NoSettings

STAYS = (0.0, 5.0, 10.0, 20.0, 40.0, 80.0, math.inf)
"""Stays on a target after meeting it, s (0: the one measurement as it is met; inf: to the end)."""
SETTLED_STEPS = 200
"""Measured steps after which a stay's covariance is taken as settled (the Riccati recursion
converges within it at the paper's ``q`` and ``R``); longer stays keep it."""


class ClairvoyantPlanner:
    """Perfect-knowledge reference (module docstring): reads the true target states."""

    name = "clairvoyant"
    reads_truth: ClassVar[str] = "the true target states, every step"

    def __init__(self, settings: NoSettings | None = None) -> None:
        self.settings = settings or NoSettings()
        self.claimed: np.ndarray | None = None
        """``(n,)`` bool: targets another UAV of a team has claimed, never planned while they
        are (set by a team planner, `hptrack.teams`); ``None``: none."""

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        one_vehicle(self.name, mission)
        self._mission = mission
        self._truth: np.ndarray | None = None
        self._target: int | None = None
        self._stay = 0.0
        self._leave_at: float | None = None  # s; set when the target is met
        self._visits: list[dict] = []

    def see_truth(self, states: np.ndarray) -> None:
        """The true target states ``(n, 4)`` of this step (m, m/s), from the simulator."""
        self._truth = np.array(states, dtype=float)

    # --- the look-ahead --------------------------------------------------------------------
    def _final_logdets(
        self, covs: np.ndarray, q: np.ndarray, arrive: np.ndarray, stay: np.ndarray, end: float
    ) -> np.ndarray:
        """``log det Sigma^xy`` at the budget's end ``end`` (s from now) of beliefs ``covs``
        ``(k, d, d)`` met after ``arrive`` s and measured at every step of ``stay`` s."""
        motion, sensor, tau = self._mission.motion, self._mission.sensor, self._mission.time_step
        zeros = np.zeros(covs.shape[:2])
        measured = np.minimum(np.floor(stay / tau + STEP_TOLERANCE).astype(int) + 1, SETTLED_STEPS)
        covs = motion.predict(zeros, covs, q, arrive)[1]
        for step in range(int(measured.max(initial=0))):
            on = measured > step
            if step:
                covs[on] = motion.predict(zeros[on], covs[on], q[on], tau)[1]
            covs[on] = sensor.update(zeros[on], covs[on], zeros[on, :2])[1]
        return position_logdet(motion.predict(zeros, covs, q, end - arrive - stay)[1])

    def _plan(self, obs: Observation, truth: np.ndarray, leaving: int | None) -> tuple[int, float]:
        """The first visit ``(target, stay s)`` of the best plan of two visits, to another
        target than the one ``leaving`` (the stay chose how long to spend on it; at most the
        budget left, so always finite)."""
        m = self._mission
        n, left = m.n_targets, obs.remaining_budget
        q, covs = m.process_noise, obs.covariances
        base = position_logdet(m.motion.predict(obs.means, covs, q, left)[1])
        stays = np.array(STAYS)
        # first visits: every target x every stay
        t1, s1 = np.repeat(np.arange(n), stays.size), np.tile(stays, n)
        vehicle, true_positions, true_velocities = (
            m.record.vehicle,
            positions(truth),
            velocities(truth),
        )
        a1 = reach_times(
            vehicle, obs.agent_position, true_positions, true_velocities, m.sensor_radius
        )[t1]
        free = np.ones(n, dtype=bool) if self.claimed is None else ~self.claimed
        ok = (a1 <= left) & ((t1 != leaving) | (n == 1)) & free[t1]
        t1, s1, a1 = t1[ok], s1[ok], a1[ok]
        if t1.size == 0:  # no target can be met in time: to the nearest, staying to the end
            return int(np.argmin(np.hypot(*(true_positions - obs.agent_position).T))), left
        s1 = np.minimum(s1, left - a1)
        gain1 = base[t1] - self._final_logdets(covs[t1], q[t1], a1, s1, left)
        free1 = a1 + s1  # when the first visit ends, s from now
        # where each first visit leaves the agent, and every target's truth then
        leave = true_positions[t1] + true_velocities[t1] * free1[:, None]
        k1 = np.repeat(np.arange(t1.size), n * stays.size)
        t2 = np.tile(np.repeat(np.arange(n), stays.size), t1.size)
        s2 = np.tile(stays, n * t1.size)
        moved = truth[t2].copy()
        moved_positions, moved_velocities = positions(moved), velocities(moved)
        moved_positions += moved_velocities * free1[k1, None]
        a2 = free1[k1] + reach_times(
            vehicle, leave[k1], moved_positions, moved_velocities, m.sensor_radius
        )
        ok = (t2 != t1[k1]) & (a2 <= left) & free[t2]
        k1, t2, s2, a2 = k1[ok], t2[ok], s2[ok], a2[ok]
        s2 = np.minimum(s2, left - a2)
        gain2 = base[t2] - self._final_logdets(covs[t2], q[t2], a2, s2, left)
        # a two-visit plan that takes no time (both targets in the footprint already, no stay)
        # buys its gain at once: its rate is infinite and it ranks first
        with np.errstate(divide="ignore"):
            rate = np.concatenate(
                [gain1 / np.maximum(free1, m.time_step), (gain1[k1] + gain2) / (a2 + s2)]
            )
        best = int(np.argmax(rate))
        first = best if best < t1.size else int(k1[best - t1.size])
        return int(t1[first]), float(s1[first])

    # --- flying ----------------------------------------------------------------------------
    def act(self, observation: Observation) -> np.ndarray:
        if self._truth is None:
            raise InputError(
                "planner 'clairvoyant' reads the true target states, which only the simulator "
                "has: use it in hptrack simulate or benchmark"
            )
        obs, truth, m = observation, self._truth, self._mission
        self._truth = None  # read once: the next step brings its own
        if self._target is not None and self._leave_at is None and obs.detected[self._target]:
            self._leave_at = obs.time + self._stay
        if self._target is None or (self._leave_at is not None and obs.time >= self._leave_at):
            self._target, self._stay = self._plan(obs, truth, self._target)
            self._leave_at = obs.time + self._stay if obs.detected[self._target] else None
            self._visits.append(
                {"step": obs.step, "target_index": self._target, "stay_s": self._stay}
            )
        position, velocity = positions(truth[self._target]), velocities(truth[self._target])
        if self._leave_at is not None:  # staying: where the target will be after this step
            return position + velocity * m.time_step
        meet = reach_times(
            m.record.vehicle, obs.agent_position, position[None], velocity[None], 0.0
        )[0]
        return position + velocity * (meet if math.isfinite(meet) else 0.0)

    @property
    def target(self) -> int | None:
        """The target visited now (``None``: none yet)."""
        return self._target

    def current_plan(self) -> CurrentPlan:
        """No sub-tasks of the paper's kind: nothing to show."""
        return CurrentPlan()

    def episode_info(self) -> dict:
        return {
            "settings": self.settings.as_json(),
            "reads_truth": self.reads_truth,
            "visits": self._visits,
        }
