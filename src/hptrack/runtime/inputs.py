"""What the controller accepts from outside: every odometry and detection is checked here
before it changes anything, and a refusal names its reason (``"jump"``, ``"outside the
area"``...) and one line of figures.

Checks: malformed or non-finite values; an unknown target id (a missing one on a mission
whose sensor names its targets, a given one on a mission whose sensor does not); an event
before the start or after the end; a detection stamped ahead of the clock by more than the
tolerance; odometry older than the last one or at the same time, or implying a speed the
vehicle cannot fly; a detection older than the newest by more than the reorder tolerance, or a
duplicate; a detection outside the mission's area (`mission_area`); a detection's own
covariance that is not a covariance or has eigenvalues outside `NOISE_RANGE_M2`. A report
without identity (`InputChecks.report`) has the same position and time checks; it must not
come after its look, and its covariance, if given, must be the scenario's ``R``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from hptrack.models.measurement import check_noise_covariance
from hptrack.models.mission import STEP_TOLERANCE
from hptrack.runtime.beliefs import BeliefTimeline
from hptrack.runtime.looks import TrackedBeliefs
from hptrack.scenario.model import Scenario


class ControllerSettings(BaseModel):
    """How the controller treats time and bad input (s, m).

    Attributes:
        reorder_tolerance_s: a detection up to this much older than the newest one is filtered
            in its time order; an older one is refused.
        future_tolerance_s: a detection stamped more than this ahead of the controller's
            clock (the newest odometry, setpoint or detection time) is refused.
        stale_odometry_s: without odometry for longer than this, ``setpoint`` holds.
        planner_deadline_s: a planner call not back within this is late (logged; the
            fallback decision is flown meanwhile).
        max_speed_factor: odometry implying a speed above this times the agent's speed is a
            jump and is refused.
        jump_slack_m: distance allowed on top of that speed (position noise), m.
        keep_lag: a new decision's leg keeps the vehicle's lag behind the reference it was
            flying (at most one step, ``v_a tau``), so that a position loop that flies less than
            its velocity setpoint (PX4 flies about 0.8 of it) still flies the planned speed;
            ``False``: every leg starts from the odometry.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    reorder_tolerance_s: Annotated[float, Field(ge=0.0, le=60.0)] = 2.0
    future_tolerance_s: Annotated[float, Field(ge=0.0, le=60.0)] = 0.5
    stale_odometry_s: Annotated[float, Field(gt=0.0, le=600.0)] = 1.0
    planner_deadline_s: Annotated[float, Field(gt=0.0, le=3600.0)] = 1.0
    max_speed_factor: Annotated[float, Field(ge=1.0, le=100.0)] = 2.0
    jump_slack_m: Annotated[float, Field(ge=0.0, le=1e4)] = 3.0
    keep_lag: bool = True


Problem = tuple[str, str]
"""A refusal: its reason and one line of figures."""

MALFORMED_POSITION: Problem = ("malformed", "position is not two numbers")
NOISE_RANGE_M2 = (1e-12, 1e8)
"""A detection's noise covariance must have its eigenvalues in ``(low, high]`` m^2 (the range
a scenario's ``R`` may take: beyond it the Kalman update loses its precision)."""


def mission_area(scenario: Scenario) -> tuple[np.ndarray, float]:
    """Centre (the agent's start, m) and radius (m) of the area where a detection can be: the
    vehicle flies at most ``v_a B`` from its start and measures only within ``w/2`` of itself,
    with an error under 10 standard deviations of ``R``."""
    mission = scenario.mission_spec()
    sigma = math.sqrt(float(np.max(np.linalg.eigvalsh(mission.measurement_noise))))
    radius = mission.agent_speed * mission.budget + mission.sensor_radius + 10.0 * sigma
    return np.asarray(scenario.agent.position, dtype=float), radius


def _numbers_only(value: Any) -> bool:
    """Whether ``value`` is a number or nested lists of numbers (no text, no booleans)."""
    if isinstance(value, np.ndarray):
        return value.dtype.kind in "iuf"
    if isinstance(value, list | tuple):
        return all(_numbers_only(item) for item in value)
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


def vector(value: Any, shape: tuple[int, ...]) -> np.ndarray | None:
    """``value`` as a float array of ``shape``, or ``None`` (numbers only: text and booleans
    are not coerced; integers too large for a float are refused)."""
    if not _numbers_only(value):
        return None
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return None
    return array if array.shape == shape else None


def raw(value: Any) -> Any:
    """A raw input as log data (an array as a list, anything odd as its repr)."""
    if value is None or isinstance(value, str | bool | int | float):
        return value
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return repr(value)[:200]


@dataclass(frozen=True)
class DetectionCheck:
    """A checked detection: the problem (``None`` if accepted), the target's index (``-1`` if
    unknown) and the noise covariance to filter it with, m^2."""

    problem: Problem | None
    index: int
    noise: np.ndarray


class InputChecks:
    """The checks of one mission (module docstring).

    Args:
        scenario: the mission (speed, ``R``, targets, area).
        settings: the controller's tolerances.
    """

    def __init__(self, scenario: Scenario, settings: ControllerSettings) -> None:
        self.mission = scenario.mission_spec()
        self.settings = settings
        self.area = mission_area(scenario)
        self._ids = {tid: i for i, tid in enumerate(self.mission.target_ids)}

    def time(
        self, t: float, ahead_s: float, clock_source: bool, ended: str | None
    ) -> Problem | None:
        """Refuse a non-finite time, one outside the mission (``ended``: why it ended), or
        (for an event that is not a source of the clock) one ``ahead_s`` s ahead of it by more
        than the tolerance."""
        if not math.isfinite(t):
            return "non-finite", f"time {t}"
        if ended is not None:
            return "after the end", f"the mission ended ({ended})"
        if t < -STEP_TOLERANCE:
            return "before the start", f"time {t:.3f} s is before the mission's start"
        if clock_source:
            return None
        if ahead_s > self.settings.future_tolerance_s:
            return "in the future", (
                f"stamped {ahead_s:.3f} s ahead of the controller's clock "
                f"(tolerance {self.settings.future_tolerance_s:g} s)"
            )
        return None

    def odometry(
        self,
        t: float,
        p: np.ndarray | None,
        last: tuple[float, np.ndarray] | None,
        ended: str | None,
    ) -> Problem | None:
        """The problem with odometry ``p`` (2,) m at ``t`` s after the ``last`` accepted one."""
        if p is None:
            return "malformed", "position is not two numbers"
        if not np.all(np.isfinite(p)):
            return "non-finite", f"position {p.tolist()}"
        problem = self.time(t, 0.0, clock_source=True, ended=ended)
        if problem is not None or last is None:
            return problem
        last_t, last_p = last
        if t < last_t:
            return "out of order", f"{last_t - t:.3f} s older than the last odometry"
        if t == last_t:
            return "duplicate", f"a second odometry at {t:.3f} s"
        distance = float(np.hypot(*(p - last_p)))
        speed = self.settings.max_speed_factor * self.mission.agent_speed
        if distance > speed * (t - last_t) + self.settings.jump_slack_m:
            return "jump", (
                f"{distance:.1f} m in {t - last_t:.3f} s (more than {speed:g} m/s "
                f"+ {self.settings.jump_slack_m:g} m)"
            )
        return None

    def detection(
        self,
        t: float,
        target_id: Any,
        z: np.ndarray | None,
        covariance: Any,
        ahead_s: float,
        ended: str | None,
        beliefs: BeliefTimeline | TrackedBeliefs,
        confidence: Any = None,
    ) -> DetectionCheck:
        """The check of a measurement ``z`` (2,) m of ``target_id`` at ``t`` s (``ahead_s``
        ahead of the clock) with its own ``covariance`` or ``None``, against the ``beliefs``
        so far. Without identity (``beliefs`` a `TrackedBeliefs`) ``target_id`` must be
        ``None`` and the report is checked by `report`."""
        noise = self.mission.measurement_noise
        if isinstance(beliefs, TrackedBeliefs):
            return self.report(t, target_id, z, covariance, ahead_s, ended, beliefs, confidence)
        if target_id is None:
            detail = (
                "a detection without id: the mission's sensor is labelled (sensor.labelled: "
                "true), so each detection names its target in its id field"
            )
            return DetectionCheck(("no id", detail), -1, noise)
        if not isinstance(target_id, str) or target_id not in self._ids:
            return DetectionCheck(
                (
                    "unknown target",
                    f"target id {raw(target_id)!r} is not in the mission "
                    f"({', '.join(self.mission.target_ids)})",
                ),
                -1,
                noise,
            )
        if z is None:
            return DetectionCheck(MALFORMED_POSITION, -1, noise)
        position = self._position(z)
        if position is not None:
            return DetectionCheck(position, -1, noise)
        if covariance is not None:
            problem, noise = self._noise(covariance, noise)
            if problem is not None:
                return DetectionCheck(problem, -1, noise)
        problem = self.time(t, ahead_s, clock_source=False, ended=ended)
        if problem is not None:
            return DetectionCheck(problem, -1, noise)
        index = self._ids[target_id]
        behind = beliefs.newest_s - t
        if behind > self.settings.reorder_tolerance_s:
            detail = (
                f"{behind:.3f} s older than the newest detection "
                f"(tolerance {self.settings.reorder_tolerance_s:g} s)"
            )
            return DetectionCheck(("out of order", detail), index, noise)
        if beliefs.is_duplicate(index, t, z):
            detail = f"the same measurement of {target_id} at {t:.3f} s"
            return DetectionCheck(("duplicate", detail), index, noise)
        return DetectionCheck(None, index, noise)

    def report(
        self,
        t: float,
        target_id: Any,
        z: np.ndarray | None,
        covariance: Any,
        ahead_s: float,
        ended: str | None,
        beliefs: TrackedBeliefs,
        confidence: Any,
    ) -> DetectionCheck:
        """The check of a report without identity (``sensor.labelled: false``): no id; a
        position as for a measurement; a covariance, if given, the scenario's ``R`` (the tracker
        filters every report with it); a ``confidence``, if given, in ``[0, 1]``; not in a look
        already done (`TrackedBeliefs.late`) and not waiting twice."""
        noise = self.mission.measurement_noise
        if target_id is not None:
            detail = (
                f"id {raw(target_id)!r} on a mission whose sensor reports no identity "
                "(sensor.labelled: false): send the detection without id"
            )
            return DetectionCheck(("id without identity", detail), -1, noise)
        if z is None:
            return DetectionCheck(MALFORMED_POSITION, -1, noise)
        problem = self._position(z)
        if problem is None and covariance is not None:
            problem, own = self._noise(covariance, noise)
            if problem is None and not np.allclose(own, noise, rtol=1e-9, atol=0.0):
                detail = (
                    f"cov {own.tolist()} m^2: the tracker of detections without identity "
                    f"filters every report with the scenario's R {noise.tolist()} m^2 (send no cov)"
                )
                problem = "not R", detail
        if problem is None and confidence is not None:
            c = vector(confidence, ())
            if c is None or not 0.0 <= float(c) <= 1.0:
                problem = "bad confidence", f"confidence {raw(confidence)!r} is not in [0, 1]"
        if problem is None:
            problem = self.time(t, ahead_s, clock_source=False, ended=ended)
        if problem is None and beliefs.late(t):
            detail = f"stamped {t:.3f} s, in the look of {beliefs.looked_s:.3f} s that is done"
            problem = "late", detail
        if problem is None and beliefs.is_duplicate(t, z):
            problem = "duplicate", f"the same report at {t:.3f} s"
        return DetectionCheck(problem, -1, noise)

    def _position(self, z: np.ndarray) -> Problem | None:
        """The problem with a detection's position ``z`` (2,) m: non-finite or outside the
        mission's area."""
        if not np.all(np.isfinite(z)):
            return "non-finite", f"position {z.tolist()}"
        centre, reach = self.area
        distance = float(np.hypot(*(z - centre)))
        if not distance <= reach:
            return "outside the area", (
                f"{distance:.3g} m from the start, beyond the mission's {reach:.0f} m"
            )
        return None

    @staticmethod
    def _noise(covariance: Any, default: np.ndarray) -> tuple[Problem | None, np.ndarray]:
        r = vector(covariance, (2, 2))
        if r is None:
            return ("malformed", "covariance is not a 2x2 matrix"), default
        try:
            noise = check_noise_covariance(r)
        except ValueError as err:
            return ("bad covariance", str(err)), default
        low, high = NOISE_RANGE_M2
        eig = np.linalg.eigvalsh(noise)
        if not (eig[0] > low and eig[1] <= high):
            detail = f"eigenvalues {eig[0]:.3g}, {eig[1]:.3g} m^2 outside ({low:g}, {high:g}]"
            return ("bad covariance", detail), default
        return None, noise
