"""Validated scenario model: the file boundary of every mission (``docs/model.md``).

A scenario fixes the time step, the budget, the agent, and each target's prior belief (mean,
covariance), process noise ``q`` and, optionally, its true initial state. Every number is
checked before any work starts: a real number (a boolean is not), finite, inside a sane range,
covariances symmetric positive definite with a well-conditioned position block and a finite
``log det`` up to the budget's end, the budget a whole number of time steps and at most
:data:`MAX_STEPS` of them, target ids unique, and every target's mean speed below the agent's
(the coverage planner of Sec. IV-A needs ``v_a > |v_hat|``). Errors name the field and the value.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Self

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, field_validator, model_validator

from hptrack.interface import MissionSpec, Observation
from hptrack.models.beliefs import position_logdet
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.motion import ConstantVelocityModel, ProcessNoiseForm

MAX_STEPS = 1_000_000
"""Most simulation steps a mission may have (``budget / time_step``)."""
MAX_COORDINATE_M = 1e7
"""Largest absolute position coordinate, m (10,000 km)."""
MIN_POSITION_CONDITION = 1e-12
"""Smallest ratio of the position covariance's eigenvalues (a flatter ellipse is degenerate)."""


def _not_bool(value: Any) -> Any:
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got the boolean {value}")
    return value


Real = Annotated[float, BeforeValidator(_not_bool)]
Coordinate = Annotated[Real, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M)]
Vector2 = tuple[Coordinate, Coordinate]
Vector4 = tuple[Real, Real, Real, Real]
Matrix2 = tuple[tuple[Real, Real], tuple[Real, Real]]
Matrix4 = tuple[Vector4, Vector4, Vector4, Vector4]

_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class AgentSpec(BaseModel):
    """The UAV: start ``position`` (m), ``speed`` ``v_a`` (m/s), footprint ``sensor_diameter``
    ``w`` (m), and the measurement noise: ``measurement_noise_std`` per axis (m; ``R = std^2
    I``) or a full 2x2 ``measurement_noise_covariance`` (m^2), which takes precedence."""

    model_config = _STRICT

    position: Vector2 = (0.0, 0.0)
    speed: Annotated[Real, Field(ge=0.1, le=1000.0)] = 30.0
    sensor_diameter: Annotated[Real, Field(ge=0.01, le=1e5)] = 100.0
    measurement_noise_std: Annotated[Real, Field(ge=1e-6, le=1e4)] = float(np.sqrt(10.0))
    measurement_noise_covariance: Matrix2 | None = None

    @model_validator(mode="after")
    def _noise(self) -> Self:
        if self.measurement_noise_covariance is not None:
            r = np.asarray(self.measurement_noise_covariance, dtype=float)
            if abs(r[0, 1] - r[1, 0]) > 1e-9 * max(float(np.max(np.abs(r))), 1.0):
                raise ValueError(f"measurement_noise_covariance is not symmetric: {r.tolist()}")
            eig = np.linalg.eigvalsh(r)
            if eig[0] <= 1e-12 or eig[1] > 1e8:
                raise ValueError(
                    "measurement_noise_covariance must be positive definite with "
                    f"eigenvalues in (1e-12, 1e8] m^2, got {r.tolist()}"
                )
        return self

    def noise_covariance(self) -> np.ndarray:
        """``R`` (2x2), m^2."""
        if self.measurement_noise_covariance is not None:
            return np.array(self.measurement_noise_covariance, dtype=float)
        return self.measurement_noise_std**2 * np.eye(2)


class TargetSpec(BaseModel):
    """One target: prior ``mean`` [x, y, vx, vy] (m, m/s), 4x4 ``covariance``, process noise
    ``q`` (m^2/s^3) and optionally its true initial state ``truth``."""

    model_config = _STRICT

    id: Annotated[str, Field(min_length=1, max_length=200)]
    mean: tuple[Coordinate, Coordinate, Real, Real]
    covariance: Matrix4
    process_noise: Annotated[Real, Field(ge=0.0, le=1e6)]
    truth: tuple[Coordinate, Coordinate, Real, Real] | None = None

    @field_validator("covariance")
    @classmethod
    def _covariance(cls, value: Matrix4) -> Matrix4:
        cov = np.asarray(value, dtype=float)
        if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-9):
            raise ValueError(f"covariance is not symmetric: {cov.tolist()}")
        with np.errstate(all="ignore"):
            eig = np.linalg.eigvalsh(cov) if np.all(np.isfinite(cov * cov)) else None
        if eig is None or not np.all(np.isfinite(eig)):
            raise ValueError(f"entries are too large: {cov.tolist()}")
        if eig[0] <= 0.0:
            raise ValueError(f"covariance is not positive definite: {cov.tolist()}")
        pos = np.linalg.eigvalsh(cov[:2, :2])
        if pos[0] < MIN_POSITION_CONDITION * pos[1]:
            raise ValueError(
                f"the position block {cov[:2, :2].tolist()} is degenerate (its "
                "ellipse is flatter than 1e-12)"
            )
        return value


class Scenario(BaseModel):
    """A whole mission. ``seed`` drives the true initial states (when not given) and all noise."""

    model_config = _STRICT

    time_step: Annotated[Real, Field(ge=1e-3, le=60.0)] = 0.5
    budget: Annotated[Real, Field(gt=0.0)] = 900.0
    seed: Annotated[int, BeforeValidator(_not_bool), Field(ge=0, lt=2**63)] = 0
    process_noise_form: ProcessNoiseForm = "continuous"
    agent: AgentSpec = AgentSpec()
    targets: Annotated[list[TargetSpec], Field(min_length=1, max_length=62)]

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        steps = self.budget / self.time_step
        if self.budget < self.time_step:
            raise ValueError(
                f"budget {self.budget:g} s is shorter than time_step {self.time_step:g} s"
            )
        if abs(steps - round(steps)) > 1e-9 * max(steps, 1.0):
            raise ValueError(
                f"budget {self.budget!r} s is not a whole number of time steps of "
                f"{self.time_step:g} s (use e.g. {round(steps) * self.time_step:g})"
            )
        if round(steps) > MAX_STEPS:
            raise ValueError(
                f"budget {self.budget:g} s is {round(steps):,} steps of "
                f"{self.time_step:g} s; at most {MAX_STEPS:,} steps are supported "
                "(use a larger time_step or a shorter budget)"
            )
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
        with np.errstate(all="ignore"):
            _, covs = self.motion_model().predict(
                self.means(), self.covariances(), self.process_noise(), self.budget
            )
            logdets = position_logdet(covs)
        for i, value in enumerate(logdets):
            if not math.isfinite(value) or not np.all(np.isfinite(covs[i])):
                raise ValueError(
                    f"targets.{i}.covariance: the position log det is not finite "
                    f"by the end of the budget ({value}); use smaller variances "
                    "or process noise"
                )
        return self

    # --- arrays for the library -------------------------------------------------------------
    @property
    def target_ids(self) -> tuple[str, ...]:
        return tuple(t.id for t in self.targets)

    @property
    def n_steps(self) -> int:
        """Simulation steps in the budget."""
        return round(self.budget / self.time_step)

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
        return PositionMeasurementModel(self.agent.noise_covariance(), self.agent.sensor_diameter)

    def mission_spec(self) -> MissionSpec:
        """The static facts a planner may use."""
        return MissionSpec(
            time_step=self.time_step,
            budget=self.budget,
            agent_speed=self.agent.speed,
            sensor_diameter=self.agent.sensor_diameter,
            measurement_noise=self.agent.noise_covariance(),
            process_noise_form=self.process_noise_form,
            process_noise=self.process_noise(),
            target_ids=self.target_ids,
        )

    def initial_observation(self) -> Observation:
        """What a planner sees at the start, before any measurement: time 0, the agent at its
        start position, the prior beliefs, nothing detected (pass it with :meth:`mission_spec`
        to :func:`hptrack.plan` or a planner's ``reset``)."""
        arrays = [
            np.array(self.agent.position, dtype=float),
            self.means(),
            self.covariances(),
            np.zeros(len(self.targets), dtype=bool),
        ]
        for a in arrays:
            a.flags.writeable = False
        return Observation(0, 0.0, float(self.budget), *arrays)

    def never_observed_uncertainty(self) -> float:
        """``U`` of a mission that measures nothing: every prior grown to the budget's end."""
        _, covs = self.motion_model().predict(
            self.means(), self.covariances(), self.process_noise(), self.n_steps * self.time_step
        )
        return float(position_logdet(covs).sum())

    def with_seed(self, seed: int) -> Scenario:
        """The same scenario driven by another seed."""
        return self.model_copy(update={"seed": seed})
