"""Plan the next decision in one call, from a scenario or from current beliefs.

`plan` hands a planner the mission and one observation, as the simulator does at the start
of an episode, and returns what it decided: the waypoint to fly towards and, for the paper's
hierarchical planner (Sec. IV-C), the target it pursues and the coverage sub-task it planned.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hptrack.interface import MissionSpec, Observation, Planner
from hptrack.registry import make_planner
from hptrack.scenario.model import Scenario
from hptrack.sim.record import subtasks_with_ids


@dataclass(frozen=True)
class Decision:
    """A planner's decision at one observation.

    Attributes:
        waypoint: ``(2,)`` position to fly towards now, m (a team planner's: ``(m, 2)``, one
            row per UAV, `hptrack.teams`).
        target: id of the target the planner pursues (the hierarchical planner's sub-task), or
            ``None`` for planners without sub-tasks (or one that follows or hovers, or a
            team's: each UAV's plan is in ``info["members"]``).
        subtask: the planned sub-task (`hptrack.subtasks.Subtask.to_json`, targets named by
            id: ``kind``, ``target``, intercept time, ``t_cutoff``, ``p_find``, expected time
            in s, the actions planned after a find and a miss) or ``None``.
        info: the planner's ``episode_info()``: its searches, settings and plans so far.
    """

    waypoint: np.ndarray
    target: str | None = None
    subtask: dict[str, Any] | None = None
    info: dict[str, Any] = field(default_factory=dict)


def _first_subtask(info: dict[str, Any], mission: MissionSpec) -> dict[str, Any] | None:
    """The planner's first sub-task, naming targets by id (as the episode JSON does)."""
    subtasks = info.get("subtasks") or []
    return subtasks_with_ids(subtasks[:1], mission.target_ids)[0] if subtasks else None


def plan(
    source: Scenario | MissionSpec,
    planner: str | Planner = "mcts",
    observation: Observation | None = None,
    *,
    seed: int = 0,
    **options: Any,
) -> Decision:
    """The next decision of ``planner`` for a scenario or for current beliefs.

    Args:
        source: a `Scenario` (planned from its priors at time 0 unless
            ``observation`` is given) or a `MissionSpec` with the
            current ``observation`` (time, remaining budget, agent position, beliefs).
        planner: a registered planner name (``hptrack planners``) or a planner object.
        observation: the planner's current view; default ``source.initial_observation()``.
        seed: seeds the planner's random generator (the tree search's rollouts).
        **options: the planner's options when ``planner`` is a name, e.g. ``iterations=20_000``
            or ``preset="paper"``; validated, a bad one raises
            `InputError`.

    Example:
        >>> import hptrack
        >>> scenario = hptrack.random_scenario(n_targets=3, seed=0)
        >>> decision = hptrack.plan(scenario, "greedy")
        >>> decision.waypoint.shape
        (2,)
    """
    if isinstance(source, Scenario):
        mission = source.mission_spec()
        if observation is None:
            observation = source.initial_observation()
    else:
        mission = source
        if observation is None:
            raise TypeError("plan(mission, ...) needs the current observation")
    if isinstance(planner, str):
        planner = make_planner(planner, options)
    elif options:
        raise TypeError("options are for a planner given by name; configure the object instead")
    planner.reset(mission, observation, np.random.default_rng(seed))
    waypoint = np.array(planner.act(observation), dtype=float)
    info = dict(planner.episode_info())
    subtask = _first_subtask(info, mission)
    target = subtask["target"] if subtask is not None and subtask["kind"] == "pursue" else None
    return Decision(waypoint, target, subtask, info)
