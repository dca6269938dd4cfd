"""Validated scenario model: the file boundary of every mission (notes: "Random scenarios").

A scenario fixes the time step, the budget, the agent, and each target's prior belief
(mean, covariance), process noise ``q`` and, optionally, its true initial state. Every number is
checked: finite, positive where it must be, covariances symmetric positive definite, target ids
unique, and every target's mean speed below the agent's (the coverage planner of Sec. IV-A needs
``v_a > |v_hat|``). Errors name the field and the value.
"""

from __future__ import annotations

from typing import Annotated, Self

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel, ProcessNoiseForm
from hptrack.sim.interface import MissionSpec

PositiveFloat = Annotated[float, Field(gt=0.0)]
Vector2 = tuple[float, float]
Vector4 = tuple[float, float, float, float]
Matrix4 = tuple[Vector4, Vector4, Vector4, Vector4]

_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class AgentSpec(BaseModel):
    """The UAV: start position (m), speed ``v_a`` (m/s), footprint diameter ``w`` (m) and the
    standard deviation of each measured coordinate (m; ``R = std^2 I``)."""

    model_config = _STRICT

    position: Vector2 = (0.0, 0.0)
    speed: PositiveFloat = 30.0
    sensor_diameter: PositiveFloat = 100.0
    measurement_noise_std: PositiveFloat = float(np.sqrt(10.0))


class TargetSpec(BaseModel):
    """One target: prior ``mean`` [x, y, vx, vy] (m, m/s), 4x4 ``covariance``, process noise
    ``q`` (m^2/s^3) and optionally its true initial state ``truth``."""

    model_config = _STRICT

    id: Annotated[str, Field(min_length=1)]
    mean: Vector4
    covariance: Matrix4
    process_noise: Annotated[float, Field(ge=0.0)]
    truth: Vector4 | None = None

    @field_validator("covariance")
    @classmethod
    def _symmetric_positive_definite(cls, value: Matrix4) -> Matrix4:
        cov = np.asarray(value, dtype=float)
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-9):
            raise ValueError(f"covariance is not symmetric: {cov.tolist()}")
        if np.min(np.linalg.eigvalsh(cov)) <= 0.0:
            raise ValueError(f"covariance is not positive definite: {cov.tolist()}")
        return value


class Scenario(BaseModel):
    """A whole mission. ``seed`` drives the true initial states (when not given) and all noise."""

    model_config = _STRICT

    time_step: PositiveFloat = 0.5
    budget: PositiveFloat = 900.0
    seed: Annotated[int, Field(ge=0)] = 0
    process_noise_form: ProcessNoiseForm = "continuous"
    agent: AgentSpec = AgentSpec()
    targets: Annotated[list[TargetSpec], Field(min_length=1)]

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.budget < self.time_step:
            raise ValueError(f"budget {self.budget} s is shorter than time_step {self.time_step} s")
        seen: set[str] = set()
        for i, target in enumerate(self.targets):
            if target.id in seen:
                raise ValueError(f"targets.{i}.id: duplicate target id {target.id!r}")
            seen.add(target.id)
            speed = float(np.hypot(target.mean[2], target.mean[3]))
            if speed >= self.agent.speed:
                raise ValueError(
                    f"targets.{i}.mean: target {target.id!r} mean speed {speed:g} m/s is not "
                    f"below agent.speed {self.agent.speed:g} m/s"
                )
        return self

    # --- arrays for the library -------------------------------------------------------------
    @property
    def target_ids(self) -> tuple[str, ...]:
        return tuple(t.id for t in self.targets)

    def means(self) -> np.ndarray:
        """Prior means ``(n, 4)``."""
        return np.array([t.mean for t in self.targets], dtype=float)

    def covariances(self) -> np.ndarray:
        """Prior covariances ``(n, 4, 4)``."""
        return np.array([t.covariance for t in self.targets], dtype=float)

    def process_noise(self) -> np.ndarray:
        """Noise intensities ``q`` ``(n,)``."""
        return np.array([t.process_noise for t in self.targets], dtype=float)

    def motion_model(self) -> ConstantVelocityModel:
        return ConstantVelocityModel(self.time_step, self.process_noise_form)

    def sensor_model(self) -> PositionMeasurementModel:
        return PositionMeasurementModel(self.agent.measurement_noise_std,
                                        self.agent.sensor_diameter)

    def mission_spec(self) -> MissionSpec:
        """The static facts a planner may use."""
        return MissionSpec(
            time_step=self.time_step,
            budget=self.budget,
            agent_speed=self.agent.speed,
            motion=self.motion_model(),
            sensor=self.sensor_model(),
            process_noise=self.process_noise(),
            target_ids=self.target_ids,
        )

    def with_seed(self, seed: int) -> Scenario:
        """The same scenario driven by another seed."""
        return self.model_copy(update={"seed": seed})
