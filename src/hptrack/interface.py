"""What every layer above the models may use: the mission's constants, what a planner sees, and
the planner protocol (Gymnasium-like; a planner never sees the truth, except a reference that
declares it reads it, `TruthReader`).

Every planner, whether it chooses sub-tasks (the paper's hierarchical planner), controls (ARVI,
A*) or a learned policy, implements `Planner`. Each step the simulator (or the real-time
controller) hands it an `Observation` (what a real UAV would know: time, remaining budget,
the vehicles' positions, the target beliefs and which targets it just measured) and receives a
waypoint per vehicle: the position each should fly towards, at most ``agent_speed * time_step``
away. Missions have ``m`` vehicles (`MissionSpec.n_vehicles`, 1 everywhere today).

`MissionSpec` is the one vocabulary for the mission constants (time step, budget, speed,
sensor diameter, measurement noise, process noise); the compiled kernels receive them as one
record, `MissionSpec.record` (`hptrack.models.mission.Mission`), built and
validated once.
"""

from __future__ import annotations

import math
import reprlib
from dataclasses import dataclass, field, replace
from typing import Any, Protocol, runtime_checkable

import numpy as np

from hptrack.models.belief_motion import BeliefMotion
from hptrack.models.fence import FenceSpec
from hptrack.models.measurement import PositionMeasurementModel
from hptrack.models.mission import Mission, mission_record
from hptrack.models.motion import ProcessNoiseForm
from hptrack.subtasks import Subtask, SubtaskAction

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
class TeamMember:
    """One UAV of a team (`MissionSpec.members`): what differs between the vehicles.

    Attributes:
        speed: ``v_a``, m/s.
        sensor_diameter: footprint diameter ``w``, m.
        measurement_noise: ``(2, 2)`` its sensor's ``R``, m^2.
    """

    speed: float
    sensor_diameter: float
    measurement_noise: np.ndarray


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
        n_vehicles: ``m``, the vehicles flown (a planner that flies one refuses more,
            `one_vehicle`); without ``members`` they share the speed and the sensor.
        members: a team's UAVs, each with its own speed and sensor (`TeamMember`; the first
            is the one-vehicle fields' ``agent_speed``, ``sensor_diameter`` and
            ``measurement_noise``); ``()``: ``n_vehicles`` alike. `vehicle_mission` gives each
            UAV's mission alone.
        belief_motion: how the beliefs assume the targets move, a registered part of
            `hptrack.models.belief_motion`; ``None``: constant velocity with
            ``process_noise_form``.
        detection_probability: the chance that a look detects a target inside the footprint
            (independent looks unless ``detection_correlation_time``): a number in ``(0, 1]``
            or a table of rows ``[distance from the footprint's centre, m; Pd]``
            (`hptrack.models.sensor.detection_table`); 1, the paper's sensor, by default.
        fence: where the vehicle may fly (`hptrack.models.fence.FenceSpec`: an operating
            area, no-fly zones, a margin); ``None``, the paper's open space, by default.
        negative_information: a look that detects nothing updates the beliefs
            (`hptrack.models.miss_update`); ``False``, the paper's, by default.
        detection_correlation_time: s, how long one detection draw holds while a target
            stays in the footprint (misses correlated over consecutive looks); 0, independent
            looks, by default.
        false_alarm_density: the false detections a look reports per m^2 of its footprint
            (Poisson; 0, the paper's sensor, by default); only a planner option that models
            false finds uses it (``mcts``'s ``false_finds="model"``).
    """

    time_step: float = 0.5
    budget: float = 900.0
    agent_speed: float = 30.0
    sensor_diameter: float = 100.0
    measurement_noise: np.ndarray = field(default_factory=_default_noise)
    process_noise_form: ProcessNoiseForm = "continuous"
    process_noise: np.ndarray = field(default_factory=lambda: np.zeros(0))
    target_ids: tuple[str, ...] = ()
    n_vehicles: int = 1
    belief_motion: tuple | None = None
    detection_probability: float | tuple[tuple[float, float], ...] = 1.0
    fence: FenceSpec | None = None
    negative_information: bool = False
    members: tuple[TeamMember, ...] = ()
    detection_correlation_time: float = 0.0
    false_alarm_density: float = 0.0
    record: Mission = field(init=False, repr=False)
    """The mission's constants as the compiled kernels take them (built and validated once,
    with the spec)."""

    def __post_init__(self) -> None:
        if self.process_noise_form not in ("continuous", "paper_text"):
            raise ValueError(f"unknown process_noise_form {self.process_noise_form!r}")
        if isinstance(self.n_vehicles, bool) or not (
            isinstance(self.n_vehicles, int | np.integer) and self.n_vehicles >= 1
        ):
            raise ValueError(f"n_vehicles must be a whole number >= 1, got {self.n_vehicles!r}")
        if self.members:
            object.__setattr__(self, "members", tuple(self.members))
            if self.n_vehicles not in (1, len(self.members)):
                raise ValueError(
                    f"n_vehicles {self.n_vehicles} is not the {len(self.members)} members"
                )
            object.__setattr__(self, "n_vehicles", len(self.members))
            first = self.members[0]
            if (first.speed, first.sensor_diameter) != (self.agent_speed, self.sensor_diameter):
                raise ValueError("members[0] must be the mission's agent_speed and sensor")
        record = mission_record(
            self.time_step,
            self.budget,
            self.agent_speed,
            self.sensor_diameter,
            self.measurement_noise,
            self.process_noise,
            self.process_noise_form == "continuous",
            self.belief_motion,
            self.detection_probability,
            self.fence,
            self.negative_information,
            self.detection_correlation_time,
            self.false_alarm_density,
        )
        object.__setattr__(self, "measurement_noise", record.sensor.measurement_noise)
        object.__setattr__(self, "process_noise", record.process_noise)
        object.__setattr__(self, "target_ids", tuple(self.target_ids))
        object.__setattr__(self, "record", record)

    @property
    def n_steps(self) -> int:
        """Number of simulation steps in the budget (``B / tau``)."""
        return self.record.n_steps

    def vehicle_mission(self, j: int) -> MissionSpec:
        """UAV ``j``'s mission alone (its speed and sensor, one vehicle): what a planner of
        one UAV of a team is told. A mission of one vehicle is its own."""
        if not 0 <= j < self.n_vehicles:
            raise IndexError(f"vehicle {j} of a team of {self.n_vehicles}")
        if self.n_vehicles == 1:
            return self
        cache = self.__dict__.setdefault("_vehicle_missions", {})
        if j not in cache:
            member = self.members[j] if self.members else None
            cache[j] = replace(
                self,
                n_vehicles=1,
                members=(),
                agent_speed=self.agent_speed if member is None else member.speed,
                sensor_diameter=self.sensor_diameter if member is None else member.sensor_diameter,
                measurement_noise=(
                    self.measurement_noise if member is None else member.measurement_noise
                ),
            )
        return cache[j]

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


def one_vehicle(planner: str, mission: MissionSpec) -> None:
    """Refuse a mission of several vehicles for a planner that flies one (its ``reset``).

    Raises:
        InputError: ``mission.n_vehicles`` is not 1.
    """
    if mission.n_vehicles != 1:
        raise InputError(
            f"planner {planner!r} flies one vehicle; the mission's n_vehicles is "
            f"{mission.n_vehicles} (a team flies with team-mcts, team-cbba, team-greedy or "
            "team-clairvoyant)"
        )


def vehicle_waypoints(waypoints: Any, n_vehicles: int, planner: str) -> np.ndarray:
    """A planner's ``act`` answer as ``(m, 2)`` waypoints, m (a ``(2,)`` answer is the one
    vehicle's).

    Raises:
        ValueError: another shape, or a value that is not finite (a planner's bug).
    """
    out = np.asarray(waypoints, dtype=float)
    if out.shape == (2,) and n_vehicles == 1:
        out = out[None]
    if out.shape != (n_vehicles, 2) or not np.all(np.isfinite(out)):
        raise ValueError(f"planner {planner!r} returned an invalid waypoint {waypoints!r}")
    return out


@dataclass(frozen=True, init=False)
class Observation:
    """The planner's view at one step (arrays are read-only copies).

    Attributes:
        step: step index ``k`` (time ``k * tau``).
        time: elapsed time, s.
        remaining_budget: ``B - time``, s.
        agent_positions: ``(m, 2)`` the vehicles' positions, m. A ``(2,)`` position, or the
            keyword ``agent_position=``, gives one vehicle; `agent_position` reads the first
            vehicle's.
        means: ``(n, 4)`` belief means (m, m/s).
        covariances: ``(n, 4, 4)`` belief covariances.
        detected: ``(n,)`` which targets were measured at this step (by any vehicle).
    """

    step: int
    time: float
    remaining_budget: float
    agent_positions: np.ndarray
    means: np.ndarray
    covariances: np.ndarray
    detected: np.ndarray

    def __init__(
        self,
        step: int,
        time: float,
        remaining_budget: float,
        agent_positions: np.ndarray | None = None,
        means: np.ndarray | None = None,
        covariances: np.ndarray | None = None,
        detected: np.ndarray | None = None,
        *,
        agent_position: np.ndarray | None = None,
    ) -> None:
        if (agent_positions is None) == (agent_position is None):
            raise TypeError("Observation takes agent_positions (m, 2) or agent_position (2,)")
        if means is None or covariances is None or detected is None:
            raise TypeError("Observation needs means, covariances and detected")
        positions = np.asarray(agent_positions if agent_position is None else agent_position)
        values = {
            "step": step,
            "time": time,
            "remaining_budget": remaining_budget,
            "agent_positions": positions[None] if positions.shape == (2,) else positions,
            "means": means,
            "covariances": covariances,
            "detected": detected,
        }
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def n_vehicles(self) -> int:
        """``m``, the vehicles seen."""
        return self.agent_positions.shape[0]

    @property
    def agent_position(self) -> np.ndarray:
        """``(2,)`` the first vehicle's position, m (the one vehicle of a single-vehicle
        planner)."""
        return self.agent_positions[0]


class SettingsRecord(Protocol):
    """A planner's settings as the layers above read them (a
    `PlannerSettings`)."""

    def as_json(self) -> dict[str, Any]:
        """The settings as JSON-ready options (they rebuild the same planner)."""
        ...


@dataclass(frozen=True)
class CurrentPlan:
    """What a planner is doing now and means to do next.

    Attributes:
        subtask: the sub-task being flown, or ``None`` (a planner without sub-tasks, or one
            hovering with nothing left to do).
        after_find: the action planned after a find (after a dwell: when it ends), or ``None``.
        after_miss: the action planned after a miss, or ``None``.
    """

    subtask: Subtask | None = None
    after_find: SubtaskAction | None = None
    after_miss: SubtaskAction | None = None


@runtime_checkable
class Planner(Protocol):
    """A mission planner. ``name`` identifies it in records and the registry; ``settings``
    are the options it was made with.

    ``reset`` is called once before the first step with the mission facts, the first
    observation and the planner's own random generator (a planner that flies one vehicle
    refuses a mission of more, `one_vehicle`); ``act`` then returns, every step, the
    waypoints ``(m, 2)`` in m that the vehicles should fly towards (a ``(2,)`` answer is the
    one vehicle's, `vehicle_waypoints`); ``current_plan`` says, after an
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
