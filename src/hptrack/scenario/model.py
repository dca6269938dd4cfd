"""Validated scenario model: the file boundary of every mission (``docs/model.md``).

A scenario fixes the time step, the budget, the agent, and each target's prior belief (mean,
covariance), process noise ``q`` and, optionally, its true initial state. Every number is
checked before any work starts: a real number (a boolean or a text such as ``"0.5"`` is not),
finite, inside a sane range; covariances symmetric positive definite, eigenvalues at least
`MIN_VARIANCE` and within 1e12 of each other, position variances (prior and at the
budget's end) within what the Kalman update handles (`MAX_UPDATE_RATIO`) and the area
(`MAX_POSITION_VARIANCE`); the budget a whole number of time steps and at most
`MAX_STEPS` of them; target ids unique and printable; every target's mean speed below the
agent's (the coverage planner of Sec. IV-A needs ``v_a > |v_hat|``); mean and true paths inside
the 10,000 km area for the whole budget. Errors name the field and the value.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal, Self

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    field_validator,
    model_validator,
)

from hptrack.interface import MissionSpec, Observation, TeamMember
from hptrack.models.belief_motion import (
    BeliefMotion,
    ConstantAccelerationMotion,
    ConstantVelocity,
    OrnsteinUhlenbeckMotion,
    RandomWalkMotion,
    SingerMotion,
    extended_prior,
)
from hptrack.models.beliefs import position_logdet
from hptrack.models.fence import CIRCLE_SIDES, FenceSpec, in_sight, point_free, sight_gap
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.mission import MAX_TARGETS, steps_left
from hptrack.models.motion import ProcessNoiseForm
from hptrack.models.sensor import certain, detection_table
from hptrack.models.state import positions, speeds, velocities
from hptrack.models.truth_motion import (
    ConstantAccelerationTruth,
    ConstantVelocityTruth,
    CoordinatedTurn,
    OrnsteinUhlenbeck,
    RandomWalk,
    SingerTruth,
)

MAX_STEPS = 1_000_000
"""Most simulation steps a mission may have (``budget / time_step``)."""
MAX_COORDINATE_M = 1e7
"""Largest absolute position coordinate, m (10,000 km)."""
MIN_POSITION_CONDITION = 1e-12
"""Smallest ratio of the position covariance's eigenvalues (a flatter ellipse is degenerate)."""
MIN_VARIANCE = 1e-12
"""Smallest eigenvalue of a prior covariance, m^2 or (m/s)^2: a smaller one is a point mass
whose ``log det`` is -inf (the score of a known target is not defined)."""
MAX_POSITION_VARIANCE = MAX_COORDINATE_M**2
"""Largest position variance of a belief up to the budget's end, m^2: a standard deviation
beyond the 10,000 km area carries no information."""
MAX_UPDATE_RATIO = 1e13
"""Largest ratio of a position variance (prior or predicted to the budget's end) to ``R``'s
smallest eigenvalue: the Kalman update ``(I - K) P`` loses about ``ratio * 2e-16`` of its
relative precision and gives negative variances from about 1e15."""
MAX_TRUE_SPEED = 1e4
"""Largest true target speed, m/s (10 km/s, above orbital speed)."""


def _not_bool(value: Any) -> Any:
    if isinstance(value, bool):
        raise ValueError(f"expected a number, got the boolean {value}")
    return value


def _printable(value: str) -> str:
    if not value.isprintable():
        raise ValueError("must be printable text (no control characters or terminal escapes)")
    return value


Real = Annotated[float, BeforeValidator(_not_bool), Strict()]
"""A number written as a number: no boolean and no text (``"0.5"`` is refused)."""
Coordinate = Annotated[Real, Field(ge=-MAX_COORDINATE_M, le=MAX_COORDINATE_M)]
Vector2 = tuple[Coordinate, Coordinate]
Vector4 = tuple[Real, Real, Real, Real]
Matrix2 = tuple[tuple[Real, Real], tuple[Real, Real]]
Matrix4 = tuple[Vector4, Vector4, Vector4, Vector4]

_STRICT = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


Speed = Annotated[Real, Field(ge=0.1, le=1000.0)]
"""The vehicle's speed ``v_a``, m/s."""
Diameter = Annotated[Real, Field(ge=0.01, le=1e5)]
"""The footprint's diameter ``w``, m."""
NoiseStd = Annotated[Real, Field(ge=1e-6, le=1e4)]
"""The measurement noise per axis, m (``R = std^2 I``)."""
DEFAULT_SPEED = 30.0
DEFAULT_DIAMETER = 100.0
DEFAULT_NOISE_STD = float(np.sqrt(10.0))
MAX_DETECTION_CORRELATION_TIME = 3600.0
"""Longest ``detection_correlation_time``, s (an hour: longer holds a draw for a whole pass
anyway)."""
MAX_FALSE_ALARM_DENSITY = 1e-2
"""Largest ``false_alarm_density``, per m^2 per look (one false alarm per 100 m^2)."""
Count = Annotated[int, Strict(), Field(ge=1, le=100)]
"""A whole number of looks (a confirmation rule's M or N)."""
DEFAULT_CONFIRMATION = (3, 5)
"""The default M-of-N confirmation rule of a tentative track."""
NOISE_FIELDS = ("measurement_noise_std", "measurement_noise_covariance")
"""The fields that give ``R`` (the covariance, when given, takes precedence)."""


def _check_noise_covariance(value: Matrix2 | None) -> None:
    """Refuse an ``R`` that is not symmetric positive definite within (1e-12, 1e8] m^2."""
    if value is not None:
        r = np.asarray(value, dtype=float)
        if abs(r[0, 1] - r[1, 0]) > 1e-9 * max(float(np.max(np.abs(r))), 1.0):
            raise ValueError(f"measurement_noise_covariance is not symmetric: {r.tolist()}")
        eig = np.linalg.eigvalsh(r)
        if eig[0] <= 1e-12 or eig[1] > 1e8:
            raise ValueError(
                "measurement_noise_covariance must be positive definite with "
                f"eigenvalues in (1e-12, 1e8] m^2, got {r.tolist()}"
            )


def _noise_of(std: float, covariance: Matrix2 | None) -> np.ndarray:
    """``R`` (2x2), m^2: ``covariance`` if given, else ``std^2 I``."""
    if covariance is not None:
        return np.array(covariance, dtype=float)
    return std**2 * np.eye(2)


class AgentSpec(BaseModel):
    """The UAV: start ``position`` (m), ``speed`` ``v_a`` (m/s), footprint ``sensor_diameter``
    ``w`` (m), and the measurement noise: ``measurement_noise_std`` per axis (m; ``R = std^2
    I``) or a full 2x2 ``measurement_noise_covariance`` (m^2), which takes precedence. The
    speed is the vehicle's and the rest the sensor's: the ``vehicle:`` and ``sensor:`` blocks
    of a scenario may give them instead (`VehicleSpec`, `SensorSpec`)."""

    model_config = _STRICT

    position: Vector2 = (0.0, 0.0)
    speed: Speed = DEFAULT_SPEED
    sensor_diameter: Diameter = DEFAULT_DIAMETER
    measurement_noise_std: NoiseStd = DEFAULT_NOISE_STD
    measurement_noise_covariance: Matrix2 | None = None

    @model_validator(mode="after")
    def _noise(self) -> Self:
        _check_noise_covariance(self.measurement_noise_covariance)
        return self

    def noise_covariance(self) -> np.ndarray:
        """``R`` (2x2), m^2."""
        return _noise_of(self.measurement_noise_std, self.measurement_noise_covariance)


def _detection_probability(value: Any) -> float | tuple[tuple[float, float], ...]:
    """A ``detection_probability`` as a float or a tuple of ``(distance_m, Pd)`` rows
    (`hptrack.models.sensor.detection_table` checks it)."""
    distances, probabilities = detection_table(value)
    if isinstance(value, int | float):
        return float(probabilities[0])
    return tuple((float(d), float(p)) for d, p in zip(distances, probabilities, strict=True))


DetectionProbability = Annotated[
    float | tuple[tuple[float, float], ...], BeforeValidator(_detection_probability)
]
"""The chance that a look detects a target inside the footprint: a number in ``(0, 1]`` or a
table of rows ``[distance from the footprint's centre (m), Pd]``."""


class FootprintSensorSpec(BaseModel):
    """The paper's sensor (`hptrack.models.sensor.FootprintSensor`): a footprint of
    ``diameter`` ``w`` (m) that measures every target inside it, with the noise
    ``measurement_noise_std`` per axis (m; ``R = std^2 I``) or a full 2x2
    ``measurement_noise_covariance`` (m^2), which takes precedence.

    ``detection_probability`` (default 1, the paper's): the chance that a look detects (and so
    measures) a target inside the footprint, independently at each look: a number in ``(0, 1]``
    or a table of rows ``[distance from the footprint's centre (m), Pd]``, distances strictly
    increasing from 0, ``Pd`` in ``[0, 1]``, linear between rows and the last value held to the
    footprint's edge (`hptrack.models.sensor.DetectingFootprintSensor`).
    ``detection_correlation_time`` (s, default 0: independent looks): a look's draw holds for
    the looks within this time of the first while the target stays in the footprint, so that
    misses come in runs, as a camera's do when a target is hidden or misclassified for a while;
    only with ``detection_probability`` below 1 and without ``negative_information``.

    ``negative_information`` (default false, the paper's): a look that detects nothing updates
    the beliefs of the targets it could have seen (`hptrack.models.miss_update`), in the
    simulator, the flight controller and the planner's sub-task model.

    Detections without identity (`hptrack.models.detector`, `hptrack.models.tracking`):
    ``labelled`` (default true, the paper's: every detection names its target); false: a look
    reports positions only, and the simulator's tracker associates them with the beliefs by
    ``association`` (``gnn`` or ``jpda``), a detection that no belief claims becoming a
    tentative track that claims a target once it is detected at ``confirmation = [M, N]`` (M of
    its first N looks). ``false_alarm_density``: false detections per m^2 per look inside the
    footprint (a Poisson count, uniform positions; default 0), only with ``labelled: false``."""

    model_config = _STRICT

    model: Literal["footprint"] = "footprint"
    diameter: Diameter = DEFAULT_DIAMETER
    measurement_noise_std: NoiseStd = DEFAULT_NOISE_STD
    measurement_noise_covariance: Matrix2 | None = None
    detection_probability: DetectionProbability = 1.0
    negative_information: Annotated[bool, Strict()] = False
    detection_correlation_time: Annotated[
        Real, Field(ge=0.0, le=MAX_DETECTION_CORRELATION_TIME)
    ] = 0.0
    false_alarm_density: Annotated[Real, Field(ge=0.0, le=MAX_FALSE_ALARM_DENSITY)] = 0.0
    labelled: Annotated[bool, Strict()] = True
    association: Literal["gnn", "jpda"] = "gnn"
    confirmation: tuple[Count, Count] = DEFAULT_CONFIRMATION

    @model_validator(mode="after")
    def _noise(self) -> Self:
        _check_noise_covariance(self.measurement_noise_covariance)
        return self

    @model_validator(mode="after")
    def _identity(self) -> Self:
        if self.false_alarm_density > 0.0 and self.labelled:
            raise ValueError(
                f"false_alarm_density {self.false_alarm_density:g} per m^2 needs labelled: false "
                "(a false alarm names no target)"
            )
        if self.negative_information and not self.labelled:
            raise ValueError(
                "negative_information needs labelled: true (the tracker of detections without "
                "identity does not update on misses)"
            )
        if self.detection_correlation_time > 0.0:
            if certain(self.detection_probability):
                raise ValueError(
                    f"detection_correlation_time {self.detection_correlation_time:g} s needs a "
                    "detection_probability below 1 (a sensor that always detects has no misses "
                    "to correlate)"
                )
            if self.negative_information:
                raise ValueError(
                    "negative_information needs detection_correlation_time 0 (its update "
                    "takes each look as independent evidence)"
                )
        m, n = self.confirmation
        if m > n:
            raise ValueError(f"confirmation [M, N] needs M <= N, value [{m}, {n}]")
        return self

    def noise_covariance(self) -> np.ndarray:
        """``R`` (2x2), m^2."""
        return _noise_of(self.measurement_noise_std, self.measurement_noise_covariance)


class HolonomicVehicleSpec(BaseModel):
    """The paper's vehicle (`hptrack.models.vehicle.HolonomicVehicle`): a point that flies
    straight at up to ``speed`` ``v_a`` (m/s) in any direction."""

    model_config = _STRICT

    model: Literal["holonomic"] = "holonomic"
    speed: Speed = DEFAULT_SPEED


SensorSpec = FootprintSensorSpec
"""Which sensor (`hptrack.models.sensor`), by ``model`` (a second model makes this a union
discriminated by ``model``, as `TruthMotionSpec`)."""
VehicleSpec = HolonomicVehicleSpec
"""Which vehicle (`hptrack.models.vehicle`), by ``model`` (as `SensorSpec`)."""


MAX_FENCE_CORNERS = 512
"""Most corners of a fence's polygons together, a circle counting as its
`hptrack.models.fence.CIRCLE_SIDES` (the visibility graph grows with their cube)."""


class PolygonZoneSpec(BaseModel):
    """A polygon of a ``fence:`` block: its corners ``[x, y]`` (m), a simple polygon."""

    model_config = _STRICT

    polygon: Annotated[list[Vector2], Field(min_length=3, max_length=MAX_FENCE_CORNERS)]


class CircleZoneSpec(BaseModel):
    """A circular no-fly zone of a ``fence:`` block: ``[x, y, radius]`` (m)."""

    model_config = _STRICT

    circle: tuple[Coordinate, Coordinate, Annotated[Real, Field(gt=0.0, le=1e6)]]


class FenceBlockSpec(BaseModel):
    """Where the UAV may fly (`hptrack.models.fence`): an optional operating area
    ``inclusion`` (a polygon), no-fly ``exclusions`` (polygons and circles) and a ``margin``
    (m) the UAV keeps from every boundary. Targets may drive anywhere; only the UAV is
    fenced."""

    model_config = _STRICT

    inclusion: PolygonZoneSpec | None = None
    exclusions: Annotated[list[PolygonZoneSpec | CircleZoneSpec], Field(max_length=64)] = []
    margin: Annotated[Real, Field(ge=0.0, le=1e4)] = 0.0

    @model_validator(mode="after")
    def _corners(self) -> Self:
        corners = len(self.inclusion.polygon) if self.inclusion else 0
        corners += sum(
            len(z.polygon) if isinstance(z, PolygonZoneSpec) else CIRCLE_SIDES
            for z in self.exclusions
        )
        if corners > MAX_FENCE_CORNERS:
            raise ValueError(
                f"the fence has {corners} corners (a circle counts {CIRCLE_SIDES}); at most "
                f"{MAX_FENCE_CORNERS}"
            )
        return self

    def spec(self) -> FenceSpec:
        """The fence as plain data (`hptrack.models.fence.FenceSpec`)."""
        return FenceSpec(
            inclusion=tuple(self.inclusion.polygon) if self.inclusion else None,
            polygons=tuple(
                tuple(z.polygon) for z in self.exclusions if isinstance(z, PolygonZoneSpec)
            ),
            circles=tuple(z.circle for z in self.exclusions if isinstance(z, CircleZoneSpec)),
            margin=self.margin,
        )


class TargetSpec(BaseModel):
    """One target: prior ``mean`` [x, y, vx, vy] (m, m/s), 4x4 ``covariance``, process noise
    ``q`` (m^2/s^3) and optionally its true initial state ``truth``."""

    model_config = _STRICT

    id: Annotated[str, Strict(), Field(min_length=1, max_length=200), AfterValidator(_printable)]
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
        if eig[0] < MIN_VARIANCE:
            raise ValueError(
                f"covariance has an eigenvalue of {eig[0]:.3g}, below {MIN_VARIANCE:g}: a point "
                "mass whose log det is -inf"
            )
        if eig[0] < MIN_POSITION_CONDITION * eig[-1]:
            raise ValueError(
                f"covariance eigenvalues {eig[0]:.3g} to {eig[-1]:.3g} span more than 1e12 "
                "(its smallest is lost in rounding)"
            )
        pos = np.linalg.eigvalsh(cov[:2, :2])
        if pos[0] < MIN_POSITION_CONDITION * pos[1]:
            raise ValueError(
                f"the position block {cov[:2, :2].tolist()} is degenerate (its "
                "ellipse is flatter than 1e-12)"
            )
        return value


class ConstantVelocitySpec(BaseModel):
    """The paper's constant velocity (the default), with the scenario's
    ``process_noise_form``."""

    model_config = _STRICT
    state_size: ClassVar[int] = 4

    model: Literal["constant_velocity"] = "constant_velocity"

    def build(self, n_targets: int, rng: np.random.Generator) -> tuple:
        return ConstantVelocityTruth()

    def belief(self, time_step: float, process_noise_form: ProcessNoiseForm) -> tuple:
        return ConstantVelocity(time_step if process_noise_form == "continuous" else 1.0)


class CoordinatedTurnSpec(BaseModel):
    """Targets that turn at a constant rate each: ``turn_rate`` rad/s (counter-clockwise
    positive), or, with ``turn_rate_sd`` rad/s, a rate per target drawn once from
    ``N(turn_rate, turn_rate_sd^2)``; the constant-velocity noise is kept."""

    model_config = _STRICT
    state_size: ClassVar[int] = 4

    model: Literal["coordinated_turn"]
    turn_rate: Annotated[Real, Field(ge=-1.0, le=1.0)] = 0.02
    turn_rate_sd: Annotated[Real, Field(ge=0.0, le=1.0)] = 0.0

    def build(self, n_targets: int, rng: np.random.Generator) -> tuple:
        rates = np.full(n_targets, float(self.turn_rate))
        if self.turn_rate_sd > 0.0:
            rates = rates + self.turn_rate_sd * rng.standard_normal(n_targets)
        return CoordinatedTurn(np.ascontiguousarray(rates))


class RandomWalkSpec(BaseModel):
    """Targets whose position diffuses by ``diffusion`` m^2/s per axis, with no velocity."""

    model_config = _STRICT
    state_size: ClassVar[int] = 4

    model: Literal["random_walk"]
    diffusion: Annotated[Real, Field(gt=0.0, le=1e6)] = 5.0

    def build(self, n_targets: int, rng: np.random.Generator) -> tuple:
        return RandomWalk(float(self.diffusion))

    def belief(self, time_step: float, process_noise_form: ProcessNoiseForm) -> tuple:
        return RandomWalkMotion(float(self.diffusion))


class OrnsteinUhlenbeckSpec(BaseModel):
    """Targets whose velocity decays at ``damping`` 1/s (at least 1e-3, a time constant of at
    most 1000 s) while driven by their ``process_noise``."""

    model_config = _STRICT
    state_size: ClassVar[int] = 4

    model: Literal["ornstein_uhlenbeck"]
    damping: Annotated[Real, Field(ge=1e-3, le=10.0)] = 0.01

    def build(self, n_targets: int, rng: np.random.Generator) -> tuple:
        return OrnsteinUhlenbeck(float(self.damping))

    def belief(self, time_step: float, process_noise_form: ProcessNoiseForm) -> tuple:
        return OrnsteinUhlenbeckMotion(float(self.damping))


class SingerSpec(BaseModel):
    """Targets whose acceleration decays at ``damping`` 1/s (a manoeuvre time of ``1 /
    damping`` s) while driven so that its stationary spread is ``acceleration_std`` m/s^2 per
    axis (Singer's model); the state gains ``[ax, ay]``, drawn at the start from
    ``N(0, acceleration_std^2)``. The targets' ``process_noise`` is not used."""

    model_config = _STRICT
    state_size: ClassVar[int] = 6

    model: Literal["singer"]
    damping: Annotated[Real, Field(ge=1e-4, le=10.0)] = 0.02
    acceleration_std: Annotated[Real, Field(gt=0.0, le=10.0)] = 0.002

    def build(self, n_targets: int, rng: np.random.Generator) -> tuple:
        return SingerTruth(float(self.damping), float(self.acceleration_std))

    def belief(self, time_step: float, process_noise_form: ProcessNoiseForm) -> tuple:
        return SingerMotion(float(self.damping), float(self.acceleration_std))


class ConstantAccelerationSpec(BaseModel):
    """Targets that keep their acceleration, changed by a white jerk of ``jerk_intensity``
    m^2/s^5 per axis; the state gains ``[ax, ay]``, drawn at the start from
    ``N(0, acceleration_std^2)``. The targets' ``process_noise`` is not used."""

    model_config = _STRICT
    state_size: ClassVar[int] = 6

    model: Literal["constant_acceleration"]
    jerk_intensity: Annotated[Real, Field(ge=0.0, le=1.0)] = 1e-8
    acceleration_std: Annotated[Real, Field(gt=0.0, le=10.0)] = 0.001

    def build(self, n_targets: int, rng: np.random.Generator) -> tuple:
        return ConstantAccelerationTruth(float(self.jerk_intensity), float(self.acceleration_std))

    def belief(self, time_step: float, process_noise_form: ProcessNoiseForm) -> tuple:
        return ConstantAccelerationMotion(float(self.jerk_intensity), float(self.acceleration_std))


TruthMotionSpec = Annotated[
    ConstantVelocitySpec
    | CoordinatedTurnSpec
    | RandomWalkSpec
    | OrnsteinUhlenbeckSpec
    | SingerSpec
    | ConstantAccelerationSpec,
    Field(discriminator="model"),
]
"""How the simulated targets truly move (`hptrack.models.truth_motion`), by ``model``; each
spec's ``build(n_targets, rng)`` gives the part it stands for (random parameters drawn from
``rng``)."""

MotionSpec = Annotated[
    ConstantVelocitySpec
    | RandomWalkSpec
    | OrnsteinUhlenbeckSpec
    | SingerSpec
    | ConstantAccelerationSpec,
    Field(discriminator="model"),
]
"""How the beliefs assume the targets move (`hptrack.models.belief_motion`), by ``model``, with
the parameters of the truth motion of the same name; each spec's ``belief(time_step,
process_noise_form)`` gives the mission record's motion part. Without a ``truth_motion`` the
simulated targets move by the same model."""


MAX_AGENTS = 16
"""Most UAVs in a team (``agents:``)."""


class Scenario(BaseModel):
    """A whole mission. ``seed`` drives the true initial states (when not given) and all noise.

    ``agent`` is the one UAV; ``agents``, a list of the same blocks, is a team (each UAV with
    its own start, speed, footprint and noise; the ``sensor:`` and ``vehicle:`` blocks are
    shared by all). Give one or the other; `team` is the list either way."""

    model_config = _STRICT

    time_step: Annotated[Real, Field(ge=1e-3, le=60.0)] = 0.5
    budget: Annotated[Real, Field(gt=0.0)] = 900.0
    seed: Annotated[int, BeforeValidator(_not_bool), Strict(), Field(ge=0, lt=2**63)] = 0
    process_noise_form: ProcessNoiseForm = "continuous"
    motion: MotionSpec | None = None
    truth_motion: TruthMotionSpec | None = None
    agent: AgentSpec = AgentSpec()
    agents: Annotated[list[AgentSpec], Field(min_length=1, max_length=MAX_AGENTS)] | None = None
    sensor: SensorSpec | None = None
    vehicle: VehicleSpec | None = None
    fence: FenceBlockSpec | None = None
    targets: Annotated[list[TargetSpec], Field(min_length=1, max_length=MAX_TARGETS)]

    @property
    def team(self) -> list[AgentSpec]:
        """The UAVs flown: ``agents``, or the one ``agent``."""
        return [self.agent] if self.agents is None else list(self.agents)

    @property
    def n_vehicles(self) -> int:
        """``m``, the UAVs flown."""
        return len(self.team)

    def _check_team(self) -> None:
        """Refuse ``agent:`` beside ``agents:``, and a team without identity whose sensors
        differ (one tracker keeps the beliefs of every UAV's looks)."""
        if self.agents is None:
            return
        if self.agent != AgentSpec():
            raise ValueError(
                "give agent (one UAV) or agents (a team), not both: agent is "
                f"{self.agent.model_dump(exclude_defaults=True)}"
            )
        sensors = {(s.diameter, s.noise_covariance().tobytes()) for s in self._sensors()}
        if not self.sensor_spec().labelled and len(sensors) > 1:
            raise ValueError(
                "sensor.labelled false needs every UAV of agents with the same sensor_diameter "
                "and measurement noise (one tracker keeps the beliefs)"
            )

    def _sensors(self) -> list[FootprintSensorSpec]:
        return [self.sensor_spec(j) for j in range(self.n_vehicles)]

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        self._check_team()
        model = self.motion_spec.model
        if self.process_noise_form != "continuous" and model != "constant_velocity":
            raise ValueError(
                f"process_noise_form {self.process_noise_form!r} is a form of constant "
                f"velocity's Q; motion.model is {model!r}"
            )
        self._check_world_given_once()
        steps = self.budget / self.time_step
        if self.budget < self.time_step:
            raise ValueError(
                f"budget {self.budget:g} s is shorter than time_step {self.time_step:g} s"
            )
        if steps > MAX_STEPS + 0.5:  # also infinite: 1e308 s over 0.5 s
            count = (
                "infinitely many"
                if math.isinf(steps)
                else f"{steps:,.0f}"
                if steps < 1e15
                else f"{steps:.3g}"
            )
            raise ValueError(
                f"budget {self.budget:g} s is {count} steps of "
                f"{self.time_step:g} s; at most {MAX_STEPS:,} steps are supported "
                "(use a larger time_step or a shorter budget)"
            )
        if abs(steps - round(steps)) > 1e-9 * max(steps, 1.0):
            raise ValueError(
                f"budget {self.budget!r} s is not a whole number of time steps of "
                f"{self.time_step:g} s (use e.g. {round(steps) * self.time_step:g})"
            )
        seen: set[str] = set()
        for i, target in enumerate(self.targets):
            if target.id in seen:
                raise ValueError(f"targets.{i}.id: duplicate target id {target.id!r}")
            seen.add(target.id)
            speed = float(speeds(np.array(target.mean)))
            slowest = min(range(self.n_vehicles), key=lambda j: self.vehicle_spec(j).speed)
            if speed >= self.vehicle_spec(slowest).speed:
                raise ValueError(
                    f"targets.{i}.mean: target {target.id!r} mean speed {speed:g} m/s is not "
                    f"below {self._speed_field(slowest)} {self.vehicle_spec(slowest).speed:g} m/s"
                )
            self._check_drift(i, "mean", target.mean)
            if target.truth is not None:
                true_speed = float(speeds(np.array(target.truth)))
                if true_speed > MAX_TRUE_SPEED:
                    raise ValueError(
                        f"targets.{i}.truth: speed {true_speed:.3g} m/s is above "
                        f"{MAX_TRUE_SPEED:g} m/s"
                    )
                self._check_drift(i, "truth", target.truth)
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
        self._check_variances(self.covariances(), "")
        self._check_variances(covs, " by the end of the budget")
        self._check_fence()
        return self

    def _check_fence(self) -> None:
        """Refuse a fence whose polygons are not simple, that leaves no free space, the start
        outside it, or a target's prior mean out of the UAV's sight (farther than the
        footprint's radius from every free point it can fly to)."""
        if self.fence is None:
            return
        try:
            fence = self.fence.spec().compiled()
        except ValueError as err:
            raise ValueError(f"fence: {err}") from None
        for j, agent in enumerate(self.team):
            x, y = agent.position
            if not point_free(fence, x, y):
                raise ValueError(
                    f"{self._agent_field(j)}.position ({x:g}, {y:g}) m is not where the fence "
                    "lets the UAV fly (in a no-fly zone, outside the operating area or within "
                    "the margin)"
                )
        x, y = self.team[0].position
        radius = 0.5 * self.sensor_spec().diameter
        for i, target in enumerate(self.targets):
            mean = target.mean[:2]
            if not in_sight(fence, (x, y), mean, radius):
                raise ValueError(
                    f"targets.{i}.mean: target {target.id!r} at ({mean[0]:g}, {mean[1]:g}) m is "
                    f"out of the UAV's sight: {sight_gap(fence, (x, y), mean):.3g} m from the "
                    f"nearest point it may fly to and reach, beyond the footprint's radius "
                    f"{radius:g} m"
                )

    def _agent_field(self, j: int) -> str:
        """Where UAV ``j`` is written: ``agent`` or ``agents.j``."""
        return "agent" if self.agents is None else f"agents.{j}"

    def _speed_field(self, j: int = 0) -> str:
        """Where UAV ``j``'s speed is written: ``vehicle.speed`` or its block's ``speed``."""
        given = self.vehicle is not None and "speed" in self.vehicle.model_fields_set
        return "vehicle.speed" if given else f"{self._agent_field(j)}.speed"

    def _check_world_given_once(self) -> None:
        """Refuse a fact that an ``agent:`` (or ``agents:``) block and the ``sensor:`` or
        ``vehicle:`` block give with different values (the blocks are the newer spelling of
        the agent's)."""
        for j, agent_spec in enumerate(self.team):
            self._check_given_once(self._agent_field(j), agent_spec)

    def _check_given_once(self, where: str, agent_spec: AgentSpec) -> None:
        agent = agent_spec.model_fields_set
        if self.vehicle is not None and {"speed"} <= agent & self.vehicle.model_fields_set:
            if self.vehicle.speed != agent_spec.speed:
                raise ValueError(
                    f"vehicle.speed {self.vehicle.speed:g} m/s and {where}.speed "
                    f"{agent_spec.speed:g} m/s disagree: give the speed once (vehicle.speed)"
                )
        if self.sensor is None:
            return
        given = self.sensor.model_fields_set
        if "diameter" in given and "sensor_diameter" in agent:
            if self.sensor.diameter != agent_spec.sensor_diameter:
                raise ValueError(
                    f"sensor.diameter {self.sensor.diameter:g} m and {where}.sensor_diameter "
                    f"{agent_spec.sensor_diameter:g} m disagree: give the diameter once "
                    "(sensor.diameter)"
                )
        if given & set(NOISE_FIELDS) and agent & set(NOISE_FIELDS):
            ours, theirs = self.sensor.noise_covariance(), agent_spec.noise_covariance()
            if not np.array_equal(ours, theirs):
                raise ValueError(
                    f"the sensor's R {ours.tolist()} m^2 and the {where}'s R {theirs.tolist()} "
                    "m^2 disagree: give the measurement noise once (sensor.measurement_noise_std "
                    "or sensor.measurement_noise_covariance)"
                )

    def vehicle_spec(self, j: int = 0) -> HolonomicVehicleSpec:
        """The vehicle UAV ``j`` flies: the ``vehicle:`` block, with its ``agent`` block's
        speed where the block gives no speed (the default: the paper's holonomic point at
        30 m/s)."""
        vehicle = self.vehicle or HolonomicVehicleSpec()
        if "speed" in vehicle.model_fields_set:
            return vehicle
        return vehicle.model_copy(update={"speed": self.team[j].speed})

    def sensor_spec(self, j: int = 0) -> FootprintSensorSpec:
        """The sensor UAV ``j`` flies: the ``sensor:`` block, with its ``agent`` block's
        diameter and noise where the block gives none (the default: the paper's 100 m
        footprint, ``R = 10 I``)."""
        agent = self.team[j]
        sensor = self.sensor or FootprintSensorSpec()
        given, update = sensor.model_fields_set, {}
        if "diameter" not in given:
            update["diameter"] = agent.sensor_diameter
        if not given & set(NOISE_FIELDS):
            update |= {name: getattr(agent, name) for name in NOISE_FIELDS}
        return sensor.model_copy(update=update) if update else sensor

    def _check_drift(self, i: int, field: str, state: tuple[float, ...]) -> None:
        """Refuse a state whose constant-velocity path leaves the 10,000 km area in the
        budget."""
        array = np.array(state, dtype=float)
        position, velocity = positions(array).tolist(), velocities(array).tolist()
        for axis in (0, 1):
            end = position[axis] + velocity[axis] * self.budget
            if abs(end) > MAX_COORDINATE_M:
                raise ValueError(
                    f"targets.{i}.{field}: at {velocity[axis]:.3g} m/s the target is at "
                    f"{end:.3g} m by the end of the budget, beyond the "
                    f"{MAX_COORDINATE_M:g} m area"
                )

    def _check_variances(self, covs: np.ndarray, when: str) -> None:
        """Refuse position variances the Kalman update cannot handle (`MAX_UPDATE_RATIO`)
        or wider than the area (`MAX_POSITION_VARIANCE`)."""
        r_min = min(float(np.linalg.eigvalsh(s.noise_covariance())[0]) for s in self._sensors())
        limit = min(MAX_POSITION_VARIANCE, MAX_UPDATE_RATIO * r_min)
        largest = np.linalg.eigvalsh(covs[:, :2, :2])[:, -1]
        for i, value in enumerate(largest):
            if value > limit:
                raise ValueError(
                    f"targets.{i}.covariance: a position variance of {value:.3g} m^2{when} is "
                    f"above {limit:.3g} m^2 (the area's {MAX_POSITION_VARIANCE:g} m^2, or "
                    f"{MAX_UPDATE_RATIO:g} times R's smallest eigenvalue {r_min:.3g} m^2, "
                    "beyond which the Kalman update loses its precision)"
                )

    # --- arrays for the library -------------------------------------------------------------
    @property
    def target_ids(self) -> tuple[str, ...]:
        return tuple(t.id for t in self.targets)

    @property
    def n_steps(self) -> int:
        """Simulation steps in the budget (`hptrack.models.mission.steps_left`)."""
        return steps_left(self.time_step, self.budget)

    def means(self) -> np.ndarray:
        """Prior means ``(n, d)``: the file's ``[x, y, vx, vy]``, with zero accelerations
        under a motion that has them (``d = 6``)."""
        return self._priors()[0]

    def covariances(self) -> np.ndarray:
        """Prior covariances ``(n, d, d)``: the file's, with the motion's
        ``acceleration_std^2`` block under a motion that has accelerations."""
        return self._priors()[1]

    def _priors(self) -> tuple[np.ndarray, np.ndarray]:
        means = np.array([t.mean for t in self.targets], dtype=float).reshape(-1, 4)
        covs = np.array([t.covariance for t in self.targets], dtype=float).reshape(-1, 4, 4)
        return extended_prior(self.motion_part(), means, covs)

    @property
    def truth_spec(self) -> TruthMotionSpec:
        """How the simulated targets truly move: ``truth_motion``, else ``motion``'s model."""
        return self.truth_motion or self.motion_spec

    def process_noise(self) -> np.ndarray:
        """Noise intensities ``q`` ``(n,)``."""
        return np.array([t.process_noise for t in self.targets], dtype=float)

    @property
    def motion_spec(self) -> MotionSpec:
        """``motion``, constant velocity when not given."""
        return self.motion or ConstantVelocitySpec()

    def motion_part(self) -> tuple:
        """The beliefs' motion, the mission record's part (`hptrack.models.belief_motion`)."""
        return self.motion_spec.belief(self.time_step, self.process_noise_form)

    def motion_model(self) -> BeliefMotion:
        """The beliefs' motion (its numpy face)."""
        return BeliefMotion(self.time_step, self.motion_part())

    def truth_motion_model(self, rng: np.random.Generator) -> tuple:
        """The simulator's truth motion (`hptrack.models.truth_motion`; by default the model of
        ``motion``); a coordinated turn with ``turn_rate_sd > 0`` draws its rates from ``rng``
        (nothing is drawn otherwise)."""
        return self.truth_spec.build(len(self.targets), rng)

    def sensor_model(self) -> PositionMeasurementModel:
        sensor = self.sensor_spec()
        return PositionMeasurementModel(sensor.noise_covariance(), sensor.diameter)

    def mission_spec(self) -> MissionSpec:
        """The static facts a planner may use (a team's: each UAV's speed and sensor in
        ``members``, the first UAV's also in the one-vehicle fields)."""
        members = tuple(
            TeamMember(
                self.vehicle_spec(j).speed,
                self.sensor_spec(j).diameter,
                self.sensor_spec(j).noise_covariance(),
            )
            for j in range(self.n_vehicles)
        )
        return MissionSpec(
            time_step=self.time_step,
            budget=self.budget,
            agent_speed=self.vehicle_spec().speed,
            sensor_diameter=self.sensor_spec().diameter,
            measurement_noise=self.sensor_spec().noise_covariance(),
            process_noise_form=self.process_noise_form,
            process_noise=self.process_noise(),
            target_ids=self.target_ids,
            belief_motion=self.motion_part(),
            detection_probability=self.sensor_spec().detection_probability,
            fence=self.fence.spec() if self.fence else None,
            negative_information=self.sensor_spec().negative_information,
            members=members if self.n_vehicles > 1 else (),
            detection_correlation_time=self.sensor_spec().detection_correlation_time,
            false_alarm_density=self.sensor_spec().false_alarm_density,
        )

    def initial_observation(self) -> Observation:
        """What a planner sees at the start, before any measurement: time 0, the agent at its
        start position, the prior beliefs, nothing detected (pass it with `mission_spec`
        to `hptrack.plan` or a planner's ``reset``)."""
        arrays = [
            self.starts(),
            self.means(),
            self.covariances(),
            np.zeros(len(self.targets), dtype=bool),
        ]
        for a in arrays:
            a.flags.writeable = False
        return Observation(0, 0.0, float(self.budget), *arrays)

    def starts(self) -> np.ndarray:
        """``(m, 2)`` the UAVs' start positions, m."""
        return np.array([agent.position for agent in self.team], dtype=float)

    def never_observed_uncertainty(self) -> float:
        """``U`` of a mission that measures nothing: every prior grown to the budget's end."""
        _, covs = self.motion_model().predict(
            self.means(), self.covariances(), self.process_noise(), self.n_steps * self.time_step
        )
        return float(position_logdet(covs).sum())

    def with_seed(self, seed: int) -> Scenario:
        """The same scenario driven by another seed."""
        return self.model_copy(update={"seed": seed})
