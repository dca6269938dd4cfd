"""Discrete motion primitives and the step-level planner base of the ARVI and A* baselines.

The control set of ``shared/notes/baselines.md``: ``n_headings`` headings at full speed plus
hover, each held for ``control_steps`` simulator steps (default 10 steps = 5 s = 150 m at
30 m/s). Control 0 is hover, so index order is the planners' tie-break (hover first); heading
``k`` points at ``2 pi (k - 1) / n_headings`` from the x axis, counter-clockwise.

:class:`PrimitivePlanner` implements the simulator's :class:`~hptrack.sim.interface.Planner`
protocol for any planner that chooses sequences of primitives over a receding horizon: it asks
the subclass for a plan at a primitive boundary, executes the first ``replan_period`` primitives
of it and turns each into one waypoint per simulator step.
"""

from __future__ import annotations

import dataclasses
import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Self, TypeVar

import numpy as np

from hptrack.baselines.information import RolloutSpec

if TYPE_CHECKING:
    from hptrack.sim.interface import MissionSpec, Observation

HOVER = 0
"""Index of the hover control in every control set."""


def step_directions(n_headings: int) -> np.ndarray:
    """Unit displacement per step of each control, ``(n_headings + 1, 2)``; row 0 is hover."""
    angles = 2.0 * np.pi * np.arange(n_headings) / n_headings
    headings = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    headings[np.abs(headings) < 1e-15] = 0.0
    return np.vstack([np.zeros((1, 2)), headings])


@dataclass(frozen=True)
class PrimitiveParams:
    """Parameters shared by the step-level planners.

    Attributes:
        control_steps: simulator steps per motion primitive (count; 10 steps of 0.5 s = 5 s).
        n_headings: number of full-speed headings besides hover (count).
        replan_period: primitives executed from each plan before replanning (count).
    """

    control_steps: int = 10
    n_headings: int = 8
    replan_period: int = 1

    def __post_init__(self) -> None:
        if self.control_steps < 1 or self.n_headings < 1 or self.replan_period < 1:
            raise ValueError("control_steps, n_headings and replan_period must be >= 1")


P = TypeVar("P", bound=PrimitiveParams)


def params_from_options(params_type: type[P], options: dict[str, Any]) -> P:
    """Build ``params_type`` from keyword options; strings (from a CLI) are parsed by field.

    A string becomes the type of the field's default: ``int``, ``float``, a comma-separated
    ``tuple`` of floats, ``"none"`` for ``None`` (a float otherwise), or stays a string; a
    sequence (a YAML list) for a tuple field becomes a tuple of floats.
    """
    defaults = {f.name: f.default for f in dataclasses.fields(params_type)}
    unknown = set(options) - set(defaults)
    if unknown:
        raise ValueError(f"unknown {params_type.__name__} options: {sorted(unknown)}")
    values = {}
    for key, value in options.items():
        default = defaults[key]
        try:
            if isinstance(default, tuple):
                items = value.split(",") if isinstance(value, str) else value
                value = tuple(float(v) for v in items)
            elif isinstance(value, str) and not isinstance(default, str):
                if value.lower() == "none":
                    value = None
                elif isinstance(default, int):
                    value = int(value)
                else:
                    value = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{params_type.__name__}.{key}: cannot read {value!r} as the type "
                             f"of its default {default!r}") from None
        values[key] = value
    return params_type(**values)


def _json_safe(value: Any) -> Any:
    """``value`` with non-finite floats as strings and tuples as lists (strict JSON)."""
    if isinstance(value, tuple | list):
        return [_json_safe(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


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
    of it have run, :meth:`search` returns a new sequence of control indices. Each simulator
    step then returns the waypoint one full-speed step along the current control (or the agent
    position for hover). ``decisions`` logs one :class:`DecisionStats` per search.
    """

    name: str
    params_type: type[PrimitiveParams] = PrimitiveParams
    option_aliases: dict[str, str] = {"time_limit": "time_limit_s"}
    """Generic option names of the CLI (``--time-limit``), mapped to parameter names."""

    def __init__(self, params: PrimitiveParams | None = None) -> None:
        self.params = self.params_type() if params is None else params
        self.decisions: list[DecisionStats] = []
        self._plan = np.zeros(0, dtype=np.int64)
        self._executed = 0
        self._sub_step = 0

    @classmethod
    def from_options(cls, **options: Any) -> Self:
        """The planner with parameters from keyword options (see :func:`params_from_options`).

        The registry's factory; ``option_aliases`` translates the CLI's generic names.
        """
        options = {cls.option_aliases.get(key, key): value for key, value in options.items()}
        return cls(params_from_options(cls.params_type, options))

    def reset(self, mission: MissionSpec, observation: Observation,
              rng: np.random.Generator) -> None:
        """Start a mission (the searches are deterministic; ``rng`` is unused)."""
        self.mission = mission
        self.spec = RolloutSpec.from_mission(mission)
        self.step_displacements = mission.step_length * step_directions(self.params.n_headings)
        self.decisions = []
        self._plan = np.zeros(0, dtype=np.int64)
        self._executed = 0
        self._sub_step = 0

    def horizon_primitives(self, observation: Observation, horizon: int) -> int:
        """``horizon`` cut to the primitives that start before the budget ends (at least 1)."""
        remaining_steps = self.mission.n_steps - observation.step
        return max(1, min(horizon, -(-remaining_steps // self.params.control_steps)))

    @abstractmethod
    def search(self, observation: Observation) -> tuple[np.ndarray, DecisionStats]:
        """Plan from ``observation``: control indices ``(H,)`` and the decision's statistics."""

    def episode_info(self) -> dict:
        """Planning effort over the mission so far (stored with the episode record)."""
        info: dict[str, Any] = {
            "decisions": len(self.decisions),
            "params": {k: _json_safe(v) for k, v in dataclasses.asdict(self.params).items()},
        }
        if self.decisions:
            times = [d.planning_time_s for d in self.decisions]
            info |= {"mean_decision_s": float(np.mean(times)),
                     "max_decision_s": float(np.max(times)),
                     "mean_nodes_expanded": float(np.mean([d.nodes_expanded
                                                           for d in self.decisions])),
                     "capped_fraction": float(np.mean([d.capped for d in self.decisions]))}
        return info

    def act(self, observation: Observation) -> np.ndarray:
        """Waypoint ``(2,)`` in m: one full-speed step along the current primitive."""
        if self._sub_step == 0 and (self._executed >= min(len(self._plan),
                                                           self.params.replan_period)):
            start = time.perf_counter()
            plan, stats = self.search(observation)
            stats = dataclasses.replace(stats, step=observation.step,
                                        planning_time_s=time.perf_counter() - start)
            self.decisions.append(stats)
            self._plan = np.asarray(plan, dtype=np.int64)
            self._executed = 0
        control = self._plan[self._executed]
        self._sub_step += 1
        if self._sub_step == self.params.control_steps:
            self._sub_step = 0
            self._executed += 1
        position = np.asarray(observation.agent_position, dtype=float)
        return position + self.step_displacements[control]
