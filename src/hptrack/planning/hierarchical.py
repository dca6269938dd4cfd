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
   may also follow it for a dwell's length only, re-planning with the dwell fixed as it
   starts. The search numbers the actions (`hptrack.subtasks.ActionTable`); the planner flies
   them (`hptrack.planning.subtask_flight`) and logs each as a typed record
   (`hptrack.subtasks.Subtask`, its planned actions typed too). With
   ``miss="keep"`` a missed target stays in the action list.

Choices the paper leaves open (``docs/model.md``): a missed target that the agent measures
by chance later returns to the action list; a planned next action that the remaining budget can
no longer carry out triggers a fresh plan from the current state; with no action left the agent
follows the last found target, or hovers.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from hptrack.interface import CurrentPlan, MissionSpec, Observation, one_vehicle
from hptrack.models.mission import follow_tables, state_size
from hptrack.models.state import positions
from hptrack.planning.backups import backup_of
from hptrack.planning.fortified import fortified_choice
from hptrack.planning.rollout import UniformRandom
from hptrack.planning.search import DEFAULT_EXPLORATION, SearchOptions, SearchResult
from hptrack.planning.subtask_flight import SubtaskFlight, feasible
from hptrack.planning.subtask_mdp import (
    FIND,
    MISS,
    PlanningProblem,
    SubtaskEnv,
    SubtaskOptions,
    action_table,
    apply_outcome,
    coverage_steps,
    new_work,
)
from hptrack.planning.subtask_rollout import (
    MostUncertain,
    Nearest,
    Tour,
    UniformNoDwell,
    UniformNoFollow,
)
from hptrack.planning.subtask_search import search, warm_up
from hptrack.planning.tour import (
    TourPlan,
    TourRollout,
    TourSettings,
    cyclic_order,
    plan_tour,
    tour_choice,
)
from hptrack.settings import Iterations, PlannerSettings, TimeLimit
from hptrack.subtasks import HOVER, Subtask

TOUR_BASE = TourSettings()
"""The tour of ``rollout="tour_plan"``: the ``tour`` planner's defaults (``settle_variance``,
``min_find``, ``samples``), scored in the search's own MDP."""

PRESET_ITERATIONS: dict[str, int] = {"paper": 100_000, "improved": 100_000, "revisit": 20_000}
"""Simulations per tree search when neither ``iterations`` nor ``time_limit`` is given, by
preset: a search with the revisit tour runs about a fifth as many simulations per second at
n = 12 and 20, so its default effort is a fifth; at these efforts its decisions take less time
than the improved search's and score better (``docs/results/planner-scale.md``)."""


PAPER_SEARCH: dict[str, Any] = {
    "backup": "sampled",
    "max_weight": 1.0,
    "root_split": "even",
    "common_rollouts": False,
    "rollout": "uniform",
    "estimator": "paper",
    "dwell": 0.0,
    "miss": "drop",
    "passes": "ignore",
    "false_finds": "ignore",
    "coverage_limit": 0.0,
    "readmit": False,
    "commit": 0.0,
    "fortify": False,
}
"""The options of the paper's search, Algorithm 1."""

PRESETS: dict[str, dict[str, Any]] = {
    "paper": PAPER_SEARCH,
    "improved": {**PAPER_SEARCH, "backup": "max"},
    "revisit": {**PAPER_SEARCH, "backup": "max", "rollout": "tour_plan"},
}
"""The search options each preset stands for: the paper's algorithm exactly as written, the
improvements measured in ``docs/results/search-options.md``, and those with the revisit tour
as rollout policy and leaf value (``docs/results/planner-scale.md``)."""

DEFAULT_PRESET = "revisit"


DwellLength = Annotated[float, Field(ge=0.0, le=1e6)]
"""A dwell action's length, s."""


ROLLOUT_POLICIES: dict[str, type] = {
    "uniform": UniformRandom,
    "uniform_no_follow": UniformNoFollow,
    "uniform_no_dwell": UniformNoDwell,
    "nearest": Nearest,
    "most_uncertain": MostUncertain,
    "tour": Tour,
    "tour_plan": TourRollout,
}
"""The rollout policy classes by their settings' names (`MctsSettings.rollout`)."""


class MctsSettings(PlannerSettings):
    """Options of the hierarchical planner (``mcts``).

    Attributes:
        iterations: simulations per tree search (reproducible on any machine); when no time
            limit is given, 100,000 (20,000 with ``preset="revisit"``, `PRESET_ITERATIONS`).
        time_limit: wall time per tree search, s (the paper uses 30 s). With both, whichever
            comes first.
        exploration: UCB1 constant ``c`` on values normalised to the observed return range.
        preset: ``"paper"`` (the paper's search, Algorithm 1), ``"improved"`` (the max
            backup) or ``"revisit"`` (the max backup and ``rollout="tour_plan"``); it sets the
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
            without the dwell actions), ``"nearest"``, ``"most_uncertain"``, ``"tour"``
            (`hptrack.planning.subtask_rollout`) or ``"tour_plan"``: the revisit tour that the
            ``tour`` planner would fly, planned at every decision in the search's own MDP and
            flown to the end of the budget from every leaf (`hptrack.planning.tour`).
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
        false_finds: ``"ignore"`` (the paper): a pursuit ends in a find or a miss;
            ``"model"``: with the mission's false alarms (``sensor.false_alarm_density``), also
            in a false find, the tracker taking a false alarm for the target
            (`hptrack.coverage.false_finds`).
        coverage_limit: s; a pursuit's spiral ends at ``t_cutoff`` or after this long,
            whichever comes first, in the search's estimates and in flight (a short look at a
            broad belief instead of a search of it to ``t_cutoff``); 0 (the paper): at
            ``t_cutoff``.
        readmit: with ``miss="drop"``, when no target is left to pursue and none is being
            followed, the missed targets re-enter the action list with the beliefs the misses
            left (predicted to now) and the planner searches again, instead of the vehicle
            staying where it is; ``False`` (the paper): it stays. On by default in ``hptrack
            fly``.
        commit: s; with ``miss="keep"``, a pursuit that misses sooner than this after it began
            is followed by a new pursuit of the same target, not by the planned switch to
            another (hysteresis against a target change at every tick when the vehicle cannot
            keep up with its plan); 0 (the paper): the plan is followed.
        threads: independent trees searched in parallel and merged (root parallelism), each
            with the effort above; 1 (the paper's single tree) unless the machine has spare
            cores.
        fortify: with ``rollout="tour_plan"``, a decision keeps the tour's action unless the
            search's best beats its value by more than the standard error of the difference
            (`hptrack.planning.fortified`); ``False`` (the paper): the search's best.
    """

    iterations: Iterations | None = None
    time_limit: TimeLimit | None = None
    exploration: Annotated[float, Field(gt=0.0)] = DEFAULT_EXPLORATION
    preset: Literal["paper", "improved", "revisit"] = DEFAULT_PRESET
    backup: Literal["sampled", "expected", "max", "robust"] | None = None
    max_weight: Annotated[float | None, Field(ge=0.0, le=1.0)] = None
    root_split: Literal["even", "weighted"] | None = None
    common_rollouts: bool | None = None
    rollout: (
        Literal[
            "uniform",
            "uniform_no_follow",
            "uniform_no_dwell",
            "nearest",
            "most_uncertain",
            "tour",
            "tour_plan",
        ]
        | None
    ) = None
    rollout_epsilon: Annotated[float, Field(ge=0.0, le=1.0)] = 0.1
    estimator: Literal["paper", "sharp"] | None = None
    dwell: DwellLength | list[DwellLength] | None = None
    miss: Literal["drop", "keep"] | None = None
    passes: Literal["ignore", "credit"] | None = None
    false_finds: Literal["ignore", "model"] | None = None
    coverage_limit: Annotated[float | None, Field(ge=0.0, le=1e6)] = None
    readmit: bool | None = None
    commit: Annotated[float | None, Field(ge=0.0, le=1e6)] = None
    threads: Annotated[int, Field(ge=1, le=64)] = 1
    fortify: bool | None = None

    effort_fields = {"iterations": "iterations", "time_limit": "time_limit"}
    default_preset: ClassVar[str | None] = None
    """The preset when none is named; ``None``: `DEFAULT_PRESET`."""

    @model_validator(mode="before")
    @classmethod
    def _defaults(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        name = data.get("preset", cls.default_preset or DEFAULT_PRESET)
        data = {**data, "preset": name}
        if data.get("iterations") is None and data.get("time_limit") is None:
            effort = PRESET_ITERATIONS.get(name, PRESET_ITERATIONS[DEFAULT_PRESET])
            data = {**data, "iterations": effort}
        preset = PRESETS.get(name, {})
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

    @model_validator(mode="after")
    def _fortify_needs_the_tour(self) -> MctsSettings:
        if self.fortify and self.rollout != "tour_plan":
            raise ValueError(
                f"option fortify=true applies only to rollout=tour_plan, got rollout={self.rollout}"
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
            cls.default_preset or DEFAULT_PRESET,
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
        self.claimed: np.ndarray | None = None
        """``(n,)`` bool: targets another UAV of a team has claimed, out of this planner's
        action list while they are (set by a team planner, `hptrack.teams`); ``None``: none."""

    def _action_list(self, last_found: int | None = None) -> np.ndarray:
        """The targets this planner may pursue: available and not claimed by another UAV, but
        for the target it just found (followed, or dwelt on, even if another UAV claims it
        over a limited link)."""
        if self.claimed is None:
            return self._available
        mask = self._available & ~self.claimed
        if last_found is not None:
            mask[last_found] = self._available[last_found]
        return mask

    # --- planning -------------------------------------------------------------------------
    def _search(
        self,
        observation: Observation,
        current_action: int | None = None,
        last_found: int | None = None,
    ) -> tuple[SearchResult, tuple[int | None, ...]]:
        """A search from ``observation`` and its decisions: the action to take (a first plan),
        or the next action after each outcome of ``current_action`` (re-planning); with
        ``fortify``, each the tour's unless the search beats it (`fortified_choice`)."""
        began = time.perf_counter()
        problem = PlanningProblem.from_observation(
            self._record,
            observation,
            available=self._action_list(last_found),
            last_found=last_found,
            current_action=current_action,
            follow=self._follow_tables,
        )
        options, tour = self.options, None
        time_limit = self.time_limit
        if self.settings.rollout == "tour_plan":
            tour_env = problem.env(self.subtask_options)
            tour = self._tour(problem, tour_env)
            options = options._replace(
                rollout=TourRollout(tour.order, tour.settle, TOUR_BASE.min_find)
            )
            if time_limit is not None:  # the tour's planning counts in the decision's time
                time_limit = max(time_limit - (time.perf_counter() - began), 1e-3)
        result = search(
            problem,
            options,
            self.subtask_options,
            iterations=self.iterations,
            time_limit=time_limit,
            seed=self._rng,
            threads=self.settings.threads,
        )
        entry = {
            "step": observation.step,
            "simulations": result.simulations,
            "elapsed_s": result.elapsed,
            "stopped_by": result.stopped_by,
            "tree_bytes": result.tree_bytes,
        }
        if current_action is None:
            decisions: tuple[int | None, ...] = (result.best_action,)
        else:
            decisions = tuple(result.best_after(o) for o in (FIND, MISS))
        if tour is not None and self.settings.fortify:
            bases = self._tour_actions(problem, tour_env, tour, result)
            stats = (result.root,) if current_action is None else result.after
            decisions = tuple(
                fortified_choice(stats[o] if o < len(stats) else None, base)
                for o, base in enumerate(bases)
            )
            entry["tour_actions"] = list(bases)
        self._searches.append(entry)
        return result, decisions

    def _tour(self, problem: PlanningProblem, env: SubtaskEnv) -> TourPlan:
        """The tour (`hptrack.planning.tour.plan_tour`) from ``problem``'s root in the
        search's own MDP (``env``), entered at the current action's target when re-planning."""
        root = problem.root_state()
        kept = np.flatnonzero(problem.available).astype(np.int64)
        order = cyclic_order(
            positions(problem.means),
            problem.agent_position,
            kept,
            problem.last_found,
            self._mission.agent_speed,
        )
        entry = problem.current_action
        if entry is not None and entry >= problem.n_targets:  # a dwell: the tour goes on after
            entry = int(order[0]) if order.size else None
        draws = self._rng.random((TOUR_BASE.samples, problem.n_steps + 1))
        return plan_tour(env, root, order, TOUR_BASE, draws, self._tour_work, entry=entry)

    def _tour_actions(
        self, problem: PlanningProblem, env: SubtaskEnv, tour: TourPlan, result: SearchResult
    ) -> tuple[int, ...]:
        """The tour's action at each state the search decides for: the root (a first plan),
        or the state after each outcome of the current action (re-planning)."""
        if problem.current_action is None:
            return (tour.first,)
        actions = []
        for o in (FIND, MISS):
            if o >= result.root.payload.shape[1] or np.isnan(result.root.p[0, o]):
                actions.append(-1)
                continue
            state = problem.root_state()
            apply_outcome(
                env,
                state,
                problem.current_action,
                o,
                int(result.root.payload[0, o]),
                self._tour_work,
            )
            actions.append(
                int(tour_choice(env, state, tour.order, tour.settle, TOUR_BASE.min_find))
            )
        return tuple(actions)

    def _start(self, observation: Observation, index: int | None, last_found: int | None) -> None:
        """Begin flying action ``index`` (`hptrack.subtasks.ActionTable`; ``None``: follow
        ``last_found``, or hover); a pursuit or a dwell re-plans with it fixed (the conditional
        plan: the next action after each outcome)."""
        if index is None:
            index = last_found  # nothing to do: follow the target just found, or hover
        action = self._table.action(index, last_found) or HOVER
        flight = SubtaskFlight(action, observation, self._mission, self._coverage_steps)
        self._flight = flight
        after_find = after_miss = None
        if action.kind == "pursue":
            _, (find, miss) = self._search(observation, current_action=action.target)
            self._plan = (find, miss)
            after_miss = self._table.action(self._plan[1])
        elif action.kind == "dwell":
            _, (find, _) = self._search(observation, current_action=index, last_found=action.target)
            self._plan = (find, None)
        else:
            self._plan = (None, None)
        after_find = self._table.action(self._plan[0], action.target)
        self._log.append(replace(flight.record, after_find=after_find, after_miss=after_miss))

    def _search_afresh(self, observation: Observation, last_found: int | None) -> int | None:
        """The best action of a new search, or ``None`` if no target is left or no time."""
        if self._action_list(last_found).any() and observation.remaining_budget > 0:
            return self._search(observation, last_found=last_found)[1][0]
        return None

    def _readmit(self, step: int) -> bool:
        """With ``readmit``: the missed targets back in the action list at ``step``; whether
        there were any."""
        if not self.settings.readmit or self._available.all():
            return False
        self._readmitted.append(
            {"step": step, "targets": np.flatnonzero(~self._available).tolist()}
        )
        self._available[:] = True
        return True

    def _committed(self, observation: Observation, missed: Subtask, planned: int | None) -> bool:
        """With ``commit``: whether the pursuit ``missed``, ended sooner than ``commit`` s after
        it began, goes on with its own target (still in the action list) instead of the planned
        switch to another target."""
        target = missed.target
        assert target is not None  # a pursuit's
        switch = planned is not None and planned != target and planned < self._mission.n_targets
        begun_steps = observation.step - missed.start_step
        commit_steps = self.settings.commit / self._mission.time_step
        return switch and bool(self._available[target]) and begun_steps < commit_steps

    def _next(self, observation: Observation, planned: int | None, last_found: int | None) -> None:
        """Carry on after a sub-task: follow, dwell, start the planned target, or plan
        afresh."""
        if planned is None or not feasible(
            self._table,
            planned,
            self._mission,
            observation,
            self._action_list(last_found),
            last_found,
        ):
            planned = self._search_afresh(observation, last_found)
            if planned is None and last_found is None and self._readmit(observation.step):
                planned = self._search_afresh(observation, last_found)
        self._start(observation, planned, last_found)

    # --- Planner protocol ----------------------------------------------------------------
    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        one_vehicle(self.name, mission)
        if self.time_limit is not None:
            warm_up(self.options, self.subtask_options)
        self._mission = mission
        self._record = mission.record
        self._follow_tables = follow_tables(self._record)
        self._tour_work = new_work(state_size(self._record))
        self._rng = rng
        self._available = np.ones(mission.n_targets, dtype=bool)
        self._table = action_table(mission.n_targets, mission.time_step, self.subtask_options)
        steps = coverage_steps(mission.time_step, self.subtask_options.coverage_limit)
        self._coverage_steps = None if steps < 0 else steps
        self._flight: SubtaskFlight | None = None
        self._plan: tuple[int | None, int | None] = (None, None)
        self._log: list[Subtask] = []
        self._searches: list[dict] = []
        self._readmitted: list[dict] = []
        self._commitments: list[int] = []
        self._next(observation, None, None)

    def act(self, observation: Observation) -> np.ndarray:
        self._available |= observation.detected
        flight = self._flight
        assert flight is not None  # started by reset
        kind, target = flight.action.kind, flight.action.target
        if kind in ("pursue", "dwell") and flight.done(observation):
            if kind == "pursue":
                found = flight.found(observation)
                self._log[-1] = self._log[-1].ended(
                    observation.step, "found" if found else "missed"
                )
                if not found and self.settings.miss == "drop":
                    self._available[target] = False
                planned = self._plan[0] if found else self._plan[1]
                if not found and self._committed(observation, self._log[-1], planned):
                    self._commitments.append(observation.step)
                    planned = target
                self._next(observation, planned, target if found else None)
            else:
                self._log[-1] = self._log[-1].ended(observation.step)
                self._next(observation, self._plan[0], target)
        assert self._flight is not None
        return self._flight.waypoint(observation)

    def current_plan(self) -> CurrentPlan:
        """The sub-task being flown (pursuit, dwell or follow) and the actions planned after
        it; nothing while hovering."""
        if self._flight is None or self._flight.action.kind == "hover":
            return CurrentPlan()
        record = self._log[-1]
        return CurrentPlan(record, record.after_find, record.after_miss)

    def episode_info(self) -> dict:
        """The sub-tasks flown (`hptrack.subtasks.Subtask.to_json`: action, estimate,
        outcome, the actions planned after it), every search's effort, the settings (and, with
        ``readmit``, when the missed targets re-entered the action list; with ``commit``, the
        steps at which a missed pursuit was followed by its own target instead of a switch)."""
        info = {
            "settings": self.settings.as_json(),
            "subtasks": [entry.to_json() for entry in self._log],
            "searches": self._searches,
        }
        if self.settings.readmit:
            info["readmitted"] = self._readmitted
        if self.settings.commit > 0.0:
            info["committed"] = self._commitments
        return info
