"""Discrete motion primitives and the step-level planner base of the ARVI and A* baselines.

The control set of ``docs/baselines.md``: ``n_headings`` headings at full speed plus
hover, each held for ``control_steps`` simulator steps (default 10 steps = 5 s = 150 m at
30 m/s). Control 0 is hover, so index order is the planners' tie-break (hover first); heading
``k`` points at ``2 pi (k - 1) / n_headings`` from the x axis, counter-clockwise.

`PrimitivePlanner` implements the simulator's `Planner`
protocol for any planner that chooses sequences of primitives over a receding horizon: it asks
the subclass for a plan at a primitive boundary, executes the first ``replan_period`` primitives
of it and turns each into one waypoint per simulator step.
"""

from __future__ import annotations

import dataclasses
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any, ClassVar

import numpy as np
from pydantic import BeforeValidator, Field

from hptrack.interface import CurrentPlan, one_vehicle
from hptrack.settings import PlannerSettings

if TYPE_CHECKING:
    from hptrack.interface import MissionSpec, Observation

HOVER = 0
"""Index of the hover control in every control set."""


def step_directions(n_headings: int) -> np.ndarray:
    """Unit displacement per step of each control, ``(n_headings + 1, 2)``; row 0 is hover."""
    angles = 2.0 * np.pi * np.arange(n_headings) / n_headings
    headings = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    headings[np.abs(headings) < 1e-15] = 0.0
    return np.vstack([np.zeros((1, 2)), headings])


def _schedule(value: Any) -> Any:
    """A comma-separated text (from ``-o``) or a single number as a tuple of numbers."""
    if isinstance(value, str):
        return tuple(part.strip() for part in value.split(",") if part.strip())
    if isinstance(value, int | float):
        return (value,)
    return value


NonNegativeOrInf = Annotated[float, Field(ge=0.0, allow_inf_nan=True)]
Schedule = Annotated[tuple[NonNegativeOrInf, ...], BeforeValidator(_schedule), Field(min_length=1)]
"""A tuple of non-negative numbers (``inf`` allowed, NaN refused by ``ge``); ``-o`` takes them
comma-separated."""


class PrimitiveSettings(PlannerSettings):
    """Settings shared by the step-level planners.

    Attributes:
        control_steps: simulator steps per motion primitive (count; 10 steps of 0.5 s = 5 s).
        n_headings: number of full-speed headings besides hover (count).
        replan_period: primitives executed from each plan before replanning (count).
    """

    control_steps: Annotated[int, Field(ge=1, le=10_000)] = 10
    n_headings: Annotated[int, Field(ge=1, le=360)] = 8
    replan_period: Annotated[int, Field(ge=1, le=10_000)] = 1


@dataclass(frozen=True)
class DecisionStats:
    """What one planning decision cost and found.

    Attributes:
        step: simulator step at which the plan was made.
        planning_time_s: wall time of the search, s.
        nodes_expanded: nodes expanded (all passes together for ARVI).
        passes: anytime passes completed (ARVI; 1 for A*).
        capped: whether a deterministic cap (A* expansions, ARVI nodes per level) bound.
        predicted_cost: cost of the returned plan under the planner's step cost.
    """

    step: int
    planning_time_s: float
    nodes_expanded: int
    passes: int
    capped: bool
    predicted_cost: float


class PrimitivePlanner(ABC):
    """Receding-horizon planner over motion primitives (the simulator's ``Planner`` protocol).

    At a primitive boundary, when the current plan is used up or ``replan_period`` primitives
    of it have run, `search` returns a new sequence of control indices. Each simulator
    step then returns the waypoint one full-speed step along the current control (or the agent
    position for hover). ``decisions`` logs one `DecisionStats` per search.
    """

    name: str
    settings_type: ClassVar[type[PrimitiveSettings]] = PrimitiveSettings

    def __init__(self, settings: PrimitiveSettings | None = None) -> None:
        self.settings = self.settings_type() if settings is None else settings
        self.decisions: list[DecisionStats] = []
        self._plan = np.zeros(0, dtype=np.int64)
        self._executed = 0
        self._sub_step = 0

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None:
        """Start a mission (the searches are deterministic; ``rng`` is unused)."""
        one_vehicle(self.name, mission)
        self.mission = mission
        self.step_displacements = mission.step_length * step_directions(self.settings.n_headings)
        self.decisions = []
        self._plan = np.zeros(0, dtype=np.int64)
        self._executed = 0
        self._sub_step = 0

    def horizon_primitives(self, observation: Observation, horizon: int) -> int:
        """``horizon`` cut to the primitives that start before the budget ends (at least 1)."""
        remaining_steps = self.mission.n_steps - observation.step
        return max(1, min(horizon, -(-remaining_steps // self.settings.control_steps)))

    @abstractmethod
    def search(self, observation: Observation) -> tuple[np.ndarray, DecisionStats]:
        """Plan from ``observation``: control indices ``(H,)`` and the decision's statistics."""

    def current_plan(self) -> CurrentPlan:
        """No sub-tasks: nothing to show."""
        return CurrentPlan()

    def episode_info(self) -> dict:
        """Planning effort over the mission so far (stored with the episode record)."""
        info: dict[str, Any] = {
            "settings": self.settings.as_json(),
            "decisions": len(self.decisions),
        }
        if self.decisions:
            times = [d.planning_time_s for d in self.decisions]
            info |= {
                "mean_decision_s": float(np.mean(times)),
                "max_decision_s": float(np.max(times)),
                "mean_nodes_expanded": float(np.mean([d.nodes_expanded for d in self.decisions])),
                "capped_fraction": float(np.mean([d.capped for d in self.decisions])),
            }
        return info

    def act(self, observation: Observation) -> np.ndarray:
        """Waypoint ``(2,)`` in m: one full-speed step along the current primitive."""
        if self._sub_step == 0 and (
            self._executed >= min(len(self._plan), self.settings.replan_period)
        ):
            start = time.perf_counter()
            plan, stats = self.search(observation)
            stats = dataclasses.replace(
                stats, step=observation.step, planning_time_s=time.perf_counter() - start
            )
            self.decisions.append(stats)
            self._plan = np.asarray(plan, dtype=np.int64)
            self._executed = 0
        control = self._plan[self._executed]
        self._sub_step += 1
        if self._sub_step == self.settings.control_steps:
            self._sub_step = 0
            self._executed += 1
        position = np.asarray(observation.agent_position, dtype=float)
        return position + self.step_displacements[control]
