"""What every layer above the models may use: the mission's constants, what a planner sees, and
the planner protocol (Gymnasium-like; a planner never sees the truth, except a reference that
declares it reads it, `TruthReader`).

Every planner, whether it chooses sub-tasks (the paper's hierarchical planner), controls (ARVI,
A*) or a learned policy, implements `Planner`. Each step the simulator (or the real-time
controller) hands it an `Observation` (what a real UAV would know: time, remaining budget,
its own position, the target beliefs and which targets it just measured) and receives a
waypoint: the position the agent should fly towards, at most ``agent_speed * time_step`` away.

`MissionSpec` is the one vocabulary for the mission constants (time step, budget, speed,
sensor diameter, measurement noise, process noise); the compiled kernels receive them as one
record, `MissionSpec.record` (`hptrack.models.mission.Mission`), built and
validated once.
"""

from __future__ import annotations

import math
import reprlib
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from hptrack.models.belief_motion import BeliefMotion
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.mission import Mission, mission_record
from hptrack.models.motion import ProcessNoiseForm

DEFAULT_MEASUREMENT_NOISE = 10.0
"""Default ``R = 10 I`` m^2 (sigma = 3.16 m per axis); the paper does not state ``R``."""


def _default_noise() -> np.ndarray:
    return DEFAULT_MEASUREMENT_NOISE * np.eye(2)


class InputError(ValueError):
    """Bad user input (a file, a field, an option or a value): the message is one line that
    names it and the value. The CLI shows it without a traceback and exits with code 2; every
    other exception is a bug and keeps its traceback."""


MAX_SHOWN_CHARS = 80
"""Longest shown value in an error message (`shown`)."""
MAX_MESSAGE_CHARS = 600
"""Longest error message (`one_line`)."""


class _ShortRepr(reprlib.Repr):
    """``repr`` that looks at a bounded part of a value: a few items of a list or a mapping, two
    levels deep, the digit count of a long integer (never its digits)."""

    def __init__(self) -> None:
        super().__init__()
        self.maxlevel, self.maxlist, self.maxtuple, self.maxdict = 2, 4, 4, 3
        self.maxstring, self.maxother, self.maxlong = 40, 40, 30

    def repr_int(self, x: int, level: int) -> str:
        if x.bit_length() > 96:
            return f"<an integer of about {int(x.bit_length() * math.log10(2)) + 1} digits>"
        return repr(x)

    def repr_str(self, x: str, level: int) -> str:
        return repr(x[: self.maxstring]) + ("..." if len(x) > self.maxstring else "")

    def repr_list(self, x: list, level: int) -> str:
        text = super().repr_list(x, level)
        return f"{text[:-1]} ({len(x)} items)]" if len(x) > self.maxlist else text


_SHORT = _ShortRepr()


def shown(value: Any, limit: int = MAX_SHOWN_CHARS) -> str:
    """A bounded, printable ``repr`` of ``value`` for an error message: long lists, mappings,
    strings and integers are shortened, control characters escaped, at most ``limit`` chars."""
    try:
        text = _SHORT.repr(value)
    except Exception:  # noqa: BLE001 - a value whose repr fails is still shown
        text = f"<{type(value).__name__}>"
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def one_line(message: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``message`` as one bounded, printable line (whitespace collapsed, control characters
    escaped, cut at ``limit`` chars)."""
    text = " ".join(message[: 4 * limit].split())
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True, eq=False)
class MissionSpec:
    """The static facts of a mission that a planner may use (SI units).

    Attributes:
        time_step: ``tau``, s (the paper uses 0.5 s).
        budget: mission duration ``B``, s.
        agent_speed: ``v_a``, m/s.
        sensor_diameter: footprint diameter ``w``, m; targets within ``w/2`` are measured.
        measurement_noise: ``(2, 2)`` position measurement covariance ``R``, m^2.
        process_noise_form: which per-step ``Q`` (`hptrack.models.motion`).
        process_noise: ``(n,)`` per-target noise intensities ``q``, m^2/s^3.
        target_ids: the targets' names.
        belief_motion: how the beliefs assume the targets move, a registered part of
            `hptrack.models.belief_motion`; ``None``: constant velocity with
            ``process_noise_form``.
    """

    time_step: float = 0.5
    budget: float = 900.0
    agent_speed: float = 30.0
    sensor_diameter: float = 100.0
    measurement_noise: np.ndarray = field(default_factory=_default_noise)
    process_noise_form: ProcessNoiseForm = "continuous"
    process_noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    target_ids: tuple[str, ...] = ()
    belief_motion: tuple | None = None
    record: Mission = field(init=False, repr=False)
    """The mission's constants as the compiled kernels take them (built and validated once,
    with the spec)."""

    def __post_init__(self) -> None:
        if self.process_noise_form not in ("continuous", "paper_text"):
            raise ValueError(f"unknown process_noise_form {self.process_noise_form!r}")
        record = mission_record(
            self.time_step,
            self.budget,
            self.agent_speed,
            self.sensor_diameter,
            self.measurement_noise,
            self.process_noise,
            self.process_noise_form == "continuous",
            self.belief_motion,
        )
        object.__setattr__(self, "measurement_noise", record.sensor.measurement_noise)
        object.__setattr__(self, "process_noise", record.process_noise)
        object.__setattr__(self, "target_ids", tuple(self.target_ids))
        object.__setattr__(self, "record", record)

    @property
    def n_steps(self) -> int:
        """Number of simulation steps in the budget (``B / tau``)."""
        return self.record.n_steps

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
    def motion(self) -> BeliefMotion:
        """The beliefs' motion model (its numpy face)."""
        return BeliefMotion(self.time_step, self.record.motion)

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


class SettingsRecord(Protocol):
    """A planner's settings as the layers above read them (a
    `PlannerSettings`)."""

    def as_json(self) -> dict[str, Any]:
        """The settings as JSON-ready options (they rebuild the same planner)."""
        ...


@dataclass(frozen=True)
class Subtask:
    """The sub-task a planner is flying (paper Sec. IV).

    Attributes:
        kind: ``"pursue"`` (a coverage sub-task on ``target``), ``"follow"`` (follow a found
            target) or ``"dwell"`` (follow it for the dwell's length).
        target: the target's index.
        since_step: the step it began at.
        p_find: the pursuit's estimated chance of finding the target, or ``None``.
    """

    kind: Literal["pursue", "follow", "dwell"]
    target: int
    since_step: int
    p_find: float | None = None


@dataclass(frozen=True)
class CurrentPlan:
    """What a planner is doing now and means to do next.

    Attributes:
        subtask: the sub-task being flown, or ``None`` (a planner without sub-tasks, or one
            hovering with nothing left to do).
        after_find: the action planned after a find (a target index; ``n`` is the dwell), or
            ``None``.
        after_miss: the action planned after a miss, or ``None``.
    """

    subtask: Subtask | None = None
    after_find: int | None = None
    after_miss: int | None = None


@runtime_checkable
class Planner(Protocol):
    """A mission planner. ``name`` identifies it in records and the registry; ``settings``
    are the options it was made with.

    ``reset`` is called once before the first step with the mission facts, the first
    observation and the planner's own random generator; ``act`` then returns, every step, the
    waypoint ``(2,)`` in m that the agent should fly towards; ``current_plan`` says, after an
    ``act``, what it is doing and means to do next (the real-time controller shows it);
    ``episode_info`` returns JSON-ready metadata of the mission so far (its decisions, effort,
    settings).
    """

    name: str
    settings: SettingsRecord

    def reset(
        self, mission: MissionSpec, observation: Observation, rng: np.random.Generator
    ) -> None: ...

    def act(self, observation: Observation) -> np.ndarray: ...

    def current_plan(self) -> CurrentPlan: ...

    def episode_info(self) -> dict[str, Any]: ...


@runtime_checkable
class TruthReader(Protocol):
    """A reference planner that reads the true target states (``clairvoyant``): the simulator
    hands them, before every ``act``, to a planner of this kind and to no other. No real mission
    has them, so it is never flown."""

    def see_truth(self, states: np.ndarray) -> None: ...
