"""The paper's hierarchical planner in the simulator (Fig. 2; Sec. IV-C-4 re-planning).

1. At the start, the tree search (`hptrack.planning.search.search`) picks the first target.
2. The agent executes that sub-task (`CoverageSubtask`:
   intercept, then the shifting spiral, until the target is detected or ``t_cutoff``).
3. As the sub-task starts, the search re-plans with the current action fixed and returns a
   conditional plan: the next target after a *find* and after a *miss* (Algorithm 1 lines 9-12).
   In the paper this runs while the sub-task is flown; in simulation it runs at the sub-task's
   start, with the planning effort given per decision.
4. When the sub-task ends, the outcome that happened picks the next target from the plan. A
   missed target leaves the action list (Sec. IV-C-2); choosing the target just found again means
   following it to the end of the budget. With the ``dwell`` option (beyond the paper) the plan
   may also follow it for a dwell's length only (action index ``n + j`` for the ``j``-th
   length, also in the log's plans), re-planning with the dwell fixed as it starts. With
   ``miss="keep"`` a missed target stays in the action list.

Choices the paper leaves open (``docs/model.md``): a missed target that the agent measures
by chance later returns to the action list; a planned next action that the remaining budget can
no longer carry out triggers a fresh plan from the current state; with no action left the agent
follows the last found target, or hovers.
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from hptrack.coverage.subtask import CoverageSubtask
from hptrack.interface import CurrentPlan, MissionSpec, Observation, Subtask
from hptrack.models.mission import (
    follow_tables,
    intercept_steps_to,
    reachable_before_budget,
    steps_left,
)
from hptrack.planning.backups import backup_of
from hptrack.planning.rollout import UniformRandom
from hptrack.planning.search import DEFAULT_EXPLORATION, SearchOptions, SearchResult
from hptrack.planning.subtask_mdp import (
    FIND,
    MISS,
    PlanningProblem,
    SubtaskOptions,
    dwell_action,
    stay_steps,
)
from hptrack.planning.subtask_rollout import (
    MostUncertain,
    Nearest,
    Tour,
    UniformNoDwell,
    UniformNoFollow,
)
from hptrack.planning.subtask_search import search, warm_up
from hptrack.settings import Iterations, PlannerSettings, TimeLimit

DEFAULT_ITERATIONS = 100_000
"""Simulations per tree search when neither ``iterations`` nor ``time_limit`` is given."""


PRESETS: dict[str, dict[str, Any]] = {
    "paper": {
        "backup": "sampled",
        "max_weight": 1.0,
        "root_split": "even",
        "common_rollouts": False,
        "rollout": "uniform",
        "estimator": "paper",
        "dwell": 0.0,
        "miss": "drop",
        "passes": "ignore",
    },
    "improved": {
        "backup": "max",
        "max_weight": 1.0,
        "root_split": "even",
        "common_rollouts": False,
        "rollout": "uniform",
        "estimator": "paper",
        "dwell": 0.0,
        "miss": "drop",
        "passes": "ignore",
    },
}
"""The search options each preset stands for: the paper's algorithm exactly as written, and the
improvements measured in ``docs/results/search-options.md``."""

DEFAULT_PRESET = "improved"


DwellLength = Annotated[float, Field(ge=0.0, le=1e6)]
"""A dwell action's length, s."""


ROLLOUT_POLICIES: dict[str, type] = {
    "uniform": UniformRandom,
    "uniform_no_follow": UniformNoFollow,
    "uniform_no_dwell": UniformNoDwell,
    "nearest": Nearest,
    "most_uncertain": MostUncertain,
    "tour": Tour,
}
"""The rollout policy classes by their settings' names (`MctsSettings.rollout`)."""


class MctsSettings(PlannerSettings):
    """Options of the hierarchical planner (``mcts``).

    Attributes:
        iterations: simulations per tree search (reproducible on any machine); default
            100,000 when no time limit is given.
        time_limit: wall time per tree search, s (the paper uses 30 s). With both, whichever
            comes first.
        exploration: UCB1 constant ``c`` on values normalised to the observed return range.
        preset: ``"paper"`` (the paper's search, Algorithm 1) or ``"improved"``; it sets the
            options below that are not given (`PRESETS`).
        backup: ``"sampled"`` (the paper's running mean), ``"expected"``, ``"max"`` or
            ``"robust"`` (`hptrack.planning.tree`).
        max_weight: with the max backup, the weight of a state's best action in its value;
            the rest is the mean return through the state (1: the pure max).
        root_split: re-planning: the current action's outcomes share the root's simulations
            ``"even"``ly (the paper's) or ``"weighted"`` by their probability
            (`hptrack.planning.search.search`).
        common_rollouts: the rollouts that value one state's actions and outcomes share their
            random draws (common random numbers) instead of all drawing from one stream.
        rollout: ``"uniform"`` (the paper's random policy), ``"uniform_no_follow"`` (the same
            without following the target just found), ``"uniform_no_dwell"`` (the same
            without the dwell actions), ``"nearest"``, ``"most_uncertain"`` or ``"tour"``
            (`hptrack.planning.subtask_rollout`).
        rollout_epsilon: probability of a random action in a ``nearest``,
            ``most_uncertain`` or ``tour`` rollout.
        estimator: the sub-task outcome estimator of the search's expansions, ``"paper"``
            (Sec. IV-B) or ``"sharp"`` (`hptrack.coverage.sharp_estimator`).
        dwell: length of an extra action beyond the paper, s: follow the target just found
            for this long, then choose again (`hptrack.planning.subtask_mdp`); a list of
            lengths gives one such action each, the search choosing; 0 (the paper): none.
        miss: ``"drop"`` (the paper): a missed target leaves the action list until it is
            measured by chance; ``"keep"``: it stays, and the search may pursue it again.
        passes: ``"ignore"`` (the paper): the MDP credits a sub-task with its own target
            only; ``"credit"``: also with the other targets its flight passes over
            (`hptrack.planning.subtask_mdp`).
        threads: independent trees searched in parallel and merged (root parallelism), each
            with the effort above; 1 (the paper's single tree) unless the machine has spare
            cores.
    """

    iterations: Iterations | None = None
    time_limit: TimeLimit | None = None
    exploration: Annotated[float, Field(gt=0.0)] = DEFAULT_EXPLORATION
    preset: Literal["paper", "improved"] = DEFAULT_PRESET
    backup: Literal["sampled", "expected", "max", "robust"] | None = None
    max_weight: Annotated[float | None, Field(ge=0.0, le=1.0)] = None
    root_split: Literal["even", "weighted"] | None = None
    common_rollouts: bool | None = None
    rollout: (
        Literal[
            "uniform", "uniform_no_follow", "uniform_no_dwell", "nearest", "most_uncertain", "tour"
        ]
        | None
    ) = None
    rollout_epsilon: Annotated[float, Field(ge=0.0, le=1.0)] = 0.1
    estimator: Literal["paper", "sharp"] | None = None
    dwell: DwellLength | list[DwellLength] | None = None
    miss: Literal["drop", "keep"] | None = None
    passes: Literal["ignore", "credit"] | None = None
    threads: Annotated[int, Field(ge=1, le=64)] = 1

    effort_fields = {"iterations": "iterations", "time_limit": "time_limit"}

    @model_validator(mode="before")
    @classmethod
    def _defaults(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        if data.get("iterations") is None and data.get("time_limit") is None:
            data = {**data, "iterations": DEFAULT_ITERATIONS}
        preset = PRESETS.get(data.get("preset", DEFAULT_PRESET), {})
        return {**data, **{k: v for k, v in preset.items() if data.get(k) is None}}

    @field_validator("dwell", mode="before")
    @classmethod
    def _dwell_lengths(cls, value: Any) -> Any:
        """Several lengths (a list, or comma-separated text from ``-o dwell=5,10,20``): each a
        positive number of seconds."""
        if isinstance(value, str) and "," in value:
            value = value.split(",")
        if not isinstance(value, list | tuple):
            return value
        try:
            lengths = [float(v) for v in value]
        except (TypeError, ValueError):
            lengths = []
        if not lengths or not all(0.0 < d <= 1e6 for d in lengths):
            raise ValueError("must be one length or several, each in (0, 1e6] s")
        return lengths[0] if len(lengths) == 1 else lengths  # one length: one identity

    @model_validator(mode="after")
    def _max_weight_needs_the_max_backup(self) -> MctsSettings:
        if self.max_weight != 1.0 and self.backup != "max":
            raise ValueError(
                f"option max_weight={self.max_weight:g} applies only to "
                f"backup=max, got backup={self.backup}"
            )
        return self

    @classmethod
    def from_canonical(cls, text: str) -> MctsSettings:
        """The settings of a stored identity, under the first preset that stands for them."""
        values = json.loads(text)
        preset = next(
            (
                name
                for name, options in PRESETS.items()
                if all(values[k] == v for k, v in options.items())
            ),
            DEFAULT_PRESET,
        )
        return cls.model_validate({**values, "preset": preset})

    def canonical(self) -> str:
        """The identity of the results: every resolved option, without ``preset`` (which only
        stands for some of them)."""
        values = self.as_json()
        values.pop("preset")
        return json.dumps(values, sort_keys=True, separators=(",", ":"))

    def rollout_policy(self) -> tuple:
        """The rollout policy instance the search takes (`ROLLOUT_POLICIES`; a policy with an
        ``epsilon`` takes ``rollout_epsilon``)."""
        policy = ROLLOUT_POLICIES[self.rollout]
        return policy(self.rollout_epsilon) if "epsilon" in policy._fields else policy()

    def search_options(self) -> SearchOptions:
        """The search's options record: each of its fields is the option of the same name,
        the backup and the rollout policy as the instances the kernels take."""
        values = {name: getattr(self, name) for name in SearchOptions._fields}
        values["backup"] = backup_of(self.backup, self.max_weight)
        values["rollout"] = self.rollout_policy()
        return SearchOptions(**values)

    def subtask_options(self) -> SubtaskOptions:
        """The sub-task MDP's options record, field by field the options of the same name."""
        values = {name: getattr(self, name) for name in SubtaskOptions._fields}
        if isinstance(values["dwell"], list):
            values["dwell"] = tuple(values["dwell"])
        return SubtaskOptions(**values)


class HierarchicalPlanner:
    """Monte Carlo tree search over coverage sub-tasks (name ``"mcts"``); see the module
    docstring and `MctsSettings`."""

    name = "mcts"

    def __init__(self, settings: MctsSettings | None = None) -> None:
        self.settings = settings or MctsSettings()
        self.iterations = self.settings.iterations
        self.time_limit = self.settings.time_limit
        self.options = self.settings.search_options()
        self.subtask_options = self.settings.subtask_options()

    # --- planning -------------------------------------------------------------------------
    def _search(
        self,
        observation: Observation,
        current_action: int | None = None,
        last_found: int | None = None,
    ) -> SearchResult:
        problem = PlanningProblem.from_observation(
            self._record,
            observation,
            available=self._available,
            last_found=last_found,
            current_action=current_action,
            follow=self._follow_tables,
        )
        result = search(
            problem,
            self.options,
            self.subtask_options,
            iterations=self.iterations,
            time_limit=self.time_limit,
            seed=self._rng,
            threads=self.settings.threads,
        )
        self._searches.append(
            {
                "step": observation.step,
                "simulations": result.simulations,
                "elapsed_s": result.elapsed,
                "stopped_by": result.stopped_by,
            }
        )
        return result

    def _feasible(self, observation: Observation, target: int) -> bool:
        """In the action list and interceptable before the budget ends (as in the MDP)."""
        if not self._available[target]:
            return False
        m, agent, mission = observation.means[target], observation.agent_position, self._record
        steps = intercept_steps_to(mission, agent[0], agent[1], m)
        left = steps_left(mission.time_step, observation.remaining_budget)
        return reachable_before_budget(steps, left)

    def _dwell_length(self, action: int) -> int:
        """Steps of dwell action ``action``."""
        return self._stay_steps[action - dwell_action(self._mission.n_targets)]

    def _dwell_feasible(
        self, observation: Observation, last_found: int | None, action: int
    ) -> bool:
        """A target was just found and the dwell ends before the budget (as in the MDP)."""
        left = steps_left(self._record.time_step, observation.remaining_budget)
        return last_found is not None and self._dwell_length(action) < left

    def _start_dwell(self, observation: Observation, target: int, action: int) -> None:
        """Follow ``target`` for dwell ``action``'s length and re-plan with it fixed."""
        self._follow = target
        self._subtask = None
        length = self._dwell_length(action)
        self._dwell_end = observation.step + length
        plan = self._search(observation, current_action=action, last_found=target)
        self._plan = (plan.best_after(FIND), None)
        self._log.append(
            {
                "dwell": target,
                "start_step": observation.step,
                "dwell_steps": length,
                "plan_after_dwell": self._plan[0],
            }
        )

    def _start(self, observation: Observation, target: int) -> None:
        """Begin a sub-task on ``target`` and re-plan with it fixed (conditional plan)."""
        self._subtask = CoverageSubtask.from_observation(observation, target, self._mission)
        plan = self._search(observation, current_action=target)
        self._plan = (plan.best_after(FIND), plan.best_after(MISS))
        self._log.append(
            {
                **self._subtask.summary(),
                "plan_after_find": self._plan[0],
                "plan_after_miss": self._plan[1],
            }
        )

    def _next(self, observation: Observation, planned: int | None, last_found: int | None) -> None:
        """Carry on after a sub-task: follow, dwell, start the planned target, or plan
        afresh."""
        dwell = dwell_action(self._mission.n_targets)
        if planned is None:
            feasible = False
        elif planned >= dwell:
            feasible = self._dwell_feasible(observation, last_found, planned)
        else:
            feasible = planned == last_found or self._feasible(observation, planned)
        if not feasible:
            if self._available.any() and observation.remaining_budget > 0:
                planned = self._search(observation, last_found=last_found).best_action
            else:
                planned = None
        if planned is None or (planned == last_found):
            self._follow = last_found
            self._subtask = None
            self._log.append({"follow": last_found, "start_step": observation.step})
            return
        if planned >= dwell:
            self._start_dwell(observation, last_found, planned)
            return
        self._start(observation, planned)

    # --- Planner protocol ----------------------------------------------------------------
    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        if self.time_limit is not None:
            warm_up(self.options, self.subtask_options)
        self._mission = mission
        self._record = mission.record
        self._follow_tables = follow_tables(self._record)
        self._rng = rng
        self._available = np.ones(mission.n_targets, dtype=bool)
        self._subtask: CoverageSubtask | None = None
        self._plan: tuple[int | None, int | None] = (None, None)
        self._follow: int | None = None
        self._dwell_end: int | None = None
        self._stay_steps = stay_steps(mission.time_step, self.settings.dwell)
        self._log: list[dict] = []
        self._searches: list[dict] = []
        self._next(observation, None, None)

    def act(self, observation: Observation) -> np.ndarray:
        self._available |= observation.detected
        subtask = self._subtask
        if subtask is not None and subtask.done(observation):
            found = subtask.found(observation)
            target = subtask.target_index
            self._log[-1].update(outcome="found" if found else "missed", end_step=observation.step)
            if not found and self.settings.miss == "drop":
                self._available[target] = False
            self._next(
                observation, self._plan[0] if found else self._plan[1], target if found else None
            )
        if self._dwell_end is not None and observation.step >= self._dwell_end:
            target = self._follow
            self._follow = self._dwell_end = None
            self._log[-1].update(end_step=observation.step)
            self._next(observation, self._plan[0], target)
        if self._subtask is not None:
            return self._subtask.next_waypoint(observation)
        if self._follow is not None:
            return self._mission.motion.mean_positions(
                observation.means[self._follow], [self._mission.time_step]
            )[0]
        return observation.agent_position

    def current_plan(self) -> CurrentPlan:
        """The sub-task being flown (pursuit, dwell or follow) and the plans after it."""
        if self._subtask is not None:
            sub = self._subtask
            pursuit = Subtask("pursue", sub.target_index, sub.start_step, float(sub.p_find))
            return CurrentPlan(pursuit, *self._plan)
        if self._follow is None:
            return CurrentPlan()
        since = self._log[-1]["start_step"]
        if self._dwell_end is not None:
            return CurrentPlan(Subtask("dwell", self._follow, since), self._plan[0])
        return CurrentPlan(Subtask("follow", self._follow, since))

    def episode_info(self) -> dict:
        """The sub-tasks flown (plan, estimate, outcome; a planned action ``n`` is the dwell),
        every search's effort, the settings."""
        return {
            "settings": self.settings.as_json(),
            "subtasks": self._log,
            "searches": self._searches,
        }
