"""What a planner sees and how it acts (Gymnasium-like, no truth).

Every planner, whether it chooses sub-tasks (the paper's hierarchical planner), controls
(ARVI, A*) or a learned policy, implements :class:`Planner`. Each step the simulator hands it an
:class:`Observation` (what a real UAV would know: time, remaining budget, its own position, the
target beliefs and which targets it just measured) and receives a waypoint: the position the agent
should fly towards. The simulator moves the agent at most ``speed * time_step`` towards it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np

from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel


@dataclass(frozen=True)
class MissionSpec:
    """The static facts of a mission that a planner may use.

    Attributes:
        time_step: ``tau``, s.
        budget: mission duration ``B``, s.
        agent_speed: ``v_a``, m/s.
        motion: target motion model (``F``, ``Q`` form).
        sensor: measurement model (footprint diameter ``w`` in m, noise ``R``).
        process_noise: ``(n,)`` per-target noise intensities ``q``.
        target_ids: the targets' names.
    """

    time_step: float
    budget: float
    agent_speed: float
    motion: ConstantVelocityModel
    sensor: PositionMeasurementModel
    process_noise: np.ndarray
    target_ids: tuple[str, ...]

    @property
    def n_steps(self) -> int:
        """Number of simulation steps in the budget (``B / tau``)."""
        return int(np.floor(self.budget / self.time_step + 1e-9))

    @property
    def step_length(self) -> float:
        """Largest agent displacement per step, m (``v_a * tau``)."""
        return self.agent_speed * self.time_step

    @property
    def n_targets(self) -> int:
        return len(self.target_ids)


@dataclass(frozen=True)
class Observation:
    """The planner's view at one step (arrays are read-only copies).

    Attributes:
        step: step index ``k`` (time ``k * tau``).
        time: elapsed time, s.
        remaining_budget: ``B - time``, s.
        agent_position: ``(2,)`` agent position, m.
        means: ``(n, 4)`` belief means.
        covariances: ``(n, 4, 4)`` belief covariances.
        detected: ``(n,)`` which targets were measured at this step.
    """

    step: int
    time: float
    remaining_budget: float
    agent_position: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    detected: np.ndarray


@runtime_checkable
class Planner(Protocol):
    """A mission planner. ``name`` identifies it in records and the registry.

    ``reset`` is called once before the first step with the mission facts, the first
    observation and the planner's own random generator; ``act`` then returns, every step, the
    waypoint ``(2,)`` in m that the agent should fly towards.
    """

    name: str

    def reset(self, mission: MissionSpec, observation: Observation,
              rng: np.random.Generator) -> None: ...

    def act(self, observation: Observation) -> np.ndarray: ...
