"""``hptrack fly``: the mission controller on a PX4 vehicle through MAVSDK (the ``mavsdk``
package, 4.x, a binding of the MAVSDK C library), as offboard position setpoints.

Sequence: connect and wait for an autopilot; wait for a local position; read the vehicle's
horizontal speed and acceleration limits (PX4's ``MPC_XY_VEL_MAX`` and ``MPC_ACC_HOR``) and
put the scenario's fence on the vehicle, or take the vehicle's (`sync_fence`: upload, read back,
compare, ``GF_ACTION``); build the mission controller with them (the caller decides the planned
speed); hand the planner
its first tick (it compiles or loads its kernels then) and, meanwhile, arm and take off to the
mission altitude if asked (else the vehicle must already be armed and in the air); wait for the
first plan; send a first setpoint (where the vehicle is, at the mission altitude) and start
offboard mode. Mission time 0 is that moment. Then, until the budget's end: the vehicle's
``LOCAL_POSITION_NED`` feeds `odometry`,
detections arriving as JSON lines on a UDP port feed ``detection``, and the controller's
reference position and planned velocity are streamed at ``setpoint_rate_hz`` as offboard
position setpoints with velocity feed-forward (converted to NED by
`enu_to_ned`), so that PX4 flies the planned speed.

The vehicle's mode and arming are watched throughout, and every change is logged (``vehicle``
records) and said, as is every ``STATUSTEXT`` of severity warning or above (``vehicle_text``
records: a geofence breach's warning, say). The take-off is done when PX4 leaves TAKEOFF for
HOLD (its AUTO_LOITER) at the altitude; a disarm, a mode change, or a lost position during the
take-off ends it at once (`FlightError`, exit code 3, an ``abort`` record). Offboard counts as
started only once the vehicle reports OFFBOARD (`OFFBOARD_ATTEMPTS` tries of
`OFFBOARD_CONFIRM_S`); leaving OFFBOARD during the mission is a pilot (or a failsafe) taking
over: the mission ends at once and nothing more is commanded. A vehicle that does not move
towards its reference is warned of (`FOLLOW_DISTANCE_M`). The flight locks onto the MAVLink
system and component ids of the autopilot found at connection; odometry from any other source is
refused and counted.

Safe ends: the budget's end, Ctrl-C (or SIGTERM), a lost link (no telemetry for
``lost_link_s``), a setpoint beyond ``max_distance_m`` from home (the vehicle's position at the
mission's start), an offboard error, or a controller error each stop the stream and switch the
vehicle to hold (offboard stop) or to return-to-launch, wait for the flight mode to confirm it,
and log and report why. Every MAVSDK error is told as one plain sentence (`plain_error`):
what happened, what the vehicle is doing now, what to do.

Detection lines: ``{"id": "t1", "x": east_m, "y": north_m}`` with optional ``"t"`` (Unix time
of the measurement, s; default the time of arrival) and ``"cov"`` (2x2 noise covariance, m^2).
They are read and parsed in a thread of their own, within the bounds of
`IntakeLimits` (`intake`), so that no input
load slows the setpoint stream. A mission log that stops growing (a full disk, its size limit)
is said once; the flight goes on, or holds if ``log_failure`` is ``"hold"``.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import json
import logging
import math
import signal
import socket
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from mavsdk import LogLevel, log_subscribe
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.exceptions import MavsdkConnectionError
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.geofence import (
    Circle,
    FenceType,
    GeofenceAsync,
    GeofenceData,
    GeofenceError,
    Point,
    Polygon,
)
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.offboard import (
    OffboardAsync,
    OffboardError,
    PositionNedYaw,
    VelocityNedYaw,
)
from mavsdk.asyncio.plugins.param import ParamAsync, ParamError
from mavsdk.asyncio.plugins.telemetry import (
    FlightMode,
    StatusTextType,
    TelemetryAsync,
    TelemetryError,
)

from hptrack.interface import InputError
from hptrack.models.fence import FenceSpec
from hptrack.runtime.controller import MissionController
from hptrack.runtime.frames import enu_to_ned, ned_to_enu
from hptrack.runtime.geofence import (
    FENCE_ACTIONS,
    FENCE_TOLERANCE_M,
    GeoZone,
    fence_block,
    fence_difference,
    fence_summary,
    from_geodetic,
    to_geodetic,
)
from hptrack.runtime.intake import DetectionIntake, IntakeLimits
from hptrack.runtime.legs import PX4_VELOCITY_TRACKING, tracking_lag_m
from hptrack.runtime.links import connection_problem
from hptrack.runtime.log import ABORT, MISSION_START_MESSAGE, MissionLog
from hptrack.runtime.network import (
    Refusal,
    enlarge_receive_buffer,
    kernel_drops,
    parse_detection_line,
    udp_address,
)

logger = logging.getLogger(__name__)
mavsdk_logger = logging.getLogger("mavsdk")


LOG_FAILURES = ("continue", "hold")
"""What a flight does when its mission log stops growing."""
FLIGHT_BOUNDS: dict[str, tuple[float, float, bool]] = {
    "altitude_m": (0.0, 1e4, False),
    "max_distance_m": (0.0, 1e6, False),
    "setpoint_rate_hz": (10.0, 1000.0, True),
    "lost_link_s": (0.0, 600.0, False),
    "connect_timeout_s": (0.0, 3600.0, False),
    "takeoff_timeout_s": (0.0, 86400.0, False),
    "first_plan_timeout_s": (0.0, 86400.0, False),
}
"""The numbers `FlightOptions` accepts: ``(low, high, low included)``, the value at most
``high`` (m, Hz, s)."""


@dataclass(frozen=True)
class FlightOptions:
    """How ``hptrack fly`` connects and flies (m, s, Hz).

    Attributes:
        connection: MAVSDK connection URL (``udpin://127.0.0.1:14540`` listens on loopback,
            ``udpin://0.0.0.0:14540`` on every interface, ``serial:///dev/...``).
        detections: where detections arrive, ``udp://HOST:PORT`` (bound here).
        altitude_m: mission altitude above the local origin, m.
        max_distance_m: a setpoint farther than this from home ends the mission, m.
        takeoff: arm and take off to ``altitude_m`` first.
        return_to_launch: end in return-to-launch instead of hold.
        setpoint_rate_hz: offboard setpoints per second (PX4 needs more than 2).
        lost_link_s: no telemetry for this long ends the mission, s.
        connect_timeout_s: wait for an autopilot at most this long, s.
        takeoff_timeout_s: wait for the take-off altitude at most this long, s.
        first_plan_timeout_s: wait for the planner's first plan at most this long, s.
        log_failure: when the mission log stops growing, ``"continue"`` (say it and fly on)
            or ``"hold"`` (end the mission in hold).
        intake: the bounds of the detection intake (its slice is one setpoint period).
        fence_action: PX4's ``GF_ACTION`` set with a fence (`FENCE_ACTIONS`; 2, hold).
        fence_from_vehicle: fly the fence the vehicle holds instead of uploading the
            scenario's.
    """

    connection: str = "udpin://127.0.0.1:14540"
    detections: str = "udp://127.0.0.1:5005"
    altitude_m: float = 30.0
    max_distance_m: float = 1000.0
    takeoff: bool = False
    return_to_launch: bool = False
    setpoint_rate_hz: float = 20.0
    lost_link_s: float = 3.0
    connect_timeout_s: float = 30.0
    takeoff_timeout_s: float = 120.0
    first_plan_timeout_s: float = 600.0
    log_failure: str = "continue"
    intake: IntakeLimits = field(default_factory=IntakeLimits)
    fence_action: int = 2
    fence_from_vehicle: bool = False

    def __post_init__(self) -> None:
        """Raises `ValueError` (one line naming the field and the value) for a number outside
        `FLIGHT_BOUNDS` or an unknown ``log_failure``."""
        for name, (low, high, closed) in FLIGHT_BOUNDS.items():
            value = getattr(self, name)
            inside = low <= value if closed else low < value
            if isinstance(value, bool) or not (math.isfinite(value) and inside and value <= high):
                interval = f"{'[' if closed else '('}{low:g}, {high:g}]"
                raise ValueError(f"{name} must be a number in {interval}, got {value}")
        if isinstance(self.fence_action, bool) or self.fence_action not in FENCE_ACTIONS:
            raise ValueError(
                f"fence_action {self.fence_action!r}: expected one of 0..5 (PX4's GF_ACTION: "
                + ", ".join(f"{k} {v}" for k, v in FENCE_ACTIONS.items())
                + ")"
            )
        if self.log_failure not in LOG_FAILURES:
            raise ValueError(
                f"log_failure {self.log_failure[:40]!r}: expected {' or '.join(LOG_FAILURES)}"
            )

    def as_json(self) -> dict:
        """The options as JSON data (for the log's header)."""
        return dataclasses.asdict(self)


WAIT_PROGRESS_S = 5.0
"""How often ``fly`` says it is still waiting for the autopilot, s (at least twice in a shorter
wait)."""
TAKEOFF_DONE_TOLERANCE_M = 1.0
"""A take-off that ends (TAKEOFF -> HOLD) at most this below the mission altitude, counted from
the height where it began, is done, m. PX4 ends its take-off within ``NAV_MC_ALT_RAD`` (0.8 m by
default) of the altitude above its home, which it sets at arming, and the local position's
height there is rarely 0 (PX4 SIH's EKF puts it some tenths of a metre above or below its local
origin)."""
OFFBOARD_CONFIRM_S = 2.0
"""How long ``fly`` streams setpoints after starting offboard for the vehicle to report
OFFBOARD, s (a heartbeat once a second shows the change within about 1 s)."""
OFFBOARD_ATTEMPTS = 3
"""How many times ``fly`` starts offboard before giving up."""
PILOT_TOOK_OVER = "pilot took over"
"""The end of a mission whose vehicle left OFFBOARD (a pilot's switch or a failsafe)."""
LEFT_TO_PILOT = "left to the pilot"
"""The action of that end: nothing is commanded."""
FOLLOW_DISTANCE_M = 10.0
"""The vehicle farther than this from its reference ..., m."""
FOLLOW_CLOSING_M_S = 0.5
"""... and closing on it slower than this, m/s ..."""
FOLLOW_PERSIST_S = 3.0
"""... for this long is not following, s: ``fly`` warns (console and log)."""
FOLLOW_WARN_EVERY_S = 10.0
"""At most one not-following warning in this long, s."""
AUTOPILOT_COMPONENT = 1
"""MAVLink's ``MAV_COMP_ID_AUTOPILOT1``: the component flown when the system has several."""


@dataclass(frozen=True)
class VehicleLimits:
    """What the vehicle says it can fly (PX4 parameters; ``None`` where it did not say).

    Attributes:
        speed_m_s: horizontal speed limit (``MPC_XY_VEL_MAX``), m/s.
        acceleration_m_s2: horizontal acceleration limit (``MPC_ACC_HOR``), m/s^2.
        detail: one line on where the figures come from.
    """

    speed_m_s: float | None
    acceleration_m_s2: float | None
    detail: str


class FlightError(Exception):
    """The mission could not start (no autopilot, no position, arming refused, a failed
    take-off, offboard never entered...); the message is one line, ``reason`` a short name
    (``"take-off failed"``, ``"offboard refused"``, ``"could not start"``...)."""

    def __init__(self, message: str, reason: str = "could not start") -> None:
        super().__init__(message)
        self.reason = reason


@dataclass
class FlightResult:
    """How a flight ended.

    Attributes:
        reason: ``"budget"``, ``"interrupted"``, ``"lost link"``, ``"geofence"``,
            ``"offboard error"``, ``"pilot took over"``, ``"log failure"`` or
            ``"controller error"``.
        detail: one line with the figures.
        action: ``"hold"``, ``"return to launch"`` or ``"left to the pilot"`` (the
            pilot took over: nothing commanded).
        confirmed: the flight mode telemetry reported after the switch, or ``None``.
        end: the controller's ``end`` record.
        setpoints_sent: offboard setpoints streamed.
        setpoint_rate_hz: their mean rate over the mission.
        max_setpoint_gap_s: the longest time between two setpoints sent, s.
        intake: the detection intake's counts (lines received, handled, dropped by reason).
        log_stopped: why the mission log stopped growing, or ``None``.
        error: the traceback of a controller error.
        foreign_odometry: odometry messages refused from other MAVLink sources, by source.
        follow_warnings: how many times the vehicle was said not to follow its reference.
    """

    reason: str
    detail: str
    action: str
    confirmed: str | None
    end: dict
    setpoints_sent: int
    setpoint_rate_hz: float
    max_setpoint_gap_s: float = 0.0
    intake: dict = field(default_factory=dict)
    log_stopped: str | None = None
    error: str | None = None
    foreign_odometry: dict[str, int] = field(default_factory=dict)
    follow_warnings: int = 0


@dataclass
class _Vehicle:
    """What telemetry last said."""

    position_ned: np.ndarray | None = None
    velocity_ned: np.ndarray = field(default_factory=lambda: np.zeros(3))
    received_at: float = -math.inf
    flight_mode: Any = None
    armed: bool = False
    in_air: bool = False


_WHY = {
    "NO_SETPOINT_SET": "no setpoint was streaming before the switch",
    "COMMAND_DENIED": "the vehicle refused it (a pre-flight check or its current state)",
    "COMMAND_DENIED_NOT_LANDED": "the vehicle refused it because it is not on the ground",
    "COMMAND_DENIED_LANDED_STATE_UNKNOWN": "the vehicle does not know whether it is landed",
    "TIMEOUT": "the vehicle did not answer (the link may be lost)",
    "CONNECTION_ERROR": "the link to the vehicle failed",
    "NO_SYSTEM": "no vehicle is connected",
    "BUSY": "the vehicle was busy with another command",
    "DOES_NOT_EXIST": "the vehicle has no such parameter (not PX4?)",
    "WRONG_TYPE": "the parameter has another type on this vehicle",
}
_TODO = {
    "NO_SETPOINT_SET": "this is a bug of hptrack: report it with the mission log",
    "COMMAND_DENIED": "look at the vehicle's messages in a ground station (QGroundControl or "
    "the PX4 console), fix the cause and fly again",
    "TIMEOUT": "check the link and watch the vehicle with a ground station; PX4 leaves offboard "
    "by itself after COM_OF_LOSS_T (1 s by default) and applies its offboard-loss failsafe",
    "CONNECTION_ERROR": "check the link and watch the vehicle with a ground station",
    "NO_SYSTEM": "check the link and watch the vehicle with a ground station",
    "BUSY": "wait a moment and fly again",
}


def plain_error(
    err: ActionError | OffboardError | ParamError | GeofenceError, doing: str, now: str
) -> str:
    """One sentence for a MAVSDK error raised while ``doing`` (``"switching to offboard"``):
    what happened, what the vehicle does ``now``, what to do."""
    result = err.result.name
    why = _WHY.get(result, f"MAVSDK said {result}")
    todo = _TODO.get(result, "watch the vehicle with a ground station")
    return f"{doing} failed: {why}; {now}; {todo}."


def _route_mavsdk_logs() -> None:
    levels = {
        LogLevel.DEBUG: logging.DEBUG,
        LogLevel.INFO: logging.INFO,
        LogLevel.WARN: logging.WARNING,
        LogLevel.ERROR: logging.ERROR,
    }

    def handler(level: LogLevel, message: str, _file: str | None, _line: int) -> bool:
        mavsdk_logger.log(levels.get(level, logging.INFO), "%s", message)
        return True

    log_subscribe(handler)


class _Flight:
    def __init__(
        self,
        controller: MissionController | None,
        options: FlightOptions,
        on_status: Callable[[dict], None],
        on_message: Callable[[str], None],
        stop: asyncio.Event,
        log: MissionLog | None = None,
    ) -> None:
        self.controller, self.options = controller, options
        self.log = log if log is not None else controller.log
        self.on_status, self.on_message, self.stop = on_status, on_message, stop
        self.vehicle = _Vehicle()
        self.mono0: float | None = None
        self.unix0: float | None = None
        self.error: str | None = None
        self.sent = 0
        self.max_gap_s = 0.0
        self.recent: deque[float] = deque(maxlen=200)
        self.home: np.ndarray | None = None
        self.early: list[dict] = []
        self.intake: DetectionIntake | None = None
        self.log_failure_said = False
        self.system_id: int | None = None
        self.component_id: int | None = None
        self.foreign: dict[str, int] = {}
        self.not_following_since: float | None = None
        self.follow_warned_at = -math.inf
        self.follow_warnings = 0

    def say(self, message: str, *, show: bool = True, kind: str = "status", **fields: Any) -> None:
        """Log ``message`` as a ``kind`` record (``status`` unless told) with ``fields``, and
        show it unless not ``show``."""
        record = {"kind": kind, "t": self.mission_time(), "message": message, **fields}
        if self.controller is None:  # the log starts with the controller's header
            self.early.append({**record, "said_at_unix_s": time.time()})
        else:
            self.log.write(record)
        if show:
            self.on_message(message)

    def log_failed(self) -> bool:
        """Say once that the mission log stopped growing; ``True`` if the flight must then
        hold (``log_failure`` is ``"hold"``)."""
        if self.log.stopped is None:
            return False
        hold = self.options.log_failure == "hold"
        if not self.log_failure_said:
            self.log_failure_said = True
            then = (
                "the mission ends in hold (--on-log-failure hold)"
                if hold
                else "the flight goes on without a log (--on-log-failure continue)"
            )
            self.on_message(f"logging stopped: --log {self.log.path}: {self.log.stopped}; {then}")
        return hold

    def attach(self, controller: MissionController) -> None:
        """The mission's controller, built once the vehicle's limits are known; the messages
        said before it follow its header in the log."""
        self.controller = controller
        for record in self.early:
            self.log.write(record)
        self.early.clear()

    def mission_time(self) -> float | None:
        return None if self.mono0 is None else time.monotonic() - self.mono0

    def mode_name(self) -> str:
        return getattr(self.vehicle.flight_mode, "name", None) or "an unknown mode"

    def _guard(self, call: Callable[[], Any]) -> None:
        """Run a controller call; an exception is a controller error that ends the mission."""
        try:
            call()
        except Exception:  # noqa: BLE001 - recorded, then the mission ends safely
            if self.error is None:
                self.error = traceback.format_exc()
            self.stop.set()

    # --- inputs ---------------------------------------------------------------------------
    def refuse_source(self, system_id: int, component_id: int) -> None:
        """Count a position message from another MAVLink source; say the first one."""
        source = f"system {system_id} component {component_id}"
        self.foreign[source] = self.foreign.get(source, 0) + 1
        if self.foreign[source] == 1:
            self.say(
                f"refusing odometry from MAVLink {source} (another vehicle on "
                f"{self.options.connection}?): this flight flies system {self.system_id} "
                f"component {self.component_id} only",
                kind="foreign",
                system_id=system_id,
                component_id=component_id,
            )

    async def watch_position(self, direct: MavlinkDirectAsync) -> None:
        """The locked vehicle's ``LOCAL_POSITION_NED`` into the controller; another
        component's is refused."""
        async for msg in direct.subscribe_message("LOCAL_POSITION_NED"):
            now = time.monotonic()
            if (msg.system_id, msg.component_id) != (self.system_id, self.component_id):
                self.refuse_source(msg.system_id, msg.component_id)
                continue
            try:
                fields = json.loads(msg.fields_json)
                ned = np.array([float(fields[k]) for k in ("x", "y", "z")])
                velocity = np.array([float(fields[k]) for k in ("vx", "vy", "vz")])
            except (ValueError, KeyError, TypeError):
                continue
            self.vehicle.position_ned, self.vehicle.received_at = ned, now
            self.vehicle.velocity_ned = velocity
            if self.mono0 is not None:
                east, north, _ = ned_to_enu(*ned)
                t = now - self.mono0
                self._guard(lambda t=t, p=(east, north): self.feed_odometry(t, p))

    def feed_odometry(self, t: float, position: tuple[float, float]) -> None:
        """The vehicle's position (east, north) m at mission time ``t`` s into the
        controller."""
        self.controller.odometry(t, position)

    async def watch_other_systems(self, mavsdk: Mavsdk) -> None:
        """Count the position messages of every other system on the connection (checked
        once a second)."""
        watched: dict[int, asyncio.Task] = {}

        async def count(system: Any) -> None:
            async for msg in MavlinkDirectAsync(system).subscribe_message("LOCAL_POSITION_NED"):
                self.refuse_source(msg.system_id, msg.component_id)

        try:
            while True:
                for system in await mavsdk.get_systems():
                    system_id = await system.get_system_id()
                    if system_id != self.system_id and system_id not in watched:
                        watched[system_id] = asyncio.create_task(count(system))
                await asyncio.sleep(1.0)
        finally:
            for task in watched.values():
                task.cancel()

    async def watch_state(self, telemetry: TelemetryAsync) -> None:
        async def modes() -> None:
            async for mode in telemetry.subscribe_flight_mode():
                previous, self.vehicle.flight_mode = self.vehicle.flight_mode, mode
                if mode != previous:
                    was = "" if previous is None else f"{previous.name} -> "
                    self.say(
                        f"vehicle mode {was}{mode.name}",
                        kind="vehicle",
                        flight_mode=mode.name,
                        armed=self.vehicle.armed,
                    )

        async def armed() -> None:
            async for value in telemetry.subscribe_armed():
                previous, self.vehicle.armed = self.vehicle.armed, bool(value)
                if self.vehicle.armed != previous:
                    self.say(
                        f"vehicle {'armed' if value else 'disarmed'}",
                        kind="vehicle",
                        flight_mode=getattr(self.vehicle.flight_mode, "name", None),
                        armed=self.vehicle.armed,
                    )

        async def in_air() -> None:
            async for value in telemetry.subscribe_in_air():
                self.vehicle.in_air = bool(value)

        async def texts() -> None:
            async for text in telemetry.subscribe_status_text():
                if text.type.value >= StatusTextType.WARNING.value:
                    self.say(
                        f"vehicle says ({text.type.name}): {text.text}",
                        kind="vehicle_text",
                        severity=text.type.name,
                        text=text.text,
                    )

        await asyncio.gather(modes(), armed(), in_air(), texts())

    def detection_line(self, line: bytes, received: float | None) -> None:
        """One line of a detection datagram, received at mission time ``received`` (``None``
        before offboard started), into the controller (run by the detection intake)."""
        controller = self.controller
        if received is None:
            controller.bad_input(
                "detection", "before the start", "arrived before offboard started", line[:200]
            )
            return
        try:
            text = line.decode("utf-8")
        except UnicodeDecodeError:
            controller.bad_input(
                "detection", "malformed", "a line that is not UTF-8 text", line[:200]
            )
            return
        parsed = parse_detection_line(text)
        if isinstance(parsed, Refusal):
            controller.bad_input("detection", parsed.reason, parsed.detail, text[:200])
            return
        t = received if parsed.stamp is None else parsed.stamp - self.unix0
        controller.detection(
            t, parsed.target, parsed.position, parsed.covariance, parsed.confidence, parsed.vehicle
        )

    # --- the mission ----------------------------------------------------------------------
    async def wait_for(
        self, check: Callable[[], bool], timeout_s: float, interruptible: bool = True
    ) -> bool:
        """Poll ``check`` every 50 ms for at most ``timeout_s`` (or until Ctrl-C)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline and not (interruptible and self.stop.is_set()):
            if check():
                return True
            await asyncio.sleep(0.05)
        return check()

    def status(self, t: float, home: np.ndarray) -> dict:
        now = time.monotonic()
        while self.recent and now - self.recent[0] > 2.0:
            self.recent.popleft()
        ned = self.vehicle.position_ned
        east, north, up = ned_to_enu(*ned)
        return {
            **self.controller.status(),
            "t": t,
            "flight_mode": getattr(self.vehicle.flight_mode, "name", None),
            "setpoint_rate_hz": len(self.recent) / 2.0,
            "altitude_m": up,
            "distance_from_home_m": float(np.hypot(east - home[0], north - home[1])),
            "link_age_s": now - self.vehicle.received_at,
            "dropped_lines": 0 if self.intake is None else self.intake.dropped_total,
        }

    def position_enu(self) -> np.ndarray:
        east, north, _ = ned_to_enu(*self.vehicle.position_ned)
        return np.array([east, north])

    def height_m(self) -> float:
        """The vehicle's height above the local origin, m."""
        return float(-self.vehicle.position_ned[2])

    def check_following(self, t: float, reference: np.ndarray) -> None:
        """Warn (console and log, at most every `FOLLOW_WARN_EVERY_S`) when the vehicle has
        been farther than `FOLLOW_DISTANCE_M` from its ``reference`` (ENU, m) and closing on
        it slower than `FOLLOW_CLOSING_M_S` for `FOLLOW_PERSIST_S` at mission time ``t``."""
        gap = np.asarray(reference, dtype=float) - self.position_enu()
        distance = float(np.hypot(*gap))
        east, north, _ = ned_to_enu(*self.vehicle.velocity_ned)
        closing = float(np.dot([east, north], gap) / distance) if distance > 0 else 0.0
        if distance <= FOLLOW_DISTANCE_M or closing >= FOLLOW_CLOSING_M_S:
            self.not_following_since = None
            return
        if self.not_following_since is None:
            self.not_following_since = t
        lasting = t - self.not_following_since
        if lasting >= FOLLOW_PERSIST_S and t - self.follow_warned_at >= FOLLOW_WARN_EVERY_S:
            self.follow_warned_at = t
            self.follow_warnings += 1
            self.say(
                f"warning: the vehicle is not moving towards its reference: {distance:.1f} m "
                f"away, closing at {closing:.1f} m/s for {lasting:.1f} s (vehicle in "
                f"{self.mode_name()})",
                warning="not following",
                distance_m=distance,
                closing_m_s=closing,
            )

    async def start_offboard(self, offboard: OffboardAsync, first: tuple[Any, Any]) -> None:
        """Start offboard, streaming the ``first`` setpoint, until the vehicle reports
        OFFBOARD (`OFFBOARD_ATTEMPTS` tries of `OFFBOARD_CONFIRM_S`).

        Raises:
            FlightError: it never entered OFFBOARD (offboard stopped, the vehicle holds).
        """
        period = 1.0 / self.options.setpoint_rate_hz
        why = ""
        for attempt in range(1, OFFBOARD_ATTEMPTS + 1):
            try:
                await offboard.start()
                why = (
                    f"it accepted offboard but did not enter OFFBOARD within "
                    f"{OFFBOARD_CONFIRM_S:g} s"
                )
            except OffboardError as err:
                why = plain_error(err, "switching to offboard", "it stays where it is")
                why = why[0].lower() + why[1:].rstrip(".")
            deadline = time.monotonic() + OFFBOARD_CONFIRM_S
            while time.monotonic() < deadline and not self.stop.is_set():
                if self.vehicle.flight_mode == FlightMode.OFFBOARD:
                    return
                with contextlib.suppress(OffboardError):
                    await offboard.set_position_velocity_ned(*first)
                await asyncio.sleep(period)
            if self.vehicle.flight_mode == FlightMode.OFFBOARD:
                return
            if self.stop.is_set():
                break
            if attempt < OFFBOARD_ATTEMPTS:
                self.say(
                    f"offboard not entered ({why}; the vehicle reports {self.mode_name()}); "
                    f"starting it again ({attempt + 1} of {OFFBOARD_ATTEMPTS})"
                )
        with contextlib.suppress(OffboardError):
            await offboard.stop()
        if self.stop.is_set():
            raise FlightError("interrupted before the mission started", reason="interrupted")
        raise FlightError(
            f"the vehicle did not enter OFFBOARD in {OFFBOARD_ATTEMPTS} attempts of "
            f"{OFFBOARD_CONFIRM_S:g} s ({why}; it reports {self.mode_name()}); offboard "
            "stopped, the vehicle was told to hold; look at its messages in a ground station",
            reason="offboard refused",
        )

    async def fly(self, system: Any) -> tuple[str, str]:
        """Stream setpoints until a safe end; returns its ``(reason, detail)``."""
        options, controller = self.options, self.controller
        offboard = OffboardAsync(system)
        home = self.home = self.position_enu()
        n, e, d = enu_to_ned(home[0], home[1], options.altitude_m)
        first = (PositionNedYaw(n, e, d, 0.0), VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        await offboard.set_position_velocity_ned(*first)
        await self.start_offboard(offboard, first)
        self.unix0 = time.time()  # first: the intake's thread stamps lines once mono0 is set
        self.mono0 = time.monotonic()
        self.say(
            MISSION_START_MESSAGE,
            unix_time=self.unix0,
            home=home,
            altitude_m=options.altitude_m,
        )
        period = 1.0 / options.setpoint_rate_hz
        next_at = self.mono0
        next_status = self.mono0
        last_sent: float | None = None
        while True:
            now = time.monotonic()
            t = now - self.mono0
            if self.error is None and self.intake is not None:
                self.error = self.intake.error
            if self.error is not None:
                return "controller error", self.error.strip().splitlines()[-1]
            if self.stop.is_set():
                return "interrupted", "Ctrl-C or a termination signal"
            if self.log_failed():
                return "log failure", f"the mission log stopped ({self.log.stopped})"
            if self.vehicle.flight_mode != FlightMode.OFFBOARD:
                return PILOT_TOOK_OVER, (
                    f"the vehicle left OFFBOARD for {self.mode_name()} at mission time "
                    f"{t:.1f} s (a pilot or a failsafe took over)"
                )
            link_age = now - self.vehicle.received_at
            if link_age > options.lost_link_s:
                return "lost link", (
                    f"no telemetry for {link_age:.1f} s (limit {options.lost_link_s:g} s)"
                )
            try:
                setpoint = controller.setpoint(t)
            except Exception:  # noqa: BLE001 - a controller bug ends the mission safely
                self.error = traceback.format_exc()
                continue
            if controller.finished:
                return controller.end["reason"], f"mission time {t:.1f} s"
            distance = float(np.hypot(*(setpoint.position - home)))
            if distance > options.max_distance_m:
                return "geofence", (
                    f"setpoint {distance:.0f} m from home, beyond --max-distance "
                    f"{options.max_distance_m:g} m"
                )
            self.check_following(t, setpoint.reference)
            x, y = setpoint.reference
            n, e, d = enu_to_ned(x, y, options.altitude_m)
            v_n, v_e, _ = enu_to_ned(setpoint.velocity[0], setpoint.velocity[1], 0.0)
            try:
                await offboard.set_position_velocity_ned(
                    PositionNedYaw(n, e, d, 0.0), VelocityNedYaw(v_n, v_e, 0.0, 0.0)
                )
            except OffboardError as err:
                return "offboard error", plain_error(
                    err, "sending a setpoint", f"the vehicle reports {self.mode_name()}"
                )
            self.sent += 1
            sent_at = time.monotonic()
            if last_sent is not None:
                self.max_gap_s = max(self.max_gap_s, sent_at - last_sent)
            last_sent = sent_at
            self.recent.append(sent_at)
            if now >= next_status:
                self.on_status(self.status(t, home))
                next_status = now + 0.25
            next_at += period
            await asyncio.sleep(max(0.0, next_at - time.monotonic()))

    async def safe_end(self, system: Any, reason: str, detail: str) -> tuple[str, str | None]:
        """Switch to hold (offboard stop) or return-to-launch; returns the action and the
        confirmed flight mode."""
        if not self.controller.finished:
            self.controller.finish(self.mission_time() or 0.0, reason)
        if self.home is not None:
            self.on_status(self.status(self.mission_time(), self.home))
        if reason == PILOT_TOOK_OVER:
            return self.leave_to_pilot(detail)
        rtl = self.options.return_to_launch
        action, wanted = (
            ("return to launch", (FlightMode.RETURN_TO_LAUNCH, FlightMode.LAND))
            if rtl
            else ("hold", (FlightMode.HOLD,))
        )
        self.say(f"mission ended ({reason}: {detail}); switching to {action}")
        error = None
        try:
            if rtl:
                await ActionAsync(system).return_to_launch()
            else:
                try:
                    await OffboardAsync(system).stop()
                except OffboardError:
                    await ActionAsync(system).hold()
        except (ActionError, OffboardError) as err:
            error = plain_error(
                err,
                f"switching to {action}",
                f"the vehicle last reported {self.mode_name()}",
            )
        # a refused or unanswered command leaves nothing to wait for
        confirmed = await self.wait_for(
            lambda: self.vehicle.flight_mode in wanted, 0.0 if error else 5.0, interruptible=False
        )
        mode = getattr(self.vehicle.flight_mode, "name", None)
        record = {
            "kind": "safety",
            "t": self.mission_time(),
            "reason": reason,
            "detail": detail,
            "action": action,
            "confirmed": mode if confirmed else None,
        }
        if error:
            record["error"] = error
        self.log.write(record)
        if self.home is not None:  # the live view ends in the vehicle's real mode
            self.on_status(self.status(self.mission_time(), self.home))
        self.on_message(
            f"vehicle in {mode} (confirmed)"
            if confirmed
            else error or f"the vehicle did not confirm {action}; it last reported {mode}"
        )
        return action, mode if confirmed else None

    def leave_to_pilot(self, detail: str) -> tuple[str, str | None]:
        """End a mission whose vehicle left OFFBOARD: command nothing (the pilot or the
        failsafe has it; MAVSDK stops its setpoints by itself), log and say so."""
        mode = getattr(self.vehicle.flight_mode, "name", None)
        self.log.write(
            {
                "kind": "safety",
                "t": self.mission_time(),
                "reason": PILOT_TOOK_OVER,
                "detail": detail,
                "action": LEFT_TO_PILOT,
                "confirmed": mode,
            }
        )
        self.on_message(
            f"the pilot took over: {detail}; hptrack commands nothing more, the vehicle is "
            f"in {mode}"
        )
        return LEFT_TO_PILOT, mode


async def read_limits(system: Any) -> VehicleLimits:
    """The vehicle's horizontal speed and acceleration limits (PX4 parameters)."""
    param = ParamAsync(system)
    values: dict[str, float | None] = {}
    missing = []
    for name in ("MPC_XY_VEL_MAX", "MPC_ACC_HOR"):
        try:
            values[name] = float(await param.get_param_float(name))
        except ParamError as err:
            values[name] = None
            missing.append(f"{name} ({err.result.name})")
    speed, acceleration = values["MPC_XY_VEL_MAX"], values["MPC_ACC_HOR"]
    detail = (
        f"MPC_XY_VEL_MAX {speed:g} m/s, MPC_ACC_HOR {acceleration:g} m/s^2"
        if not missing
        else f"could not read {', '.join(missing)}"
    )
    return VehicleLimits(speed, acceleration, detail)


def _geofence_data(zones: list[GeoZone]) -> GeofenceData:
    """MAVSDK's geofence of ``zones``."""
    kinds = {True: FenceType.INCLUSION, False: FenceType.EXCLUSION}
    return GeofenceData(
        polygons=[
            Polygon([Point(lat, lon) for lat, lon in z.points], kinds[z.inclusion])
            for z in zones
            if z.radius_m is None
        ],
        circles=[
            Circle(Point(*z.points[0]), z.radius_m, kinds[z.inclusion])
            for z in zones
            if z.radius_m is not None
        ],
    )


def _zones(data: GeofenceData) -> list[GeoZone]:
    """The zones of MAVSDK's geofence ``data``: inclusions first, then the polygons and the
    circles in the vehicle's order."""
    polygons = [
        GeoZone(
            p.fence_type == FenceType.INCLUSION,
            tuple((q.latitude_deg, q.longitude_deg) for q in p.points),
        )
        for p in data.polygons
    ]
    circles = [
        GeoZone(
            c.fence_type == FenceType.INCLUSION,
            ((c.point.latitude_deg, c.point.longitude_deg),),
            float(c.radius),
        )
        for c in data.circles
    ]
    zones = polygons + circles
    return [z for z in zones if z.inclusion] + [z for z in zones if not z.inclusion]


async def sync_fence(
    flight: _Flight,
    system: Any,
    fence: FenceSpec | None,
    origin: tuple[float, float] | None = None,
) -> FenceSpec | None:
    """Put the scenario's ``fence`` on the vehicle (upload, download, compare within
    `FENCE_TOLERANCE_M`) or, with ``fence_from_vehicle``, take the vehicle's (the scenario's
    margin kept); set ``GF_ACTION``; log a ``geofence`` record. Returns the fence to fly (the
    scenario's itself once the vehicle holds it), or ``None`` (no fence in the scenario: the
    vehicle's is left alone). The fence's metres are from ``origin`` (latitude, longitude,
    degrees; a team's frame, the first vehicle's), by default the vehicle's own
    ``GPS_GLOBAL_ORIGIN``.

    Raises:
        InputError: the vehicle's fence differs from the scenario's, or cannot be flown.
        FlightError: the vehicle did not answer the fence protocol or the parameter.
    """
    options = flight.options
    if fence is None and not options.fence_from_vehicle:
        return None
    if origin is None:
        try:
            origin_msg = await TelemetryAsync(system).get_gps_global_origin()
        except TelemetryError as err:
            raise FlightError(
                f"the vehicle gave no GPS_GLOBAL_ORIGIN ({err}): the fence cannot be placed; "
                "nothing was flown"
            ) from None
        origin = (float(origin_msg.latitude_deg), float(origin_msg.longitude_deg))
    geofence = GeofenceAsync(system)
    margin = fence.margin if fence is not None else 0.0
    try:
        if not options.fence_from_vehicle:
            await geofence.upload_geofence(_geofence_data(to_geodetic(fence, origin)))
        held = _zones(await geofence.download_geofence())
    except GeofenceError as err:
        doing = "uploading the fence" if not options.fence_from_vehicle else "reading its fence"
        raise FlightError(
            plain_error(err, doing, "the vehicle is still on the ground; nothing was flown")
        ) from None
    try:
        flown = from_geodetic(held, origin, margin)
    except ValueError as err:
        where = "--fence-from-vehicle" if options.fence_from_vehicle else "the uploaded fence"
        raise InputError(f"{where}: {err}") from None
    if options.fence_from_vehicle:
        if not held:
            raise InputError("--fence-from-vehicle: the vehicle holds no fence")
        source = "the vehicle's"
    else:
        difference = fence_difference(fence, flown)
        if difference is not None:
            raise InputError(
                f"the vehicle's fence differs from the scenario's after the upload: "
                f"{difference}; nothing was flown"
            )
        source = f"the scenario's, uploaded and read back (within {FENCE_TOLERANCE_M:g} m)"
    action = options.fence_action
    try:
        await ParamAsync(system).set_param_int("GF_ACTION", action)
    except ParamError as err:
        raise FlightError(
            plain_error(err, f"setting GF_ACTION to {action}", "nothing was flown")
        ) from None
    flight.say(
        f"fence: {source}, {fence_summary(flown)}; GF_ACTION {action} "
        f"({FENCE_ACTIONS[action]}) on a breach",
        kind="geofence",
        source="vehicle" if options.fence_from_vehicle else "scenario",
        origin=list(origin),
        action=action,
        fence=fence_block(flown),
    )
    return flown if options.fence_from_vehicle else fence


async def say_fence_margin(flight: _Flight, system: Any, speed: float, margin: float) -> None:
    """Say the fence's margin (m) beside the vehicle's tracking lag at the planned ``speed``
    (m/s): `tracking_lag_m` with PX4's measured `PX4_VELOCITY_TRACKING` and the vehicle's
    ``MPC_XY_P``; a margin below it is warned of (the vehicle may cross the margin's edge by
    the difference)."""
    try:
        gain = float(await ParamAsync(system).get_param_float("MPC_XY_P"))
    except ParamError:
        flight.say(f"fence margin {margin:g} m; the vehicle's MPC_XY_P is unknown (not PX4?)")
        return
    lag = tracking_lag_m(speed, PX4_VELOCITY_TRACKING, gain)
    flight.say(
        f"fence margin {margin:g} m; tracking lag at {speed:g} m/s {lag:.1f} m (PX4 flies "
        f"{PX4_VELOCITY_TRACKING:g} of its velocity setpoint, MPC_XY_P {gain:g} 1/s)"
        + (
            f"; the margin is below the lag: the vehicle may fly up to {lag - margin:.1f} m "
            "past the fence"
            if margin < lag
            else ""
        ),
        kind="geofence",
        margin_m=margin,
        lag_m=lag,
        speed_m_s=speed,
        mpc_xy_p=gain,
    )


def say_fence_projections(flight: _Flight, controller: MissionController) -> None:
    """Say (and log) how many setpoints the controller projected into the fence's free
    space."""
    flight.say(
        f"{controller.fence_projections} setpoints projected into the fence's free space",
        kind="geofence",
        projections=controller.fence_projections,
    )


async def fly_mission(
    build: Callable[[VehicleLimits, FenceSpec | None], MissionController],
    log: MissionLog,
    options: FlightOptions,
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
    stop: asyncio.Event | None = None,
    fence: FenceSpec | None = None,
) -> FlightResult:
    """Fly the mission of the controller that ``build`` makes from the vehicle's limits and the
    fence flown (`sync_fence` with the scenario's ``fence``), on the vehicle at
    ``options.connection``, logging to ``log`` (module docstring).

    Raises:
        FlightError: the mission could not start (nothing was commanded, or the vehicle was
            switched to hold before raising).
        InputError: the connection or the detection address cannot be opened, or ``build``
            refused the vehicle's limits.
    """
    stop = stop or asyncio.Event()
    flight = _Flight(None, options, on_status, on_message, stop, log)
    host, port = udp_address(options.detections, "--detections")
    _route_mavsdk_logs()
    tasks: list[asyncio.Task] = []
    sock: socket.socket | None = None
    intake: DetectionIntake | None = None
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        try:
            try:
                await mavsdk.add_any_connection(options.connection)
            except MavsdkConnectionError as err:
                raise InputError(connection_problem(options.connection, str(err))) from None
            system = await _first_autopilot(mavsdk, flight)
            await _lock_ids(flight, system)
            telemetry = TelemetryAsync(system)
            tasks = [
                asyncio.create_task(flight.watch_position(MavlinkDirectAsync(system))),
                asyncio.create_task(flight.watch_state(telemetry)),
                asyncio.create_task(flight.watch_other_systems(mavsdk)),
            ]
            if not await flight.wait_for(
                lambda: flight.vehicle.position_ned is not None, options.connect_timeout_s
            ):
                raise FlightError(
                    f"no local position from the vehicle within {options.connect_timeout_s:g} s"
                )
            flight.say("vehicle found; local position received")
            limits = await read_limits(system)
            flown_fence = await sync_fence(flight, system, fence)
            controller = build(limits, flown_fence)
            flight.attach(controller)
            if flown_fence is not None:
                await say_fence_margin(
                    flight, system, controller.mission.agent_speed, flown_fence.margin
                )
            if flight.log_failed():
                raise FlightError(
                    f"the mission log cannot be written ({log.stopped}); nothing was flown"
                )
            sock, drops_before, intake = open_detections(options, host, port, flight)
            started = time.monotonic()
            controller.prepare(flight.position_enu())
            flight.say("computing the first plan (the planner compiles or loads its kernels)")
            if options.takeoff:
                await _take_off(flight, system)
            elif not await flight.wait_for(
                lambda: flight.vehicle.armed and flight.vehicle.in_air, 3.0
            ):
                raise FlightError(
                    "the vehicle is not armed and in the air; pass --takeoff to arm and take off"
                )
            elif not await flight.wait_for(
                lambda: flight.vehicle.flight_mode != FlightMode.TAKEOFF,
                options.takeoff_timeout_s,
            ):
                raise FlightError(
                    f"the vehicle was still taking off after {options.takeoff_timeout_s:g} s; "
                    "offboard never started",
                    reason="take-off failed",
                )
            await wait_for_first_plan(
                flight, controller, options, stop, started, "the vehicle stays in its current mode"
            )
            if flight.log_failed():
                raise FlightError(
                    f"the mission log stopped before the mission started ({log.stopped}); "
                    "the vehicle stays in its current mode (offboard never started)"
                )
            try:
                reason, detail = await flight.fly(system)
            except FlightError:
                raise
            except Exception:  # noqa: BLE001 - end safely first, report after
                flight.error = traceback.format_exc()
                reason, detail = "controller error", flight.error.strip().splitlines()[-1]
            flown_s = flight.mission_time()
            flight.say(
                f"odometry refused from other MAVLink sources: {sum(flight.foreign.values())}",
                show=False,
                foreign_odometry=flight.foreign,
            )
            flight.say(
                f"{flight.sent} setpoints sent in {flown_s:.1f} s, largest gap "
                f"{flight.max_gap_s:.3f} s",
                show=False,
                setpoints=flight.sent,
                mission_time_s=flown_s,
                max_gap_s=flight.max_gap_s,
            )
            if flown_fence is not None:
                say_fence_projections(flight, controller)
            intake.stop()
            _say_intake(flight, intake, drops_before, kernel_drops(sock))
            action, confirmed = await flight.safe_end(system, reason, detail)
        except FlightError as err:
            if flight.controller is not None:  # the log has its header: say why it ends
                log.write({"kind": ABORT, "t": None, "reason": err.reason, "detail": str(err)})
            raise
        finally:
            if intake is not None:
                intake.stop()
            if sock is not None:
                sock.close()
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
            if flight.controller is not None:
                flight.controller.close()
    t = flight.mission_time() or 0.0
    return FlightResult(
        reason,
        detail,
        action,
        confirmed,
        controller.end or {},
        flight.sent,
        flight.sent / t if t > 0 else 0.0,
        flight.max_gap_s,
        intake.counts(),
        log.stopped,
        flight.error,
        dict(flight.foreign),
        flight.follow_warnings,
    )


async def _lock_ids(flight: _Flight, system: Any) -> None:
    """Lock the flight onto the system id of the autopilot found and its autopilot
    component (`AUTOPILOT_COMPONENT` when it has several)."""
    flight.system_id = await system.get_system_id()
    components = await system.component_ids()
    flight.component_id = (
        AUTOPILOT_COMPONENT
        if AUTOPILOT_COMPONENT in components or not components
        else components[0]
    )
    flight.say(
        f"flying MAVLink system {flight.system_id} component {flight.component_id} "
        "(odometry from any other source is refused)",
        system_id=flight.system_id,
        component_id=flight.component_id,
    )


async def _first_autopilot(mavsdk: Mavsdk, flight: _Flight) -> Any:
    """Wait for the first autopilot on the connection, saying at once what is awaited and
    where, then every `WAIT_PROGRESS_S`; a hint on what to start if none comes."""
    options = flight.options
    url, timeout = options.connection, options.connect_timeout_s
    every_s = min(WAIT_PROGRESS_S, timeout / 2)
    flight.say(f"waiting for an autopilot on {url} (at most {timeout:g} s; Ctrl-C stops)")
    started = time.monotonic()
    search = asyncio.ensure_future(mavsdk.first_autopilot(timeout_s=timeout))
    stopping = asyncio.ensure_future(flight.stop.wait())
    try:
        while not search.done():
            await asyncio.wait(
                {search, stopping}, timeout=every_s, return_when=asyncio.FIRST_COMPLETED
            )
            if flight.stop.is_set():
                raise FlightError("interrupted while waiting for the autopilot")
            if not search.done():
                flight.say(
                    f"still waiting for an autopilot on {url} "
                    f"({time.monotonic() - started:.0f} of {timeout:g} s)"
                )
    finally:
        search.cancel()
        stopping.cancel()
    system = search.result()
    if system is None:
        raise FlightError(
            f"no autopilot found on {url} within {timeout:g} s: start the vehicle first (for "
            "a dry run, hptrack vehicle-sim SCENARIO in another terminal; or PX4 SITL, which "
            "sends to 127.0.0.1:14540), or give the vehicle's address with --connection"
        )
    return system


def _say_intake(
    flight: _Flight, intake: DetectionIntake, drops_before: int | None, drops_after: int | None
) -> None:
    """Log the detection intake's counts; show them when lines or datagrams were dropped."""
    counts = intake.counts()
    dropped = intake.dropped_total
    reasons = ", ".join(f"{n} {why}" for why, n in sorted(intake.dropped.items()))
    flight.say(
        f"detection lines: {intake.received} received, {intake.handled} logged, {dropped} "
        f"dropped{f' ({reasons})' if reasons else ''}",
        show=dropped > 0,
        detection_lines=counts,
    )
    if drops_before is not None and drops_after is not None:
        datagrams = drops_after - drops_before
        flight.say(
            f"{datagrams} detection datagrams dropped by the system (receive buffer full)",
            show=datagrams > 0,
            dropped_datagrams=datagrams,
        )


async def wait_for_first_plan(
    flight, controller, options, stop, started: float, stays: str
) -> None:
    """Wait, before offboard, for the controller's first plan (``options.first_plan_timeout_s``)
    and say how long it took (``started``: the take-off phase's start, monotonic s).

    Raises:
        FlightError: interrupted, no plan in time or a failed one (``stays``: what the vehicles
            do then, said in the message).
    """
    if not await flight.wait_for(
        lambda: controller.first_plan(0.0) is not None or controller.planner_error is not None,
        options.first_plan_timeout_s,
    ):
        if stop.is_set():
            raise FlightError("interrupted before the mission started")
        raise FlightError(
            f"the planner gave no first plan within {options.first_plan_timeout_s:g} s; "
            f"{stays} (offboard never started)"
        )
    if controller.first_plan_s is None:
        raise FlightError(
            f"the planner failed on its first plan ({controller.planner_error}); "
            f"{stays} (offboard never started)"
        )
    flight.say(
        f"first plan ready before offboard: {controller.first_plan_s:.2f} s of "
        f"planning, {time.monotonic() - started:.1f} s after the start of the "
        "take-off phase",
        first_plan_s=controller.first_plan_s,
    )
    if stop.is_set():
        raise FlightError("interrupted before the mission started")


def open_detections(options, host: str, port: int, flight) -> tuple[socket.socket, int, Any]:
    """Bind the detection port and start ``flight``'s intake on it (``flight.intake``):
    ``(socket, the kernel's drops so far, the intake)``.

    Raises:
        InputError: the port cannot be bound (the ``--detections`` option named).
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except OSError as err:
        sock.close()
        raise InputError(
            f"--detections {options.detections!r}: cannot receive there ({err.strerror})"
        ) from None
    enlarge_receive_buffer(sock)
    drops_before = kernel_drops(sock)
    intake = flight.intake = DetectionIntake(
        sock,
        flight.detection_line,
        flight.mission_time,
        dataclasses.replace(options.intake, slice_s=1.0 / options.setpoint_rate_hz),
    )
    intake.start()
    return sock, drops_before, intake


async def _take_off(flight: _Flight, system: Any) -> None:
    options = flight.options
    action = ActionAsync(system)
    step = "arming"
    ground_m = flight.height_m()  # PX4 takes off from here (its home, set at arming)
    try:
        flight.say("arming")
        await action.arm()
        step = "setting the take-off altitude"
        await action.set_takeoff_altitude(options.altitude_m)
        flight.say(f"taking off to {options.altitude_m:g} m")
        step = "taking off"
        await action.takeoff()
    except ActionError as err:
        raise FlightError(
            plain_error(err, step, f"the vehicle reports {flight.mode_name()}")
        ) from None

    failure = await _watch_take_off(flight, ground_m)
    if failure is not None:
        if failure.endswith("(switched to hold)"):
            with contextlib.suppress(ActionError):
                await action.hold()
        raise FlightError(
            f"the take-off failed: {failure}; offboard never started",
            reason="interrupted" if failure.startswith("interrupted") else "take-off failed",
        )
    flight.say(
        f"take-off done: {flight.mode_name()} at {flight.height_m():.1f} m "
        f"({flight.height_m() - ground_m:.1f} m above where it began)",
        altitude_m=flight.height_m(),
        ground_m=ground_m,
    )


async def _watch_take_off(flight: _Flight, ground_m: float | None = None) -> str | None:
    """Wait for the take-off's end (TAKEOFF -> HOLD within `TAKEOFF_DONE_TOLERANCE_M` of the
    altitude above ``ground_m``, the height where the take-off began, default the height now);
    ``None`` when it is done, else why it failed, at once: a disarm, a mode other than HOLD
    after TAKEOFF (or HOLD too low), no position for ``lost_link_s``, Ctrl-C, or the take-off
    timeout."""
    options, vehicle = flight.options, flight.vehicle
    ground_m = flight.height_m() if ground_m is None else ground_m
    began = time.monotonic()
    armed_seen = taking_off_seen = False
    while True:
        now = time.monotonic()
        height = flight.height_m()
        mode = vehicle.flight_mode
        where = (
            f"at {height:.1f} m of {options.altitude_m:g} m, {now - began:.1f} s into the take-off"
        )
        armed_seen = armed_seen or vehicle.armed
        taking_off_seen = taking_off_seen or mode == FlightMode.TAKEOFF
        high = height - ground_m >= options.altitude_m - TAKEOFF_DONE_TOLERANCE_M
        if flight.stop.is_set():
            return f"interrupted {where} (switched to hold)"
        if not vehicle.armed and (armed_seen or taking_off_seen):
            return f"the vehicle disarmed {where}"
        if now - vehicle.received_at > options.lost_link_s:
            return (
                f"no position from the vehicle for {now - vehicle.received_at:.1f} s {where} "
                "(its sensors or the link failed)"
            )
        if mode == FlightMode.HOLD and high:
            return None
        if taking_off_seen and mode != FlightMode.TAKEOFF:
            return f"the vehicle left TAKEOFF for {flight.mode_name()} {where}"
        if now - began > options.takeoff_timeout_s:
            return (
                f"the vehicle did not end its take-off at {options.altitude_m:g} m within "
                f"{options.takeoff_timeout_s:g} s (it reports {flight.mode_name()} {where}) "
                "(switched to hold)"
            )
        await asyncio.sleep(0.05)


def run_flight(
    build: Callable[[VehicleLimits, FenceSpec | None], MissionController],
    log: MissionLog,
    options: FlightOptions,
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
    fence: FenceSpec | None = None,
) -> FlightResult:
    """`fly_mission` in its own event loop; Ctrl-C and SIGTERM end the mission safely
    (hold or return) instead of killing the program."""

    async def main() -> FlightResult:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        try:
            return await fly_mission(build, log, options, on_status, on_message, stop, fence)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)

    return asyncio.run(main())
