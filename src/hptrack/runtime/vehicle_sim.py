"""A small MAVLink vehicle for dry runs without a drone or a PX4 simulator (pymavlink).

It speaks enough of PX4's protocol for MAVSDK: a PX4 quadrotor heartbeat whose custom mode
shows the flight mode (offboard, hold, takeoff, return, land), ``COMMAND_ACK`` for arming, mode
changes, takeoff, return and land (offboard is refused, as PX4 does, unless setpoints are
streaming), ``PARAM_VALUE`` for parameter reads and writes, ``AUTOPILOT_VERSION`` on request,
``TIMESYNC`` replies, and ``SYS_STATUS``, ``EXTENDED_SYS_STATE``, ``LOCAL_POSITION_NED``,
``GLOBAL_POSITION_INT`` and ``HOME_POSITION`` telemetry. In offboard mode it flies straight
towards the last ``SET_POSITION_TARGET_LOCAL_NED`` at the scenario's speed (climbing at
``climb_rate_m_s``).

It also simulates the scenario's true targets (from the first switch to offboard, the mission's
start) and, while airborne, sends every target within the sensor footprint as a JSON line to the
detection port: ``{"t": unix_s, "id": ..., "x": east_m, "y": north_m}`` (the scenario's ``R``
as noise). The vehicle starts on the ground at the scenario's agent position.

Loopback addresses only; every loop is bounded by the run's duration.
"""

from __future__ import annotations

import json
import logging
import math
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from hptrack.runtime.frames import enu_to_ned, ned_to_enu
from hptrack.runtime.network import udp_address
from hptrack.runtime.world import TrueTargets
from hptrack.scenario.model import Scenario

logger = logging.getLogger(__name__)

PX4_MAIN_MODE = {"manual": 1, "posctl": 3, "auto": 4, "offboard": 6}
"""PX4 main modes (``custom_mode`` bits 16-23)."""
PX4_AUTO_SUB_MODE = {"ready": 1, "takeoff": 2, "hold": 3, "mission": 4, "rtl": 5, "land": 6}
"""PX4 auto sub-modes (``custom_mode`` bits 24-31)."""

_SYSTEM_ID = 1
_COMPONENT_ID = mavlink.MAV_COMP_ID_AUTOPILOT1
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
_EARTH_RADIUS_M = 6_378_137.0


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


@dataclass
class VehicleStats:
    """What the stub saw and did (JSON-ready through :meth:`as_json`)."""

    setpoint_times: list[float] = field(default_factory=list)
    modes: list[tuple[float, str]] = field(default_factory=list)
    commands: dict[str, int] = field(default_factory=dict)
    detections_sent: dict[str, int] = field(default_factory=dict)
    armed_at: float | None = None
    mission_started_at: float | None = None
    max_speed_m_s: float = 0.0

    def as_json(self, final_mode: str, armed: bool, position_ned: np.ndarray) -> dict:
        """Summary: setpoint count and rates while in offboard, modes, detections."""
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
            "detections_sent": self.detections_sent,
            "max_speed_m_s": self.max_speed_m_s,
            "position_ned": position_ned.tolist(),
        }


class VehicleSim:
    """The stub vehicle (module docstring).

    Args:
        scenario: the mission (agent start, speed, footprint, ``R``, targets).
        mavlink_url: where MAVSDK listens, ``udpout://127.0.0.1:PORT``.
        detections_url: where to send detections, ``udp://127.0.0.1:PORT``.
        seed: drives the true targets and the measurement noise (default the scenario's).
        detection_rate_hz: sensing per second (default one per ``tau``).
        climb_rate_m_s: vertical speed, m/s.

    Raises:
        InputError: a malformed or non-loopback address.
    """

    def __init__(
        self,
        scenario: Scenario,
        mavlink_url: str = "udpout://127.0.0.1:14540",
        detections_url: str = "udp://127.0.0.1:5005",
        seed: int | None = None,
        detection_rate_hz: float | None = None,
        climb_rate_m_s: float = 5.0,
    ) -> None:
        self.scenario = scenario
        self.mission = scenario.mission_spec()
        self._gcs = udp_address(mavlink_url, "--mavlink", loopback_only=True)
        self._detections = udp_address(detections_url, "--detections", loopback_only=True)
        self._rate = detection_rate_hz or 1.0 / self.mission.time_step
        self._climb = float(climb_rate_m_s)
        seed = scenario.seed if seed is None else int(seed)
        truth_seq, motion_seq, sensor_seq, _ = np.random.SeedSequence(seed).spawn(4)
        self._targets = TrueTargets(
            scenario, np.random.default_rng(truth_seq), np.random.default_rng(motion_seq)
        )
        self._sensor_rng = np.random.default_rng(sensor_seq)
        x, y = scenario.agent.position
        self.home = np.array(enu_to_ned(x, y, 0.0))
        self.position = self.home.copy()
        self.velocity = np.zeros(3)
        self.armed = False
        self.mode = "hold"
        self._target: np.ndarray | None = None
        self._hold = self.position.copy()
        self._last_setpoint: float = -math.inf
        self._params: dict[str, float] = {
            "MIS_TAKEOFF_ALT": 2.5,
            "MPC_XY_CRUISE": 10.0,
            "RTL_RETURN_ALT": 30.0,
            "NAV_RCL_ACT": 0.0,
            "COM_RCL_EXCEPT": 4.0,
        }
        self.stats = VehicleStats()
        self._start = time.monotonic()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", 0))
        self._sock.setblocking(False)
        self._out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._mav = mavlink.MAVLink(self, srcSystem=_SYSTEM_ID, srcComponent=_COMPONENT_ID)
        self._mav.robust_parsing = True

    # --- link -------------------------------------------------------------------------------
    def write(self, buffer: bytes) -> None:
        """MAVLink output (the pymavlink file interface): one datagram to MAVSDK."""
        try:
            self._sock.sendto(buffer, self._gcs)
        except OSError as err:  # nobody listening yet: MAVSDK will hear the next one
            logger.debug("send failed: %s", err)

    def _now(self) -> float:
        return time.monotonic() - self._start

    def _set_mode(self, mode: str) -> None:
        if mode != self.mode or not self.stats.modes:
            self.stats.modes.append((self._now(), mode))
            logger.info("mode %s", mode)
        self.mode = mode
        if mode == "offboard" and self.stats.mission_started_at is None:
            self.stats.mission_started_at = self._now()
        if mode in ("hold", "takeoff"):
            self._hold = self.position.copy()

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
                if np.all(np.isfinite(values)):
                    self._target = values
                    self._last_setpoint = self._now()
                    self.stats.setpoint_times.append(self._last_setpoint)
        elif kind in ("COMMAND_LONG", "COMMAND_INT"):
            if msg.target_system in (0, _SYSTEM_ID) and msg.target_component in (0, _COMPONENT_ID):
                self._command(msg)
        elif kind == "PARAM_SET":
            name = (
                msg.param_id.rstrip("\x00")
                if isinstance(msg.param_id, str)
                else msg.param_id.decode().rstrip("\x00")
            )
            self._params[name] = float(msg.param_value)
            self._send_param(name)
        elif kind == "PARAM_REQUEST_READ":
            name = (
                msg.param_id.rstrip("\x00")
                if isinstance(msg.param_id, str)
                else msg.param_id.decode().rstrip("\x00")
            )
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
        self._mav.param_value_send(
            name.encode(),
            self._params[name],
            mavlink.MAV_PARAM_TYPE_REAL32,
            len(names),
            names.index(name),
        )

    def _command(self, msg: Any) -> None:
        cmd = msg.command
        name = mavlink.enums["MAV_CMD"][cmd].name if cmd in mavlink.enums["MAV_CMD"] else str(cmd)
        self.stats.commands[name] = self.stats.commands.get(name, 0) + 1
        accepted, denied = mavlink.MAV_RESULT_ACCEPTED, mavlink.MAV_RESULT_DENIED
        if cmd == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            arm = msg.param1 > 0.5
            if arm and not self.armed:
                self.stats.armed_at = self._now()
            self.armed = arm
            self._ack(cmd, accepted)
        elif cmd == mavlink.MAV_CMD_DO_SET_MODE:
            mode = _mode_of(int(msg.param2), int(msg.param3))
            if mode is None:
                self._ack(cmd, mavlink.MAV_RESULT_UNSUPPORTED)
            elif mode == "offboard" and self._now() - self._last_setpoint > 0.5:
                self._ack(cmd, denied)  # PX4: no offboard without a setpoint stream
            elif mode in ("takeoff", "offboard") and not self.armed:
                self._ack(cmd, denied)
            else:
                self._set_mode(mode)
                self._ack(cmd, accepted)
        elif cmd == mavlink.MAV_CMD_NAV_TAKEOFF:
            if self.armed:
                self._set_mode("takeoff")
                self._ack(cmd, accepted)
            else:
                self._ack(cmd, denied)
        elif cmd == mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            self._set_mode("rtl")
            self._ack(cmd, accepted)
        elif cmd == mavlink.MAV_CMD_NAV_LAND:
            self._set_mode("land")
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
        )
        self._mav.autopilot_version_send(
            capabilities, (1 << 24) | (15 << 16), 0, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, 1
        )

    def _geodetic(self, ned: np.ndarray) -> tuple[int, int, int]:
        lat = _HOME_LAT_DEG + math.degrees(ned[0] / _EARTH_RADIUS_M)
        lon = _HOME_LON_DEG + math.degrees(
            ned[1] / (_EARTH_RADIUS_M * math.cos(math.radians(_HOME_LAT_DEG)))
        )
        return int(lat * 1e7), int(lon * 1e7), int((_HOME_ALT_M - ned[2]) * 1000)

    def _send_home(self) -> None:
        lat, lon, alt = self._geodetic(self.home)
        self._mav.home_position_send(
            lat, lon, alt, *self.home.tolist(), [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0
        )

    def _send_status(self) -> None:
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
        self._mav.sys_status_send(
            _SENSORS, _SENSORS, _SENSORS, 100, 16000, 500, 90, 0, 0, 0, 0, 0, 0
        )
        landed = (
            mavlink.MAV_LANDED_STATE_IN_AIR
            if self._airborne()
            else mavlink.MAV_LANDED_STATE_ON_GROUND
        )
        self._mav.extended_sys_state_send(mavlink.MAV_VTOL_STATE_UNDEFINED, landed)
        self._send_home()

    def _send_position(self, boot_ms: int) -> None:
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

    def _fly(self, dt: float) -> None:
        before = self.position.copy()
        if not self.armed:
            goal = self.position.copy()
        elif self.mode == "offboard" and self._target is not None:
            goal = self._target
        elif self.mode == "takeoff":
            goal = self._hold.copy()
            goal[2] = self.home[2] - self._params["MIS_TAKEOFF_ALT"]
            if abs(self.position[2] - goal[2]) < 0.05:
                self._set_mode("hold")
        elif self.mode == "rtl":
            goal = self.home.copy()
            if np.hypot(*(self.position[:2] - self.home[:2])) > 0.5:
                goal[2] = self.position[2]
            elif not self._airborne():
                self.armed = False
        elif self.mode == "land":
            goal = self.position.copy()
            goal[2] = self.home[2]
            if not self._airborne():
                self.armed = False
        else:
            goal = self._hold.copy()
        step = goal[:2] - self.position[:2]
        dist = float(np.hypot(*step))
        reach = self.mission.agent_speed * dt
        self.position[:2] += step if dist <= reach else step * (reach / dist)
        rise = float(np.clip(goal[2] - self.position[2], -self._climb * dt, self._climb * dt))
        self.position[2] = min(self.position[2] + rise, self.home[2])
        self.velocity = (self.position - before) / dt if dt > 0 else np.zeros(3)
        self.stats.max_speed_m_s = max(
            self.stats.max_speed_m_s, float(np.hypot(*self.velocity[:2]))
        )

    def _sense(self) -> None:
        start = self.stats.mission_started_at
        if start is None or not self._airborne():
            return
        truth = self._targets.positions_at(self._now() - start)
        east, north, _ = ned_to_enu(*self.position)
        sensor = self.mission.sensor
        seen = np.flatnonzero(sensor.in_footprint(np.array([east, north]), truth))
        if not len(seen):
            return
        stamp = time.time()
        lines = []
        for i, z in zip(seen, sensor.sample(truth[seen], self._sensor_rng), strict=True):
            tid = self.mission.target_ids[i]
            lines.append(json.dumps({"t": stamp, "id": tid, "x": float(z[0]), "y": float(z[1])}))
            self.stats.detections_sent[tid] = self.stats.detections_sent.get(tid, 0) + 1
        try:
            self._out.sendto("\n".join(lines).encode(), self._detections)
        except OSError as err:
            logger.debug("detection send failed: %s", err)

    # --- main loop --------------------------------------------------------------------------
    def run(
        self, duration_s: float, stop: threading.Event | None = None, loop_hz: float = 50.0
    ) -> dict:
        """Fly for at most ``duration_s`` wall seconds or until ``stop`` is set; returns the
        stats (:meth:`VehicleStats.as_json`)."""
        period = 1.0 / loop_hz
        self._set_mode(self.mode)
        last = self._now()
        next_status = next_position = next_sense = last
        end = last + float(duration_s)
        try:
            while self._now() < end and not (stop is not None and stop.is_set()):
                now = self._now()
                self._receive()
                self._fly(now - last)
                last = now
                if now >= next_status:
                    self._send_status()
                    next_status = now + 1.0
                if now >= next_position:
                    self._send_position(int(now * 1000))
                    next_position = now + 1.0 / 30.0
                if now >= next_sense:
                    self._sense()
                    next_sense = now + 1.0 / self._rate
                time.sleep(max(0.0, min(period, end - self._now())))
        finally:
            self._sock.close()
            self._out.close()
        return self.stats.as_json(self.mode, self.armed, self.position)
