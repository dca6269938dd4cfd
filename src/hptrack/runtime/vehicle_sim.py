"""A small MAVLink vehicle for dry runs without a drone or a PX4 simulator (pymavlink), made to
behave like PX4 with its SIH quadrotor (figures measured on PX4 main of early 2025; see
docs/flight.md).

It speaks enough of PX4's protocol for MAVSDK: a PX4 quadrotor heartbeat whose custom mode
shows the flight mode (offboard, hold, takeoff, return, land), ``COMMAND_ACK`` for arming, mode
changes, takeoff, return and land, the parameter protocol (``PARAM_REQUEST_READ`` by name or
index, ``PARAM_REQUEST_LIST``, ``PARAM_SET``, each answered by ``PARAM_VALUE``) over PX4's
parameters that matter here (`PX4_PARAMETERS`), ``AUTOPILOT_VERSION`` on request,
``TIMESYNC`` replies, and ``SYS_STATUS``, ``EXTENDED_SYS_STATE``, ``LOCAL_POSITION_NED``,
``GLOBAL_POSITION_INT`` and ``HOME_POSITION`` telemetry, to MAVSDK and optionally to a second
link (a ground station, such as ``hptrack targets-sim``).

Flight as PX4 flies it:

* take-off: the motors spool up for ``COM_SPOOLUP_TIME``, the climb rate ramps up to
  ``MPC_TKO_SPEED`` over ``MPC_TKO_RAMP_T`` and slows in the last metres; then HOLD;
* horizontal motion (offboard, hold, return): PX4's position loop, a commanded velocity
  ``v_ff + MPC_XY_P (p_sp - p)`` (``v_ff`` the setpoint's velocity when it carries one; the
  approach no faster than a stop at the setpoint allows), capped at ``MPC_XY_VEL_MAX``; the
  airframe flies `PX4_VELOCITY_TRACKING` (0.8) of that command, as the SIH quadrotor does, and
  at most its top speed (its drag holds it near 10 m/s at its 45 degree tilt limit), reached
  with at most ``MPC_ACC_HOR``; vertical commands are flown at the same share;
* offboard is refused unless setpoints are streaming, and left for HOLD when they stop for
  ``COM_OF_LOSS_T`` (PX4's offboard-loss failsafe, also when ``hptrack fly`` dies);
* the take-off ends by a TAKEOFF -> HOLD mode change (PX4's AUTO_LOITER, which MAVSDK reports as
  HOLD); offboard entered during the take-off is overridden by that change, as PX4 was seen
  doing;
* the fence: MAVLink's mission protocol for ``MAV_MISSION_TYPE_FENCE`` (upload by
  ``MISSION_COUNT`` / ``MISSION_REQUEST_INT`` / ``MISSION_ITEM_INT`` / ``MISSION_ACK``, download
  from ``MISSION_REQUEST_LIST``, ``MISSION_CLEAR_ALL``) with inclusion and exclusion polygons
  (``param1`` the vertex count) and circles (``param1`` the radius), kept after a link loss;
  armed and in the air, a breach (inside an exclusion, or outside every inclusion) does
  ``GF_ACTION`` once (`hptrack.runtime.geofence.FENCE_ACTIONS`: a ``STATUSTEXT`` warning, hold,
  return, terminate (disarm) or land); ``GPS_GLOBAL_ORIGIN`` on request;
* it speaks as MAVLink system ``system_id``, component ``component_id``, and obeys only
  commands and setpoints addressed to it (so two stubs can share a port).

`Misbehaviour` makes it misbehave as a real vehicle may: refuse offboard (deny it, or accept
it and stay where it is), leave offboard after a while (a pilot switching to POSCTL or HOLD),
or fail its take-off (disarm, lose its sensors, or be switched out of TAKEOFF).

Every mode change is reported through ``on_event`` (the CLI prints it). The scenario's targets
are simulated and detected by `TargetDetector`, the component
``hptrack targets-sim`` uses against a real SITL, fed here with the stub's own position (with the
scenario's detector: misses, false alarms, no ids with ``labelled: false``).
The vehicle starts on the ground at the scenario's agent position.

Loopback addresses only; every loop is bounded by the run's duration.
"""

from __future__ import annotations

import logging
import math
import socket
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink
from shapely.geometry import Point, Polygon

from hptrack.interface import InputError
from hptrack.models.fence import FenceSpec
from hptrack.runtime.frames import (
    EARTH_RADIUS_M,
    enu_to_ned,
    geodetic_to_local,
    local_to_geodetic,
    ned_to_enu,
)
from hptrack.runtime.geofence import FENCE_ACTIONS, GeoZone, to_geodetic
from hptrack.runtime.legs import PX4_VELOCITY_TRACKING
from hptrack.runtime.network import udp_address
from hptrack.runtime.targets import TargetDetector
from hptrack.scenario.model import Scenario

logger = logging.getLogger(__name__)

PX4_MAIN_MODE = {"manual": 1, "posctl": 3, "auto": 4, "offboard": 6}
"""PX4 main modes (``custom_mode`` bits 16-23)."""
PX4_AUTO_SUB_MODE = {"ready": 1, "takeoff": 2, "hold": 3, "mission": 4, "rtl": 5, "land": 6}
"""PX4 auto sub-modes (``custom_mode`` bits 24-31)."""

PX4_PARAMETERS: dict[str, float] = {
    "MPC_XY_VEL_MAX": 12.0,
    "MPC_ACC_HOR": 3.0,
    "MPC_XY_P": 0.95,
    "MPC_XY_CRUISE": 5.0,
    "MPC_TILTMAX_AIR": 45.0,
    "MPC_Z_VEL_MAX_UP": 3.0,
    "MPC_Z_VEL_MAX_DN": 1.5,
    "MPC_TKO_SPEED": 1.5,
    "MPC_TKO_RAMP_T": 3.0,
    "COM_SPOOLUP_TIME": 1.0,
    "COM_OF_LOSS_T": 1.0,
    "MIS_TAKEOFF_ALT": 2.5,
    "RTL_RETURN_ALT": 30.0,
    "NAV_RCL_ACT": 0.0,
    "COM_RCL_EXCEPT": 4.0,
    "GF_ACTION": 2.0,
    "GF_PREDICT": 0.0,
}
"""PX4's defaults (as read over MAVLink from PX4 SITL with the SIH quadrotor): speeds m/s,
accelerations m/s^2, gains 1/s, times s, altitudes m, tilt degrees; ``GF_ACTION`` hold,
``GF_PREDICT`` off (the stub has no breach predictor)."""
INTEGER_PARAMETERS = ("GF_ACTION", "GF_PREDICT")
"""Parameters PX4 keeps as ``INT32`` (sent byte-wise in ``PARAM_VALUE``'s float, as PX4 does)."""

AIRFRAME_SPEED_M_S = 10.0
"""Top horizontal speed of PX4's SIH quadrotor (its drag at the 45 degree tilt limit), m/s."""


_SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_AHRS
    | mavlink.MAV_SYS_STATUS_PREARM_CHECK
)
_HOME_LAT_DEG, _HOME_LON_DEG, _HOME_ALT_M = 47.397742, 8.545594, 488.0
"""The local frame's origin (PX4 SITL's default, Zurich), degrees and m above sea level."""
_FENCE = mavlink.MAV_MISSION_TYPE_FENCE
_FENCE_COMMANDS = {
    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION: (True, False),
    mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION: (False, False),
    mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION: (True, True),
    mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION: (False, True),
}
"""The fence items: ``(inclusion, circle)`` of each command."""
_STREAM_S = 0.5
"""Offboard is accepted only with a setpoint received within this, s (PX4 wants >= 2 Hz)."""
_VELOCITY_IGNORED = 0b111000
"""``type_mask`` bits of ``SET_POSITION_TARGET_LOCAL_NED`` that ignore vx, vy, vz."""


OFFBOARD_REFUSALS = ("deny", "ignore")
"""How `Misbehaviour` refuses offboard: ``"deny"`` (``COMMAND_ACK`` denied) or
``"ignore"`` (accepted, and the mode stays)."""
LEAVE_OFFBOARD_MODES = ("posctl", "hold")
"""The modes `Misbehaviour` leaves offboard for (a pilot's switch)."""
TAKEOFF_FAILURES = ("disarm", "sensors", "posctl")
"""How `Misbehaviour` fails a take-off: ``"disarm"`` (the motors stop, it falls),
``"sensors"`` (its estimator fails: no more local position, health bits cleared, and PX4's
failsafe LAND), ``"posctl"`` (a pilot switches to POSCTL mid-climb)."""


@dataclass(frozen=True)
class Misbehaviour:
    """Switches that make the stub misbehave as a real vehicle may (all off by default).

    Attributes:
        refuse_offboard: ``None``, or how offboard is refused (`OFFBOARD_REFUSALS`).
        leave_offboard_after_s: leave offboard this long after first entering it, s.
        leave_offboard_to: the mode it then switches to (`LEAVE_OFFBOARD_MODES`).
        takeoff_failure: ``None``, or how the take-off fails (`TAKEOFF_FAILURES`).
        takeoff_failure_after_s: that long after the take-off began, s.
        fence_shift_m: keep an uploaded fence moved this far north (a vehicle whose fence
            is not the one sent), m.
    """

    refuse_offboard: str | None = None
    leave_offboard_after_s: float | None = None
    leave_offboard_to: str = "posctl"
    takeoff_failure: str | None = None
    takeoff_failure_after_s: float = 2.0
    fence_shift_m: float = 0.0

    def __post_init__(self) -> None:
        """Raises `ValueError` (one line naming the field and the value) for an unknown
        choice or a time that is not a positive number."""
        for name, value, allowed in (
            ("refuse_offboard", self.refuse_offboard, (None, *OFFBOARD_REFUSALS)),
            ("leave_offboard_to", self.leave_offboard_to, LEAVE_OFFBOARD_MODES),
            ("takeoff_failure", self.takeoff_failure, (None, *TAKEOFF_FAILURES)),
        ):
            if value not in allowed:
                choices = ", ".join(str(a) for a in allowed if a is not None)
                raise ValueError(f"{name} {str(value)[:40]!r}: expected one of {choices}")
        for name in ("leave_offboard_after_s", "takeoff_failure_after_s"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and 0.0 < value <= 86400.0):
                raise ValueError(f"{name} must be a number in (0, 86400], got {value}")
        if not (math.isfinite(self.fence_shift_m) and abs(self.fence_shift_m) <= 1e4):
            raise ValueError(
                f"fence_shift_m must be a number in [-1e4, 1e4], got {self.fence_shift_m}"
            )


def _items(zones: list[GeoZone]) -> list[tuple[int, float, int, int]]:
    """Fence ``zones`` as mission items ``(command, param1, lat 1e7, lon 1e7)``."""
    codes = {value: command for command, value in _FENCE_COMMANDS.items()}
    items = []
    for zone in zones:
        command = codes[(zone.inclusion, zone.radius_m is not None)]
        param1 = zone.radius_m if zone.radius_m is not None else float(len(zone.points))
        items += [(command, param1, round(a * 1e7), round(b * 1e7)) for a, b in zone.points]
    return items


def _custom_mode(mode: str) -> int:
    if mode == "offboard":
        return PX4_MAIN_MODE["offboard"] << 16
    if mode == "posctl":
        return PX4_MAIN_MODE["posctl"] << 16
    return (PX4_MAIN_MODE["auto"] << 16) | (PX4_AUTO_SUB_MODE[mode] << 24)


def _mode_of(main: int, sub: int) -> str | None:
    if main == PX4_MAIN_MODE["offboard"]:
        return "offboard"
    if main == PX4_MAIN_MODE["posctl"]:
        return "posctl"
    if main == PX4_MAIN_MODE["auto"]:
        for name, value in PX4_AUTO_SUB_MODE.items():
            if value == sub and name in ("takeoff", "hold", "rtl", "land"):
                return name
    return None


def _param_name(raw: str | bytes) -> str:
    return (raw if isinstance(raw, str) else raw.decode(errors="replace")).rstrip("\x00")


def _limit(vector: np.ndarray, size: float) -> np.ndarray:
    """``vector`` scaled down to length ``size`` if it is longer."""
    norm = float(np.hypot(*vector))
    return vector if norm <= size else vector * (size / norm)


def _approach(error: np.ndarray, gain: float, acceleration: float) -> np.ndarray:
    """Velocity towards a position ``error`` (m) away: PX4's proportional approach
    (``gain`` 1/s), no faster than a stop at the setpoint allows with ``acceleration`` m/s^2
    (PX4 stops at a position setpoint without overshoot), m/s."""
    distance = float(np.hypot(*error))
    if distance <= 0.0:
        return np.zeros(2)
    speed = min(gain * distance, math.sqrt(2.0 * acceleration * distance))
    return error * (speed / distance)


@dataclass
class VehicleStats:
    """What the stub saw and did (JSON-ready through `as_json`)."""

    setpoint_times: list[float] = field(default_factory=list)
    modes: list[tuple[float, str]] = field(default_factory=list)
    commands: dict[str, int] = field(default_factory=dict)
    armed_at: float | None = None
    mission_started_at: float | None = None
    max_speed_m_s: float = 0.0
    track: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    """``(t s, north m, east m, v_north m/s, v_east m/s)`` at 10 Hz while in offboard."""
    setpoints: list[tuple[float, float, float]] = field(default_factory=list)
    """``(t s, north m, east m)`` of every position setpoint received."""
    fence_breaches: list[tuple[float, str, float, float]] = field(default_factory=list)
    """``(t s, action, east m, north m)`` of every fence breach (where the vehicle crossed)."""

    def as_json(
        self, final_mode: str, armed: bool, position_ned: np.ndarray, detections: dict
    ) -> dict:
        """Summary: setpoint count and rates while in offboard, modes, detections, track."""
        offboard = [
            t
            for t in self.setpoint_times
            if self.mission_started_at is not None and t >= self.mission_started_at
        ]
        end = next(
            (
                t
                for t, m in self.modes
                if m != "offboard"
                and self.mission_started_at is not None
                and t > self.mission_started_at
            ),
            None,
        )
        inside = [t for t in offboard if end is None or t <= end]
        gaps = np.diff(inside) if len(inside) > 1 else np.zeros(0)
        span = inside[-1] - inside[0] if len(inside) > 1 else 0.0
        return {
            "setpoints": len(self.setpoint_times),
            "offboard_setpoints": len(inside),
            "offboard_setpoint_rate_hz": (len(inside) - 1) / span if span > 0 else 0.0,
            "offboard_max_gap_s": float(gaps.max()) if gaps.size else None,
            "modes": [{"t": t, "mode": m} for t, m in self.modes],
            "final_mode": final_mode,
            "armed": armed,
            "armed_at": self.armed_at,
            "mission_started_at": self.mission_started_at,
            "commands": self.commands,
            "detections_sent": detections,
            "max_speed_m_s": self.max_speed_m_s,
            "position_ned": position_ned.tolist(),
            "track": [list(row) for row in self.track],
            "setpoint_positions": [list(row) for row in self.setpoints],
            "fence_breaches": [
                {"t": t, "action": a, "position": [e, n]} for t, a, e, n in self.fence_breaches
            ],
        }


MAX_PHYSICS_STEP_S = 0.01
"""Longest physics step, s: a loop that runs late (a loaded machine) flies its lost time in
steps of at most this, so that the vehicle moves, and its fence is checked, as at 100 Hz."""


class VehicleSim:
    """The stub vehicle (module docstring).

    Args:
        scenario: the mission (agent start, footprint, ``R``, targets).
        mavlink_url: where MAVSDK listens, ``udpout://127.0.0.1:PORT``.
        detections_url: where to send detections, ``udp://127.0.0.1:PORT``; ``None``: no
            targets (fly them with ``hptrack targets-sim`` on ``gcs_url``).
        seed: drives the true targets and the measurement noise (default the scenario's).
        detection_rate_hz: sensing per second (default one per ``tau``).
        gcs_url: a second telemetry link, ``udpout://127.0.0.1:PORT`` (PX4's ground-station
            port is 14550), or ``None``.
        airframe_speed_m_s: the airframe's top horizontal speed, m/s.
        velocity_tracking: the share of the commanded velocity the airframe flies (default
            PX4's `PX4_VELOCITY_TRACKING`; 1 for an ideal velocity loop).
        parameters: PX4 parameters that differ from `PX4_PARAMETERS`.
        on_event: called with one line at each mode change and failsafe.
        system_id: its MAVLink system id (PX4's ``MAV_SYS_ID``, 1 by default).
        component_id: its MAVLink component id (1, the autopilot's, by default).
        misbehaviour: how it misbehaves (`Misbehaviour`; default not at all).
        instance: which UAV of the scenario's team it is (it starts at that UAV's position
            and looks with its footprint); 0, the first, by default.
        detector: the targets and detector shared by a team's stubs (`TargetDetector`; its
            owner closes it), instead of one of its own at ``detections_url``.

    Raises:
        InputError: a malformed or non-loopback address.
    """

    def __init__(
        self,
        scenario: Scenario,
        mavlink_url: str = "udpout://127.0.0.1:14540",
        detections_url: str | None = "udp://127.0.0.1:5005",
        seed: int | None = None,
        detection_rate_hz: float | None = None,
        gcs_url: str | None = None,
        airframe_speed_m_s: float = AIRFRAME_SPEED_M_S,
        parameters: dict[str, float] | None = None,
        on_event: Callable[[str], None] | None = None,
        velocity_tracking: float = PX4_VELOCITY_TRACKING,
        system_id: int = 1,
        component_id: int = mavlink.MAV_COMP_ID_AUTOPILOT1,
        misbehaviour: Misbehaviour | None = None,
        instance: int = 0,
        detector: TargetDetector | None = None,
    ) -> None:
        if not 0.0 < velocity_tracking <= 1.0:
            raise InputError(
                f"--velocity-tracking {velocity_tracking!r}: must be in (0, 1] (the share of "
                "the commanded velocity the airframe flies)"
            )
        self.scenario = scenario
        self.mission = scenario.mission_spec()
        self._links = [udp_address(mavlink_url, "--mavlink", loopback_only=True)]
        if gcs_url is not None:
            self._links.append(udp_address(gcs_url, "--gcs", loopback_only=True))
        self._detector = detector
        self._own_detector = detector is None
        self.instance = instance
        if detector is None and detections_url is not None:
            udp_address(detections_url, "--detections", loopback_only=True)
            self._detector = TargetDetector(scenario, detections_url, seed)
        self._rate = detection_rate_hz or 1.0 / self.mission.time_step
        self._airframe_speed = float(airframe_speed_m_s)
        self._tracking = float(velocity_tracking)
        self._on_event = on_event or (lambda text: None)
        x, y = scenario.team[instance].position
        self.home = np.array(enu_to_ned(x, y, 0.0))
        self.position = self.home.copy()
        self.velocity = np.zeros(3)
        self.armed = False
        self.mode = "hold"
        self._mode_since = 0.0
        self._target: np.ndarray | None = None
        self._target_velocity = np.zeros(3)
        self._hold = self.position.copy()
        self._last_setpoint: float = -math.inf
        self._params = {**PX4_PARAMETERS, **(parameters or {})}
        self.system_id, self.component_id = system_id, component_id
        self.misbehaviour = misbehaviour or Misbehaviour()
        self._takeoff_since: float | None = None  # when the take-off in progress began, s
        self._offboard_since: float | None = None
        self._sensors_ok = True
        self._heartbeat_due = False
        self.fence: list[GeoZone] = []
        """The fence the vehicle holds (kept after a link loss)."""
        self._fence_local: list[tuple[bool, Polygon | None, tuple[float, float], float]] = []
        """Each zone as ``(inclusion, polygon or None, circle centre, radius)``, east-north m."""
        self._upload: list[tuple[int, float, int, int]] | None = None  # items so far
        self._upload_count = 0
        self._breached = False
        self.stats = VehicleStats()
        self._start = time.monotonic()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.setblocking(False)
        self._mav = mavlink.MAVLink(self, srcSystem=system_id, srcComponent=component_id)
        self._mav.robust_parsing = True

    # --- link -------------------------------------------------------------------------------
    def write(self, buffer: bytes) -> None:
        """MAVLink output (the pymavlink file interface): one datagram to each link."""
        for address in self._links:
            try:
                self._sock.sendto(buffer, address)
            except OSError as err:  # nobody listening yet: the next one may arrive
                logger.debug("send failed: %s", err)

    def _now(self) -> float:
        return time.monotonic() - self._start

    def _say(self, text: str) -> None:
        logger.info("%s", text)
        self._on_event(f"[{self._now():7.2f} s] {text}")

    def _set_mode(self, mode: str, why: str = "") -> None:
        if mode != self.mode or not self.stats.modes:
            self.stats.modes.append((self._now(), mode))
            self._say(f"mode {mode.upper()}{f' ({why})' if why else ''}")
            if self.stats.modes[1:]:
                self._heartbeat_due = True  # as PX4 does, the new mode shows at once
        if mode != self.mode:
            self._mode_since = self._now()
        self.mode = mode
        if mode == "takeoff":
            self._takeoff_since = self._now()
        elif mode != "offboard":  # offboard in mid-climb leaves the take-off pending
            self._takeoff_since = None
        if mode == "offboard" and self._offboard_since is None:
            self._offboard_since = self._now()
        if mode == "offboard" and self.stats.mission_started_at is None:
            self.stats.mission_started_at = self._now()
            if self._detector is not None:
                self._detector.start(time.time())
        if mode in ("hold", "takeoff", "posctl"):
            self._hold = self.position.copy()

    def _disarm(self, why: str) -> None:
        self.armed = False
        self._say(f"disarmed ({why})")
        self._heartbeat_due = True  # as PX4 does, the disarm shows at once

    def _misbehave(self) -> None:
        """Apply `Misbehaviour`'s switches whose time has come."""
        bad, now = self.misbehaviour, self._now()
        if (
            bad.takeoff_failure is not None
            and self.mode == "takeoff"
            and now - self._mode_since >= bad.takeoff_failure_after_s
        ):
            if bad.takeoff_failure == "disarm":
                self._disarm("in mid-climb: motors stopped")
            elif bad.takeoff_failure == "sensors":
                self._sensors_ok = False
                self._set_mode("land", "failsafe: sensors lost, no position estimate")
            else:
                self._set_mode("posctl", "a pilot switched to position mode")
        if (
            bad.leave_offboard_after_s is not None
            and self.mode == "offboard"
            and self._offboard_since is not None
            and now - self._offboard_since >= bad.leave_offboard_after_s
        ):
            self._set_mode(bad.leave_offboard_to, "a pilot switched modes")

    def _receive(self) -> None:
        for _ in range(1000):
            try:
                data, _addr = self._sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:  # ICMP port unreachable while MAVSDK starts
                return
            for msg in self._mav.parse_buffer(data) or []:
                self._handle(msg)

    def _ack(self, command: int, result: int) -> None:
        self._mav.command_ack_send(command, result)

    def _handle(self, msg: Any) -> None:
        kind = msg.get_type()
        if kind == "SET_POSITION_TARGET_LOCAL_NED":
            if msg.coordinate_frame == mavlink.MAV_FRAME_LOCAL_NED and not msg.type_mask & 0b111:
                values = np.array([msg.x, msg.y, msg.z], dtype=float)
                velocity = (
                    np.zeros(3)
                    if msg.type_mask & _VELOCITY_IGNORED
                    else np.array([msg.vx, msg.vy, msg.vz], dtype=float)
                )
                if (
                    np.all(np.isfinite(values))
                    and np.all(np.isfinite(velocity))
                    and msg.target_system in (0, self.system_id)
                ):
                    self._target, self._target_velocity = values, velocity
                    self._last_setpoint = self._now()
                    self.stats.setpoint_times.append(self._last_setpoint)
                    self.stats.setpoints.append((self._last_setpoint, *values[:2].tolist()))
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            if msg.target_system in (0, self.system_id) and msg.target_component in (
                0,
                self.component_id,
            ):
                self._command(msg)
        elif kind.startswith("MISSION_") and getattr(msg, "mission_type", None) == _FENCE:
            if msg.target_system in (0, self.system_id):
                self._fence_message(kind, msg)
        elif kind == "PARAM_SET":
            name = _param_name(msg.param_id)
            value = (
                struct.unpack("<i", struct.pack("<f", msg.param_value))[0]
                if name in INTEGER_PARAMETERS
                else msg.param_value
            )
            if name in self._params and math.isfinite(value):
                self._params[name] = float(value)
                self._say(f"parameter {name} = {value:g}")
                self._send_param(name)
        elif kind == "PARAM_REQUEST_READ":
            name = _param_name(msg.param_id)
            names = list(self._params)
            if name in self._params:
                self._send_param(name)
            elif 0 <= msg.param_index < len(names):
                self._send_param(names[msg.param_index])
        elif kind == "PARAM_REQUEST_LIST":
            for name in self._params:
                self._send_param(name)
        elif kind == "TIMESYNC" and msg.tc1 == 0:
            self._mav.timesync_send(time.monotonic_ns(), msg.ts1)

    def _send_param(self, name: str) -> None:
        names = list(self._params)
        integer = name in INTEGER_PARAMETERS
        value = (
            struct.unpack("<f", struct.pack("<i", round(self._params[name])))[0]
            if integer
            else self._params[name]
        )
        self._mav.param_value_send(
            name.encode(),
            value,
            mavlink.MAV_PARAM_TYPE_INT32 if integer else mavlink.MAV_PARAM_TYPE_REAL32,
            len(names),
            names.index(name),
        )

    # --- fence ------------------------------------------------------------------------------
    def _fence_message(self, kind: str, msg: Any) -> None:
        """The mission protocol for the fence (module docstring)."""
        to = (msg.get_srcSystem(), msg.get_srcComponent())
        if kind == "MISSION_COUNT":
            self._upload, self._upload_count = [], int(msg.count)
            if msg.count == 0:
                self._store_fence([])
                self._mav.mission_ack_send(*to, mavlink.MAV_MISSION_ACCEPTED, _FENCE)
            else:
                self._mav.mission_request_int_send(*to, 0, _FENCE)
        elif kind == "MISSION_ITEM_INT" and self._upload is not None:
            if msg.seq == len(self._upload):
                self._upload.append((msg.command, float(msg.param1), msg.x, msg.y))
            if len(self._upload) < self._upload_count:
                self._mav.mission_request_int_send(*to, len(self._upload), _FENCE)
                return
            result = self._store_fence(self._upload)
            self._upload = None
            self._mav.mission_ack_send(*to, result, _FENCE)
        elif kind == "MISSION_REQUEST_LIST":
            self._mav.mission_count_send(*to, len(self._fence_items()), _FENCE)
        elif kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST"):
            items = self._fence_items()
            if 0 <= msg.seq < len(items):
                command, param1, x, y = items[msg.seq]
                self._mav.mission_item_int_send(
                    *to, msg.seq, mavlink.MAV_FRAME_GLOBAL_INT, command, 0, 1,
                    param1, 0.0, 0.0, 0.0, x, y, 0.0, _FENCE,
                )  # fmt: skip
        elif kind == "MISSION_CLEAR_ALL":
            self._store_fence([])
            self._mav.mission_ack_send(*to, mavlink.MAV_MISSION_ACCEPTED, _FENCE)

    def _store_fence(self, items: list[tuple[int, float, int, int]]) -> int:
        """Keep the uploaded ``items`` (command, param1, lat 1e7, lon 1e7) as the fence;
        returns the ``MISSION_ACK`` result (a bad item or vertex count is refused)."""
        zones, i = [], 0
        shift = math.degrees(self.misbehaviour.fence_shift_m / EARTH_RADIUS_M)
        while i < len(items):
            command, param1, _, _ = items[i]
            if command not in _FENCE_COMMANDS:
                return mavlink.MAV_MISSION_UNSUPPORTED
            inclusion, circle = _FENCE_COMMANDS[command]
            size = 1 if circle else int(param1)
            group = items[i : i + size]
            if size < (1 if circle else 3) or len(group) < size:
                return mavlink.MAV_MISSION_INVALID_PARAM1
            if any(c != command or (not circle and int(p) != size) for c, p, _, _ in group):
                return mavlink.MAV_MISSION_INVALID_SEQUENCE
            points = tuple((x * 1e-7 + shift, y * 1e-7) for _, _, x, y in group)
            zones.append(GeoZone(inclusion, points, param1 if circle else None))
            i += size
        self.fence = zones
        self._fence_local = []
        for zone in zones:
            local = [geodetic_to_local(_HOME_LAT_DEG, _HOME_LON_DEG, *p)[::-1] for p in zone.points]
            shape = Polygon(local) if zone.radius_m is None else None
            self._fence_local.append((zone.inclusion, shape, local[0], zone.radius_m or 0.0))
        self._say(f"fence: {len(zones)} zones ({len(items)} items)" if zones else "fence cleared")
        return mavlink.MAV_MISSION_ACCEPTED

    def hold_fence(self, spec: FenceSpec) -> None:
        """Hold ``spec`` (a scenario's fence, local metres) as if it had been uploaded."""
        self._store_fence(_items(to_geodetic(spec, (_HOME_LAT_DEG, _HOME_LON_DEG))))

    def _fence_items(self) -> list[tuple[int, float, int, int]]:
        """The fence as mission items (command, param1, lat 1e7, lon 1e7)."""
        return _items(self.fence)

    def outside_fence(self) -> bool:
        """Whether the vehicle is inside an exclusion or outside every inclusion."""
        east, north = float(self.position[1]), float(self.position[0])
        inside_any, inclusions = False, False
        for inclusion, shape, centre, circle_m in self._fence_local:
            if shape is None:
                inside = math.dist((east, north), centre) < circle_m
            else:
                inside = shape.contains(Point(east, north))
            if inclusion:
                inclusions = True
                inside_any = inside_any or inside
            elif inside:
                return True
        return inclusions and not inside_any

    def _check_fence(self) -> None:
        """On a breach (armed, in the air), do ``GF_ACTION`` once until the vehicle is back
        inside."""
        if not self._fence_local or not self.armed or not self._airborne():
            return
        breached = self.outside_fence()
        if breached and not self._breached:
            action = int(self._params["GF_ACTION"])
            name = FENCE_ACTIONS.get(action, "none")
            east, north = float(self.position[1]), float(self.position[0])
            self.stats.fence_breaches.append((self._now(), name, east, north))
            self._say(f"geofence breached: GF_ACTION {action} ({name})")
            self._mav.statustext_send(
                mavlink.MAV_SEVERITY_CRITICAL, f"Geofence violation, action {name}".encode()
            )
            why = "geofence breached"
            if name == "hold":
                self._set_mode("hold", why)
            elif name == "return":
                self._set_mode("rtl", why)
            elif name == "land":
                self._set_mode("land", why)
            elif name == "terminate":
                self._disarm("geofence breached: flight termination")
        self._breached = breached

    def _streaming(self) -> bool:
        return self._now() - self._last_setpoint <= _STREAM_S

    def _command(self, msg: Any) -> None:
        cmd = msg.command
        name = mavlink.enums["MAV_CMD"][cmd].name if cmd in mavlink.enums["MAV_CMD"] else str(cmd)
        self.stats.commands[name] = self.stats.commands.get(name, 0) + 1
        accepted, denied = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            arm = msg.param1 > 0.5
            if arm and not self.armed:
                self.stats.armed_at = self._now()
                self._say("armed")
                self.armed = True
            elif not arm and self.armed:
                self._disarm("commanded")
            self._ack(cmd, accepted)
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            mode = _mode_of(int(msg.param2), int(msg.param3))
            if mode is None:
                self._ack(cmd, mavlink.MAV_RESULT_UNSUPPORTED)
            elif mode == "offboard" and not self._streaming():
                self._say("offboard refused: no setpoint stream")
                self._ack(cmd, denied)
            elif mode in ("takeoff", "offboard") and not self.armed:
                self._ack(cmd, denied)
            elif mode == "offboard" and self.misbehaviour.refuse_offboard == "deny":
                self._say("offboard refused (refuse_offboard deny)")
                self._ack(cmd, denied)
            elif mode == "offboard" and self.misbehaviour.refuse_offboard == "ignore":
                self._say(f"offboard accepted, but it stays in {self.mode.upper()}")
                self._ack(cmd, accepted)
            else:
                self._set_mode(mode, "commanded")
                self._ack(cmd, accepted)
        elif cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            if self.armed:
                self._set_mode("takeoff", f"to {self._params['MIS_TAKEOFF_ALT']:g} m")
                self._ack(cmd, accepted)
            else:
                self._ack(cmd, denied)
        elif cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._set_mode("rtl", "commanded")
            self._ack(cmd, accepted)
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            self._set_mode("land", "commanded")
            self._ack(cmd, accepted)
        elif cmd in (
            mavlink.MAV_CMD_REQUEST_MESSAGE,
            mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
        ):
            wanted = (
                int(msg.param1)
                if cmd == mavlink.MAV_CMD_REQUEST_MESSAGE
                else mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            )
            if wanted == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
                self._ack(cmd, accepted)
                self._send_version()
            elif wanted == mavlink.MAVLINK_MSG_ID_HOME_POSITION:
                self._ack(cmd, accepted)
                self._send_home()
            elif wanted == mavlink.MAVLINK_MSG_ID_GPS_GLOBAL_ORIGIN:
                self._ack(cmd, accepted)
                self._mav.gps_global_origin_send(
                    round(_HOME_LAT_DEG * 1e7), round(_HOME_LON_DEG * 1e7), round(_HOME_ALT_M * 1e3)
                )
            else:
                self._ack(cmd, mavlink.MAV_RESULT_UNSUPPORTED)
        elif cmd == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            self._ack(cmd, accepted)
        else:
            self._ack(cmd, mavlink.MAV_RESULT_UNSUPPORTED)

    # --- telemetry --------------------------------------------------------------------------
    def _send_version(self) -> None:
        capabilities = (
            mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
            | mavlink.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
        )
        self._mav.autopilot_version_send(
            capabilities, (1 << 24) | (15 << 16), 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1
        )

    def _geodetic(self, ned: np.ndarray) -> tuple[int, int, int]:
        lat, lon = local_to_geodetic(_HOME_LAT_DEG, _HOME_LON_DEG, ned[0], ned[1])
        return int(lat * 1e7), int(lon * 1e7), int((_HOME_ALT_M - ned[2]) * 1000)

    def _send_home(self) -> None:
        lat, lon, alt = self._geodetic(self.home)
        self._mav.home_position_send(
            lat, lon, alt, *self.home.tolist(), [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0
        )

    def _send_heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        state = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self._mav.heartbeat_send(
            mavlink.MAV_TYPE_QUADROTOR,
            mavlink.MAV_AUTOPILOT_PX4,
            base,
            _custom_mode(self.mode),
            state,
        )

    def _send_status(self) -> None:
        self._send_heartbeat()
        healthy = _SENSORS if self._sensors_ok else 0
        self._mav.sys_status_send(
            _SENSORS, _SENSORS, healthy, 100, 16000, 500, 90, 0, 0, 0, 0, 0, 0
        )
        landed = (
            mavlink.MAV_LANDED_STATE_IN_AIR
            if self._airborne()
            else mavlink.MAV_LANDED_STATE_ON_GROUND
        )
        self._mav.extended_sys_state_send(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)
        self._send_home()

    def _send_position(self, boot_ms: int) -> None:
        if not self._sensors_ok:  # no estimate, no position (as PX4)
            return
        n, e, d = self.position.tolist()
        vn, ve, vd = self.velocity.tolist()
        self._mav.local_position_ned_send(boot_ms, n, e, d, vn, ve, vd)
        lat, lon, alt = self._geodetic(self.position)
        self._mav.global_position_int_send(
            boot_ms, lat, lon, alt, int(-d * 1000), int(vn * 100), int(ve * 100), int(vd * 100), 0
        )

    # --- physics ----------------------------------------------------------------------------
    def _airborne(self) -> bool:
        return self.home[2] - self.position[2] > 0.5

    def _takeoff_climb_rate(self) -> float:
        """PX4's take-off: spool-up, then a climb rate ramped up to ``MPC_TKO_SPEED`` that
        slows near the take-off altitude, m/s (up)."""
        p = self._params
        since = self._now() - self._mode_since - p["COM_SPOOLUP_TIME"]
        if since <= 0.0:
            return 0.0
        ramp = min(1.0, since / p["MPC_TKO_RAMP_T"]) if p["MPC_TKO_RAMP_T"] > 0 else 1.0
        to_go = self.position[2] - (self.home[2] - p["MIS_TAKEOFF_ALT"])
        return min(ramp * p["MPC_TKO_SPEED"], max(to_go, 0.0))

    def _goal(self) -> tuple[np.ndarray, np.ndarray]:
        """The position setpoint and feed-forward velocity of the current mode (NED)."""
        if self.mode == "offboard" and self._target is not None:
            return self._target, self._target_velocity
        goal = self._hold.copy()
        if self.mode == "rtl":
            goal = self.home.copy()
            if np.hypot(*(self.position[:2] - self.home[:2])) > 0.5:
                goal[2] = min(self.position[2], self.home[2] - self._params["RTL_RETURN_ALT"])
        elif self.mode == "land":
            goal = self.position.copy()
            goal[2] = self.home[2]
        return goal, np.zeros(3)

    def _fly(self, dt: float) -> None:
        if dt <= 0.0:
            return
        p = self._params
        if not self.armed:  # on the ground it stays; in the air it falls
            self.velocity[:2] = 0.0
            falling = self.position[2] < self.home[2]
            self.velocity[2] = self.velocity[2] + 9.81 * dt if falling else 0.0
            self.position[2] = min(self.home[2], self.position[2] + self.velocity[2] * dt)
            return
        self._misbehave()
        if self.mode == "offboard" and self._now() - self._last_setpoint > p["COM_OF_LOSS_T"]:
            self._set_mode(
                "hold", f"offboard lost: no setpoint for {p['COM_OF_LOSS_T']:g} s, failsafe"
            )
        goal, feed_forward = self._goal()
        command = feed_forward[:2] + _approach(
            goal[:2] - self.position[:2], p["MPC_XY_P"], p["MPC_ACC_HOR"]
        )
        flown = _limit(self._tracking * _limit(command, p["MPC_XY_VEL_MAX"]), self._airframe_speed)
        if self.mode == "takeoff":
            flown = np.zeros(2)
        change = _limit(flown - self.velocity[:2], p["MPC_ACC_HOR"] * dt)
        self.velocity[:2] += change
        # vertical: the take-off profile, else a proportional climb or descent within limits
        takeoff_left = self.position[2] - (self.home[2] - p["MIS_TAKEOFF_ALT"])
        if self.mode == "takeoff":
            climb = self._takeoff_climb_rate()
            if takeoff_left < 0.05:
                self._set_mode("hold", "take-off altitude reached")
                climb = 0.0
            self.velocity[2] = -self._tracking * climb
        else:
            if self._takeoff_since is not None and takeoff_left < 0.05:
                # the take-off's end switches to LOITER even out of offboard
                self._set_mode("hold", "take-off altitude reached: LOITER overrides offboard")
                goal, feed_forward = self._goal()
            self.velocity[2] = self._tracking * float(
                np.clip(goal[2] - self.position[2], -p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"])
            )
        self.position += self.velocity * dt
        self._check_fence()
        if self.position[2] >= self.home[2]:
            self.position[2] = self.home[2]
            self.velocity[2] = 0.0
            if self.mode in ("land", "rtl") and np.hypot(*self.velocity[:2]) < 0.1:
                self.armed = False
                self._say("landed and disarmed")
        self.stats.max_speed_m_s = max(
            self.stats.max_speed_m_s, float(np.hypot(*self.velocity[:2]))
        )

    def close(self) -> None:
        """Close the stub's sockets."""
        self._sock.close()
        if self._detector is not None and self._own_detector:
            self._detector.close()

    # --- main loop --------------------------------------------------------------------------
    def run(
        self, duration_s: float, stop: threading.Event | None = None, loop_hz: float = 100.0
    ) -> dict:
        """Fly for at most ``duration_s`` wall seconds or until ``stop`` is set; returns the
        stats (`VehicleStats.as_json`)."""
        period = 1.0 / loop_hz
        self._set_mode(self.mode)
        last = self._now()
        next_status = next_position = next_sense = next_track = last
        end = last + float(duration_s)
        try:
            while self._now() < end and not (stop is not None and stop.is_set()):
                now = self._now()
                self._receive()
                elapsed = now - last
                while elapsed > 0.0:  # a late loop still flies (and checks its fence) finely
                    self._fly(min(elapsed, MAX_PHYSICS_STEP_S))
                    elapsed -= MAX_PHYSICS_STEP_S
                last = now
                if now >= next_status:
                    self._send_status()
                    next_status = now + 1.0
                elif self._heartbeat_due:  # after the command's ACK, in the same loop
                    self._send_heartbeat()
                self._heartbeat_due = False
                if now >= next_position:
                    self._send_position(int(now * 1000))
                    next_position = now + 1.0 / 30.0
                if now >= next_sense:
                    if self._detector is not None and self._airborne():
                        east, north, _ = ned_to_enu(*self.position)
                        self._detector.sense(time.time(), np.array([east, north]), self.instance)
                    next_sense = now + 1.0 / self._rate
                if now >= next_track and self.mode == "offboard":
                    self.stats.track.append((now, *self.position[:2], *self.velocity[:2]))
                    next_track = now + 0.1
                time.sleep(max(0.0, min(period, end - self._now())))
        finally:
            self.close()
        detector = self._detector
        detections = {} if detector is None else detector.stats.detections
        summary = self.stats.as_json(self.mode, self.armed, self.position, detections)
        summary["false_alarms_sent"] = 0 if detector is None else detector.stats.false_alarms
        return summary
