"""The value of a UAV flying a path of "pursue target i" sub-tasks, from the paper's estimator
(Sec. IV-B, IV-C-2): the bids of a team allocation (`hptrack.planning.cbba`; ``docs/teams.md``).

A path is walked from the UAV's position at the root, every belief as it is now. For each target
of the path in turn, the walk asks the sub-task MDP's own kernels (`hptrack.planning.subtask_mdp`)
whether the pursuit can start before the budget ends (`subtask_mdp.is_available`: interceptable,
strictly before the budget) and what it gives (`subtask_mdp.expand_action`: the intercept of
`hptrack.models.mission`, the covariance predicted to the spiral's start and the estimator's
``p_find``, the find's ``n_i + round(E[T_find])`` and the miss's ``n_i + t_cutoff`` steps, all
truncated by the budget). The pursuit of target ``i`` is credited

    p_find (U_i(unseen) - U_i(found)),   U_i = log det Sigma^xy_i at the budget's end,

``unseen`` the root covariance predicted to the end, ``found`` one position update with ``R`` at
the find's step (the mission's sensor's update), then predicted to the end. The walk then
advances by the expected duration ``p_find find + (1 - p_find) miss`` (nearest whole step, at
least one) and moves the UAV to the target's predicted mean there (as the MDP's
`subtask_mdp.apply_outcome` does). A target that cannot be pursued from where and when the walk
reaches it is skipped and worth 0; once the budget is spent, every later target is. Each term is
at least 0 (an update never raises ``log det``), so a longer path is never worth less at its end.

What the value leaves out: the beliefs are the root's (a pursuit credits its own target only,
the MDP's ``passes="ignore"``), a miss changes nothing (no negative information), and a find
ends the target's tracking (no follow or dwell after it; the planner that flies the bundle
decides those).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba
import numpy as np

from hptrack.interface import MissionSpec
from hptrack.models.beliefs import logdet_xy
from hptrack.models.mission import (
    follow_tables,
    mean_position_on,
    position_covariance_on,
    predict_covariance_on,
)
from hptrack.models.sensor import sensor_update_covariance
from hptrack.planning.subtask_mdp import (
    I_STEP,
    PlanningProblem,
    SubtaskEnv,
    SubtaskOptions,
    expand_action,
    int_state,
    is_available,
    new_work,
)


@numba.njit(cache=True)
def walk_path(env, root_cov, position, path, work):
    """The value of flying ``path`` (``int64`` target indices, in order) from ``position``
    (m) at the root of ``env`` (`SubtaskEnv`), the beliefs' covariances ``root_cov``
    (module docstring); ``work`` is the MDP's scratch (`new_work`)."""
    mission = env.mission
    n = root_cov.shape[0]
    n_steps = env.n_steps
    si = int_state(0, np.ones(n, dtype=np.bool_), -1)
    sf = np.array([position[0], position[1]])
    state = (si, sf, root_cov, np.zeros(n, dtype=np.int64))
    found, unseen = work[1], work[2]
    total = 0.0
    for a in path:
        if not is_available(env, state, a):
            continue
        p_find, find_steps, miss_steps = expand_action(env, state, a, work)
        t = si[I_STEP]
        q = mission.process_noise[a]
        predict_covariance_on(mission, root_cov[a], q, t + find_steps, unseen)
        sensor_update_covariance(mission.sensor, unseen, found)
        sxx, sxy, syy = position_covariance_on(mission, found, q, float(n_steps - t - find_steps))
        u_found = logdet_xy(sxx, sxy, syy)
        sxx, sxy, syy = position_covariance_on(mission, root_cov[a], q, float(n_steps))
        total += p_find * (logdet_xy(sxx, sxy, syy) - u_found)
        expected = p_find * find_steps + (1.0 - p_find) * miss_steps
        end = t + max(1, int(math.floor(expected + 0.5)))
        x, y = mean_position_on(mission, env.means[a], end * mission.time_step)
        si[I_STEP] = end
        sf[0] = x
        sf[1] = y
    return total


class TeamPathValue:
    """``path_value(agent, path)`` of a team at one decision: the value (log m^4, module
    docstring) of UAV ``agent`` flying the targets ``path`` in that order, cached per
    ``(agent, path)``. Built by `team_path_value`."""

    def __init__(
        self, envs: list[SubtaskEnv], positions: np.ndarray, covariances: np.ndarray
    ) -> None:
        self._envs = envs
        self._positions = positions
        self._covariances = covariances
        self._work = [new_work(covariances.shape[1]) for _ in envs]
        self._cache: dict[tuple[int, tuple[int, ...]], float] = {}

    @property
    def n_agents(self) -> int:
        return len(self._envs)

    @property
    def n_targets(self) -> int:
        return self._covariances.shape[0]

    def __call__(self, agent: int, path: tuple[int, ...]) -> float:
        key = (agent, tuple(path))
        value = self._cache.get(key)
        if value is None:
            if not 0 <= agent < self.n_agents:
                raise ValueError(f"agent must be in 0..{self.n_agents - 1}, got {agent}")
            targets = np.array(key[1], dtype=np.int64)
            if np.any((targets < 0) | (targets >= self.n_targets)) or len(set(key[1])) != len(
                key[1]
            ):
                raise ValueError(f"path must be distinct targets in 0..{self.n_targets - 1}")
            value = float(
                walk_path(
                    self._envs[agent],
                    self._covariances,
                    self._positions[agent],
                    targets,
                    self._work[agent],
                )
            )
            self._cache[key] = value
        return value


def team_path_value(
    missions: Sequence[MissionSpec],
    agent_positions: np.ndarray,
    means: np.ndarray,
    covariances: np.ndarray,
    remaining_budget: float,
    estimator: str = "paper",
    coverage_limit: float = 0.0,
) -> TeamPathValue:
    """The `TeamPathValue` of a team at one decision.

    Args:
        missions: one `MissionSpec` per UAV (its speed, sensor, fence; the targets' noise and
            motion, the same targets for all).
        agent_positions: ``(m, 2)`` the UAVs' positions, m.
        means: ``(n, d)`` the belief means now, m, m/s.
        covariances: ``(n, d, d)`` the belief covariances now.
        remaining_budget: time left, s.
        estimator: the sub-task MDP's estimator (`hptrack.planning.subtask_estimators`),
            ``"paper"`` (Sec. IV-B) by default.
        coverage_limit: the longest spiral of a pursuit, s (`SubtaskOptions.coverage_limit`;
            0: the paper's ``t_cutoff`` alone).

    Raises:
        ValueError: shapes that do not match, a budget not positive, an unknown estimator.
    """
    positions = np.array(agent_positions, dtype=float)
    if positions.shape != (len(missions), 2) or not np.all(np.isfinite(positions)):
        raise ValueError(
            f"agent_positions must be ({len(missions)}, 2) finite numbers, got {positions.shape}"
        )
    options = SubtaskOptions(estimator=estimator, coverage_limit=coverage_limit)
    envs = []
    for spec, position in zip(missions, positions, strict=True):
        record = spec.record
        problem = PlanningProblem(
            record,
            position,
            means,
            covariances,
            remaining_budget,
            follow=follow_tables(record, 1),  # a walk never follows a target
        )
        envs.append(problem.env(options))
    return TeamPathValue(envs, positions, np.array(covariances, dtype=float))
