"""A Stone Soup sensor manager that flies an actionable platform with any hptrack planner.

Stone Soup (dstl's tracking framework) keeps targets as `Track`\\ s
of Gaussian states ordered ``[x, vx, y, vy]``; hptrack's planners see beliefs ordered
``[x, y, vx, vy]`` (paper Sec. III). `HptrackSensorManager` converts the tracks in one
place (`hptrack_beliefs`, the permutation `STONESOUP_TO_HPTRACK`), builds the
planner's `MissionSpec` and `Observation`,
and turns the planner's waypoint into a `MovePositionAction` of a platform moved by a
`MaxSpeedActionableMovable`.

Missions: the planner is reset once per *mission* and asked for a waypoint at every call. A
mission starts at the first call, and again whenever the set of track ids changes (a track
appeared or was deleted: the planner's target set is fixed, so it plans afresh from the current
beliefs) or when the mission's ``budget`` runs out (missions then roll on, each ``budget``
seconds long). Target ``i`` of a mission is the ``i``-th track in first-seen order (tracks first
seen in the same call sorted by id); a track keeps its relative order for as long as it exists.

`FootprintPositionSensor` is the paper's sensor in Stone Soup terms (a position fix with
noise ``R`` of every target within ``w/2``) and `HoverSensorManager` the baseline that
keeps the platform where it is. Registered as the Stone Soup plugin ``hptrack``
(``from stonesoup.plugins.hptrack import HptrackSensorManager``).
"""

import datetime
import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from stonesoup.base import Property
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.transition.linear import (
    CombinedLinearGaussianTransitionModel,
    ConstantVelocity,
)
from stonesoup.movable.action.move_position_action import (
    MaxSpeedPositionActionGenerator,
    MovePositionAction,
)
from stonesoup.movable.max_speed import MaxSpeedActionableMovable
from stonesoup.sensor.sensor import SimpleSensor
from stonesoup.sensormanager.base import SensorManager
from stonesoup.types.array import CovarianceMatrix, StateVector
from stonesoup.types.state import GaussianState
from stonesoup.types.track import Track
from stonesoup.types.update import Update

from hptrack.interface import MissionSpec, Observation, Planner
from hptrack.models.measurement import check_noise_covariance
from hptrack.models.motion import ConstantVelocityModel
from hptrack.models.sensor import FootprintSensor, measured_mask
from hptrack.models.vehicle import move_towards
from hptrack.registry import make_planner, planner_settings

__all__ = [
    "STONESOUP_TO_HPTRACK",
    "FootprintPositionSensor",
    "HoverSensorManager",
    "HptrackSensorManager",
    "hptrack_beliefs",
    "process_noise_of",
]

log = logging.getLogger(__name__)

STONESOUP_TO_HPTRACK = (0, 2, 1, 3)
"""hptrack's ``[x, y, vx, vy]`` taken from a Stone Soup ``[x, vx, y, vy]`` state: entry ``j`` is
the Stone Soup index of hptrack component ``j`` (the permutation is its own inverse)."""


def _state_indices(state_mapping: Sequence[int]) -> np.ndarray:
    """Track-state indices of hptrack's ``[x, y, vx, vy]`` given those of ``[x, vx, y, vy]``."""
    mapping = np.asarray(state_mapping)
    if mapping.shape != (4,) or len(set(mapping.tolist())) != 4 or np.any(mapping < 0):
        raise ValueError(
            "state_mapping must give 4 distinct indices of x, vx, y, vy in the "
            f"track state, got {list(state_mapping)}"
        )
    return mapping[list(STONESOUP_TO_HPTRACK)]


def hptrack_beliefs(
    states: Sequence[GaussianState], state_mapping: Sequence[int] = (0, 1, 2, 3)
) -> tuple[np.ndarray, np.ndarray]:
    """Stacked hptrack beliefs of Stone Soup Gaussian states: means ``(n, 4)`` ordered
    ``[x, y, vx, vy]`` (m, m/s) and covariances ``(n, 4, 4)``.

    ``state_mapping`` gives the indices of ``x, vx, y, vy`` in the Stone Soup state (the
    default is Stone Soup's 2-D constant-velocity order; ``(0, 1, 2, 3)`` of a 3-D
    ``[x, vx, y, vy, z, vz]`` state plans in the ``x, y`` plane).
    """
    idx = _state_indices(state_mapping)
    means = np.empty((len(states), 4))
    covs = np.empty((len(states), 4, 4))
    for i, state in enumerate(states):
        means[i] = np.asarray(state.state_vector, dtype=float).reshape(-1)[idx]
        covs[i] = np.asarray(state.covar, dtype=float)[np.ix_(idx, idx)]
    return means, covs


def process_noise_of(transition_model: CombinedLinearGaussianTransitionModel) -> float:
    """``q`` (m^2/s^3) of a Stone Soup ``[ConstantVelocity(q), ConstantVelocity(q), ...]`` model.

    Stone Soup's ``ConstantVelocity`` noise is ``q [[dt^3/3, dt^2/2], [dt^2/2, dt]]`` per axis,
    hptrack's ``"continuous"`` form; hptrack's targets have one ``q`` for both axes.

    Raises:
        ValueError: the model is not constant velocity on x and y with one ``q``.
    """
    models = getattr(transition_model, "model_list", ())
    if len(models) < 2 or not all(isinstance(m, ConstantVelocity) for m in models[:2]):
        raise ValueError(
            "the transition model must combine ConstantVelocity models on x and y, "
            f"got {transition_model!r}"
        )
    qx, qy = (float(m.noise_diff_coeff) for m in models[:2])
    if not math.isclose(qx, qy, rel_tol=1e-12, abs_tol=0.0):
        raise ValueError(f"hptrack needs one process noise for x and y, got {qx} and {qy}")
    return qx


def _check_nchoose(nchoose: int) -> None:
    if nchoose != 1:
        raise ValueError(f"this sensor manager gives one configuration (nchoose=1), got {nchoose}")


class FootprintPositionSensor(SimpleSensor):
    """Measures the ``[x, y]`` position, with noise ``R``, of every target within ``w/2`` of the
    sensor (the paper's downward-looking camera, Sec. III). The sensor's position is taken as
    the first two entries of its platform position."""

    noise_covar: CovarianceMatrix = Property(doc="Measurement noise ``R`` (2x2), m^2.")
    diameter: float = Property(doc="Footprint diameter ``w``, m.")
    ndim_state: int = Property(default=4, doc="Dimension of the target state.")
    mapping: Sequence[int] = Property(
        default=(0, 2), doc="Indices of ``x`` and ``y`` in the target state."
    )

    @property
    def measurement_model(self) -> LinearGaussian:
        return LinearGaussian(
            ndim_state=self.ndim_state, mapping=self.mapping, noise_covar=self.noise_covar
        )

    def _within(self, xy: np.ndarray) -> bool:
        """The footprint's rule, asked of hptrack's sensor part (`hptrack.models.sensor`)."""
        centre = np.asarray(self.position, dtype=float).reshape(-1)[:2]
        part = FootprintSensor(float(self.diameter), np.asarray(self.noise_covar, dtype=float))
        return bool(measured_mask(part, centre, xy[None])[0])

    def is_detectable(self, state, measurement_model=None) -> bool:
        return self._within(
            np.asarray(state.state_vector, dtype=float).reshape(-1)[list(self.mapping)]
        )

    def is_clutter_detectable(self, state) -> bool:
        return self._within(np.asarray(state.state_vector, dtype=float).reshape(-1)[:2])


def _movable_of(platform: Any) -> MaxSpeedActionableMovable:
    movable = getattr(platform, "movement_controller", platform)
    if not isinstance(movable, MaxSpeedActionableMovable):
        raise ValueError(
            "the platform must be moved by a MaxSpeedActionableMovable, got "
            f"{type(movable).__name__}"
        )
    return movable


def _position_generator(
    platform: Any, timestamp: datetime.datetime
) -> MaxSpeedPositionActionGenerator:
    (generator,) = platform.actions(timestamp)
    return generator


class HoverSensorManager(SensorManager):
    """Keeps every managed platform where it is (each position generator's default action): the
    baseline that `HptrackSensorManager` must beat."""

    def choose_actions(
        self, tracks: Iterable[Track], timestamp: datetime.datetime, nchoose: int = 1, **kwargs
    ) -> list[dict]:
        _check_nchoose(nchoose)
        return [
            {
                platform: [generator.default_action for generator in platform.actions(timestamp)]
                for platform in self.platforms
            }
        ]


class HptrackSensorManager(SensorManager):
    """Moves one `MaxSpeedActionableMovable` platform with
    an hptrack planner (module docstring: frames, missions, track identity).

    Call `choose_actions` every ``time_step`` seconds of platform time with the current
    tracks; it returns ``[{platform: [MovePositionAction]}]`` for the platform's next
    ``time_step`` seconds. The mission's agent speed is the movable's ``max_speed``; the sensor
    footprint and ``R`` are ``sensor_diameter`` and ``measurement_noise``, or, when these are
    not given, those of the platform's `FootprintPositionSensor`.
    """

    process_noise: float | Mapping[str, float] = Property(
        doc="Target process noise ``q``, m^2/s^3 (`process_noise_of` reads it from a "
        "transition model): one value for every track, or a mapping of track id to ``q``."
    )
    time_step: float = Property(doc="Decision interval ``tau``, s.")
    planner: str = Property(default="mcts", doc="hptrack planner name (``hptrack.registry``).")
    planner_options: Mapping[str, Any] = Property(
        default=None, doc="The planner's options, e.g. ``{'iterations': 2000}``."
    )
    budget: float = Property(default=900.0, doc="Mission duration ``B``, s.")
    sensor_diameter: float = Property(
        default=None, doc="Footprint diameter ``w``, m (default: the platform's sensor's)."
    )
    measurement_noise: np.ndarray = Property(
        default=None,
        doc="Position measurement noise ``R`` (2x2), m^2 (default: the platform's sensor's).",
    )
    state_mapping: Sequence[int] = Property(
        default=(0, 1, 2, 3), doc="Indices of ``x, vx, y, vy`` in the track states."
    )
    discrete_actions: bool = Property(
        default=False,
        doc="Take the position generator's action closest to the waypoint "
        "instead of flying straight at it at full speed.",
    )
    seed: int = Property(default=None, doc="Seed of the planner's random streams.")

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        if len(self.platforms) != 1:
            raise ValueError(
                f"HptrackSensorManager flies exactly one platform, got {len(self.platforms)}"
            )
        (self._platform,) = self.platforms
        self._movable = _movable_of(self._platform)
        self._settings = planner_settings(self.planner, dict(self.planner_options or {}))
        for name in ("time_step", "budget"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(
                    f"{name} must be a positive finite number of seconds, got {value!r}"
                )
        self._diameter, self._noise = self._sensor_model()
        _state_indices(self.state_mapping)
        self._seeds = np.random.SeedSequence(self.seed)
        self._order: list[str] = []
        self._mission: MissionSpec | None = None
        self._mission_start: datetime.datetime | None = None
        self._planner: Planner | None = None

    def _sensor_model(self) -> tuple[float, np.ndarray]:
        diameter, noise = self.sensor_diameter, self.measurement_noise
        if diameter is None or noise is None:
            footprints = [s for s in self.sensors if isinstance(s, FootprintPositionSensor)]
            if len(footprints) != 1:
                raise ValueError(
                    "give sensor_diameter and measurement_noise, or mount one "
                    f"FootprintPositionSensor on the platform (found "
                    f"{len(footprints)})"
                )
            diameter = footprints[0].diameter if diameter is None else diameter
            noise = footprints[0].noise_covar if noise is None else noise
        if not (math.isfinite(diameter) and diameter > 0.0):
            raise ValueError(
                f"sensor_diameter must be a positive number of metres, got {diameter!r}"
            )
        return float(diameter), check_noise_covariance(np.asarray(noise, dtype=float))

    @property
    def mission(self) -> MissionSpec | None:
        """The current mission (``None`` before the first call or without tracks)."""
        return self._mission

    @property
    def target_ids(self) -> tuple[str, ...]:
        """Track ids of the current mission's targets, in target-index order."""
        return () if self._mission is None else self._mission.target_ids

    def planner_info(self) -> dict[str, Any]:
        """The current mission's planner metadata (``episode_info()``), or ``{}``."""
        return {} if self._planner is None else dict(self._planner.episode_info())

    # --- tracks -> observation -----------------------------------------------------------
    def _ordered(self, tracks: Iterable[Track]) -> list[Track]:
        """``tracks`` in first-seen order; forgets the ids of tracks no longer given."""
        by_id = {str(track.id): track for track in tracks}
        self._order = [i for i in self._order if i in by_id]
        self._order += sorted(set(by_id) - set(self._order))
        return [by_id[i] for i in self._order]

    def _process_noise(self, ids: Sequence[str]) -> np.ndarray:
        if isinstance(self.process_noise, Mapping):
            missing = [i for i in ids if i not in self.process_noise]
            if missing:
                raise ValueError(f"process_noise has no entry for track {missing[0]!r}")
            q = np.array([self.process_noise[i] for i in ids], dtype=float)
        else:
            q = np.full(len(ids), float(self.process_noise))
        if not np.all(np.isfinite(q) & (q >= 0.0)):
            raise ValueError(f"process_noise must be finite and >= 0 m^2/s^3, got {q.tolist()}")
        return q

    def _beliefs(
        self, tracks: Sequence[Track], q: np.ndarray, now: datetime.datetime
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Means, covariances (predicted to ``now`` when a track is older) and which tracks
        were updated at ``now``."""
        states = [track.state for track in tracks]
        for track, state in zip(tracks, states, strict=True):
            if state.timestamp is None or state.timestamp > now:
                raise ValueError(
                    f"track {track.id!r} is at {state.timestamp}, the platform at "
                    f"{now}: tracks must not be ahead of the platform"
                )
        means, covs = hptrack_beliefs(states, self.state_mapping)
        ages = np.array([(now - s.timestamp).total_seconds() for s in states])
        means, covs = ConstantVelocityModel(self.time_step).predict(means, covs, q, ages)
        detected = np.array([isinstance(s, Update) and s.timestamp == now for s in states])
        return means, covs, detected

    def _agent_position(self) -> np.ndarray:
        position = np.asarray(self._movable.position, dtype=float).reshape(-1)
        return position[list(self._movable.action_mapping)]

    def _start_mission(
        self, ids: tuple[str, ...], q: np.ndarray, observation: Observation, now: datetime.datetime
    ) -> None:
        self._mission = MissionSpec(
            time_step=self.time_step,
            budget=self.budget,
            agent_speed=float(self._movable.max_speed),
            sensor_diameter=self._diameter,
            measurement_noise=self._noise,
            process_noise_form="continuous",
            process_noise=q,
            target_ids=ids,
        )
        self._mission_start = now
        self._planner = make_planner(self.planner, self._settings)
        (seq,) = self._seeds.spawn(1)
        self._planner.reset(self._mission, observation, np.random.default_rng(seq))
        log.info("new %s mission at %s over %d tracks", self.planner, now, len(ids))

    def _observation(
        self, step: int, means: np.ndarray, covs: np.ndarray, detected: np.ndarray
    ) -> Observation:
        arrays = [self._agent_position(), means, covs, detected]
        for a in arrays:
            a.flags.writeable = False
        time = step * self.time_step
        return Observation(step, time, self.budget - time, *arrays)

    # --- waypoint -> action --------------------------------------------------------------
    def _action(
        self, generator: MaxSpeedPositionActionGenerator, waypoint: np.ndarray
    ) -> MovePositionAction:
        mapping = list(self._movable.action_mapping)
        if self.discrete_actions:
            return min(
                generator,
                key=lambda a: float(
                    np.hypot(
                        *(np.asarray(a.target_value, dtype=float).reshape(-1)[mapping] - waypoint)
                    )
                ),
            )
        goal = move_towards(self._agent_position(), waypoint, generator.maximum_travel)
        space = self._movable.action_space
        if space is not None:
            space = np.asarray(space, dtype=float)
            goal = np.clip(goal, space[:, 0], space[:, 1])
        target = StateVector(np.array(generator.current_value, dtype=float))
        target[mapping, 0] = goal
        action = generator.action_from_value(target)
        if action is None:
            raise RuntimeError(f"position {goal} is out of the platform's reach")
        return action

    def choose_actions(
        self, tracks: Iterable[Track], timestamp: datetime.datetime, nchoose: int = 1, **kwargs
    ) -> list[dict]:
        """Plan the platform's move until ``timestamp`` (``time_step`` s after the platform's
        current time) from ``tracks`` (Gaussian states at or before the platform's time).

        Returns:
            ``[{platform: [MovePositionAction]}]``; without tracks, the action that stays.

        Raises:
            ValueError: ``nchoose`` is not 1, the interval is not ``time_step``, or a track is
                ahead of the platform or has no process noise.
        """
        _check_nchoose(nchoose)
        now = self._movable.state.timestamp
        interval = (timestamp - now).total_seconds()
        if not math.isclose(interval, self.time_step, rel_tol=1e-9, abs_tol=1e-6):
            raise ValueError(
                f"choose_actions for {timestamp} is {interval} s after the "
                f"platform's time {now}; this manager decides every "
                f"time_step = {self.time_step} s"
            )
        generator = _position_generator(self._platform, timestamp)
        ordered = self._ordered(tracks)
        if not ordered:
            self._mission = self._planner = self._mission_start = None
            return [{self._platform: [generator.default_action]}]
        ids = tuple(str(track.id) for track in ordered)
        q = self._process_noise(ids)
        means, covs, detected = self._beliefs(ordered, q, now)
        step, restart = 0, self._mission is None or self._mission.target_ids != ids
        if not restart:
            step = round((now - self._mission_start).total_seconds() / self.time_step)
            restart = step >= self._mission.n_steps
        if restart:
            step = 0
            self._start_mission(ids, q, self._observation(0, means, covs, detected), now)
        waypoint = np.asarray(
            self._planner.act(self._observation(step, means, covs, detected)), dtype=float
        )
        if waypoint.shape != (2,) or not np.all(np.isfinite(waypoint)):
            raise ValueError(f"planner {self.planner!r} returned an invalid waypoint {waypoint!r}")
        return [{self._platform: [self._action(generator, waypoint)]}]
