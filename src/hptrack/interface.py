"""What every layer above the models may use: the mission's constants, what a planner sees, and
the planner protocol (Gymnasium-like; a planner never sees the truth, except a reference that
declares it reads it, :class:`TruthReader`).

Every planner, whether it chooses sub-tasks (the paper's hierarchical planner), controls (ARVI,
A*) or a learned policy, implements :class:`Planner`. Each step the simulator (or the real-time
controller) hands it an :class:`Observation` (what a real UAV would know: time, remaining budget,
its own position, the target beliefs and which targets it just measured) and receives a
waypoint: the position the agent should fly towards, at most ``agent_speed * time_step`` away.

:class:`MissionSpec` is the one vocabulary for the mission constants (time step, budget, speed,
sensor diameter, measurement noise, process noise); the compiled kernels receive the same names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hptrack.models.measurement import PositionMeasurementModel, check_noise_covariance
from hptrack.models.motion import ConstantVelocityModel, ProcessNoiseForm

DEFAULT_MEASUREMENT_NOISE = 10.0
"""Default ``R = 10 I`` m^2 (sigma = 3.16 m per axis); the paper does not state ``R``."""


def _default_noise() -> np.ndarray:
    return DEFAULT_MEASUREMENT_NOISE * np.eye(2)


class InputError(ValueError):
    """Bad user input (a file, a field, an option or a value): the message is one line that
    names it and the value. The CLI shows it without a traceback and exits with code 2; every
    other exception is a bug and keeps its traceback."""


@dataclass(frozen=True, eq=False)
class MissionSpec:
    """The static facts of a mission that a planner may use (SI units).

    Attributes:
        time_step: ``tau``, s (the paper uses 0.5 s).
        budget: mission duration ``B``, s.
        agent_speed: ``v_a``, m/s.
        sensor_diameter: footprint diameter ``w``, m; targets within ``w/2`` are measured.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
        process_noise_form: which per-step ``Q`` (:mod:`hptrack.models.motion`).
        process_noise: ``(n,)`` per-target noise intensities ``q``, m^2/s^3.
        target_ids: the targets' names.
    """

    time_step: float = 0.5
    budget: float = 900.0
    agent_speed: float = 30.0
    sensor_diameter: float = 100.0
    measurement_noise: np.ndarray = field(default_factory=_default_noise)
    process_noise_form: ProcessNoiseForm = "continuous"
    process_noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    target_ids: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        for name in ("time_step", "budget", "agent_speed", "sensor_diameter"):
            value = getattr(self, name)
            if isinstance(value, bool) or not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if self.process_noise_form not in ("continuous", "paper_text"):
            raise ValueError(f"unknown process_noise_form {self.process_noise_form!r}")
        noise = check_noise_covariance(self.measurement_noise)
        q = np.array(self.process_noise, dtype=float).reshape(-1)
        if not np.all(np.isfinite(q) & (q >= 0.0)):
            raise ValueError(f"process_noise must be finite and >= 0, got {q.tolist()}")
        noise.flags.writeable = False
        q.flags.writeable = False
        object.__setattr__(self, "measurement_noise", noise)
        object.__setattr__(self, "process_noise", q)
        object.__setattr__(self, "target_ids", tuple(self.target_ids))

    @property
    def n_steps(self) -> int:
        """Number of simulation steps in the budget (``B / tau``)."""
        return int(np.floor(self.budget / self.time_step + 1e-9))

    @property
    def step_length(self) -> float:
        """Largest agent displacement per step, m (``v_a * tau``)."""
        return self.agent_speed * self.time_step

    @property
    def sensor_radius(self) -> float:
        """Footprint radius ``w / 2``, m."""
        return 0.5 * self.sensor_diameter

    @property
    def n_targets(self) -> int:
        return len(self.target_ids)

    @property
    def motion(self) -> ConstantVelocityModel:
        """The target motion model (``F``, ``Q`` form)."""
        return ConstantVelocityModel(self.time_step, self.process_noise_form)

    @property
    def c_per_step(self) -> float:
        """Lower-right block of the per-step ``Q`` over ``q`` (``tau`` s or 1)."""
        return self.motion.c_per_step

    @property
    def sensor(self) -> PositionMeasurementModel:
        """The measurement model (footprint, ``R``)."""
        return PositionMeasurementModel(self.measurement_noise, self.sensor_diameter)


@dataclass(frozen=True)
class Observation:
    """The planner's view at one step (arrays are read-only copies).

    Attributes:
        step: step index ``k`` (time ``k * tau``).
        time: elapsed time, s.
        remaining_budget: ``B - time``, s.
        agent_position: ``(2,)`` agent position, m.
        means: ``(n, 4)`` belief means (m, m/s).
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
    waypoint ``(2,)`` in m that the agent should fly towards; ``episode_info`` returns
    JSON-ready metadata of the mission so far (its decisions, effort, settings).
    """

    name: str

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None: ...

    def act(self, observation: Observation) -> np.ndarray: ...

    def episode_info(self) -> dict[str, Any]: ...


@runtime_checkable
class TruthReader(Protocol):
    """A reference planner that reads the true target states (``clairvoyant``): the simulator
    hands them, before every ``act``, to a planner of this kind and to no other. No real mission
    has them, so it is never flown."""

    def see_truth(self, states: np.ndarray) -> None: ...
