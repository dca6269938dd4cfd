"""Synthetic targets and a footprint detector for flights without real targets: the scenario's
true targets move from the mission's start (the vehicle's first switch to offboard), and every
target within the sensor footprint of the vehicle is measured with the scenario's ``R`` and sent
as a detection datagram to ``hptrack fly``. A sensor other than the paper's looks with the
simulator's detector (`hptrack.runtime.world.synthetic_detector`): a target inside is detected
with ``detection_probability``, false alarms come by ``false_alarm_density``, and with
``labelled: false`` the detections carry no id.

One component, two uses: the vehicle stub (`hptrack.runtime.vehicle_sim`) feeds it its own
position, and ``hptrack targets-sim`` (`run_targets_sim`) feeds it the position an
autopilot reports on its MAVLink telemetry (a second link, such as PX4's ground-station port
14550), so that any SITL flies with synthetic targets.

Detection datagram: JSON lines ``{"t": unix_s, "id": ..., "x": east_m, "y": north_m}`` (no
``"id"`` without identity; a team's with the ``"vehicle"`` whose camera looked), one datagram
per look.
"""

from __future__ import annotations

import json
import logging
import math
import socket
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from hptrack.interface import InputError
from hptrack.runtime.frames import geodetic_to_local, ned_to_enu
from hptrack.runtime.network import udp_address
from hptrack.runtime.world import TrueTargets, synthetic_detector
from hptrack.scenario.model import Scenario

logger = logging.getLogger(__name__)

PX4_OFFBOARD_MAIN_MODE = 6
"""PX4's main mode number of offboard (``custom_mode`` bits 16-23)."""


def detection_datagram(
    stamp_unix_s: float,
    detections: list[tuple[str | None, np.ndarray]],
    vehicle: int | None = None,
) -> bytes:
    """The detection datagram of measurements ``(id, (x east, y north) m)`` taken at
    ``stamp_unix_s`` by the camera of the team's UAV ``vehicle`` (module docstring; an id
    ``None``: a line without ``"id"``; a ``vehicle`` ``None``: a line without ``"vehicle"``)."""
    extra = {} if vehicle is None else {"vehicle": vehicle}
    lines = [
        json.dumps(
            {"t": stamp_unix_s, **({} if tid is None else {"id": tid})}
            | {"x": float(z[0]), "y": float(z[1])}
            | extra
        )
        for tid, z in detections
    ]
    return "\n".join(lines).encode()


@dataclass
class DetectorStats:
    """What the detector sent: datagrams, detections per target (by their true source, also
    without identity) and false alarms."""

    datagrams: int = 0
    detections: dict[str, int] = field(default_factory=dict)
    false_alarms: int = 0
    started_at_unix_s: float | None = None


class TargetDetector:
    """The scenario's true targets and the footprint sensor (module docstring).

    Args:
        scenario: the mission (targets, motion, footprint, ``R``).
        detections_url: where detections go, ``udp://HOST:PORT``.
        seed: drives the true targets and the noise (default the scenario's); the streams are
            the simulator's (truth, motion, sensor).
        option: the option that gave ``detections_url``, for error messages.

    Raises:
        InputError: a malformed address.
    """

    def __init__(
        self,
        scenario: Scenario,
        detections_url: str,
        seed: int | None = None,
        option: str = "--detections",
    ) -> None:
        self.mission = scenario.mission_spec()
        self._address = udp_address(detections_url, option)
        seed = scenario.seed if seed is None else int(seed)
        truth_seq, motion_seq, sensor_seq, _ = np.random.SeedSequence(seed).spawn(4)
        self._targets = TrueTargets(
            scenario, np.random.default_rng(truth_seq), np.random.default_rng(motion_seq)
        )
        self._sensor_rng = np.random.default_rng(sensor_seq)
        self._detector = synthetic_detector(scenario, seed)
        self._labelled = scenario.sensor_spec().labelled
        self._team = scenario.n_vehicles > 1
        """Whether each line names the UAV whose camera looked (``"vehicle"``)."""
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._lock = threading.Lock()  # a team's stubs sense from their own threads
        self.stats = DetectorStats()

    @property
    def started(self) -> bool:
        return self.stats.started_at_unix_s is not None

    def start(self, unix_s: float) -> None:
        """The mission starts (targets at their initial states) at ``unix_s``; later calls do
        nothing."""
        if self.stats.started_at_unix_s is None:
            self.stats.started_at_unix_s = float(unix_s)

    def sense(self, unix_s: float, position_enu: np.ndarray, vehicle: int = 0) -> int:
        """Measure the targets in the footprint of UAV ``vehicle`` of the team (the first by
        default) at ``position_enu`` (2,) m at ``unix_s`` and send them; returns how many
        were sent (0 before the start)."""
        with self._lock:
            return self._sense(unix_s, position_enu, vehicle)

    def _sense(self, unix_s: float, position_enu: np.ndarray, vehicle: int) -> int:
        start = self.stats.started_at_unix_s
        if start is None:
            return 0
        truth = self._targets.positions_at(unix_s - start)
        agent = np.asarray(position_enu, float)
        if self._detector is None:
            sensor = self.mission.vehicle_mission(vehicle).sensor
            seen = np.flatnonzero(sensor.in_footprint(agent, truth))
            measured = sensor.sample(truth[seen], self._sensor_rng) if len(seen) else truth[:0]
        else:
            measured, seen = self._detector.look(agent, truth)
        if not len(seen):
            return 0
        target_ids = self.mission.target_ids
        for i in seen[seen >= 0]:
            tid = target_ids[i]
            self.stats.detections[tid] = self.stats.detections.get(tid, 0) + 1
        self.stats.false_alarms += int(np.sum(seen < 0))
        ids = [target_ids[i] if self._labelled else None for i in seen]
        try:
            datagram = detection_datagram(
                unix_s, list(zip(ids, measured, strict=True)), vehicle if self._team else None
            )
            self._sock.sendto(datagram, self._address)
            self.stats.datagrams += 1
        except OSError as err:  # nobody listening (yet): the next one may arrive
            logger.debug("detection send failed: %s", err)
        return len(ids)

    def close(self) -> None:
        self._sock.close()


@dataclass
class _Telemetry:
    position_ned: np.ndarray | None = None
    offboard: bool = False
    armed: bool = False
    geodetic: tuple[float, float] | None = None
    """The last ``GLOBAL_POSITION_INT`` (latitude, longitude), degrees."""


def team_position(first: _Telemetry, other: _Telemetry) -> np.ndarray | None:
    """Where ``other`` is in the first UAV's local frame, east-north m: the first's local
    position plus the tangent-plane offset of ``other``'s geodetic position from the first's
    (`geodetic_to_local`); ``None`` until both have sent both."""
    if first.position_ned is None or first.geodetic is None or other.geodetic is None:
        return None
    north, east = geodetic_to_local(*first.geodetic, *other.geodetic)
    east0, north0, _ = ned_to_enu(*first.position_ned)
    return np.array([east0 + east, north0 + north])


def run_targets_sim(
    detector: TargetDetector,
    mavlink_url: str,
    duration_s: float,
    rate_hz: float,
    stop: threading.Event | None = None,
    min_altitude_m: float = 0.5,
    on_event=None,
    team_system_ids: tuple[int, ...] | None = None,
) -> dict:
    """Listen to an autopilot's MAVLink telemetry at ``mavlink_url`` (``udpin://HOST:PORT``,
    pymavlink) and sense at ``rate_hz`` for at most ``duration_s`` s: the mission starts at the
    first heartbeat in offboard mode; the vehicle's position is its ``LOCAL_POSITION_NED`` (the
    local frame of the mission); it senses while higher than ``min_altitude_m`` above the
    local origin. Returns a summary (heartbeats seen, positions, detections sent).

    A team (``team_system_ids``: the MAVLink system id of each UAV, in the order of
    ``agents:``; PX4's multi-vehicle SITL numbers instance ``i`` ``MAV_SYS_ID = i + 1`` and
    sends every instance's telemetry to the one ground-station port) is sensed from every
    UAV's position with its own footprint (``positions_by_vehicle`` counts them); the
    positions of other systems are ignored (counted in ``other_positions``), and the first UAV
    in offboard starts the targets. The team's frame is the first UAV's local frame (each
    autopilot's local origin is its own): another UAV is where its ``GLOBAL_POSITION_INT``
    lies from the first's, east-north m (`team_position`), added to the first's local
    position.

    Raises:
        InputError: an address that cannot be opened (malformed, in use, not on this machine).
    """
    from pymavlink import mavutil

    host, port = udp_address(mavlink_url, "--mavlink")
    try:
        link = mavutil.mavlink_connection(f"udpin:{host}:{port}", source_system=255)
    except OSError as err:
        raise InputError(
            f"--mavlink {mavlink_url!r}: cannot listen there ({err.strerror})"
        ) from None
    say = on_event or (lambda text: None)
    ids = (0,) if team_system_ids is None else team_system_ids
    seen = {system: _Telemetry() for system in ids}
    counts = {"heartbeats": 0, "positions": 0}
    by_vehicle = [0] * len(ids)
    if team_system_ids is not None:
        counts["other_positions"] = 0

    def vehicle_of(msg) -> int | None:
        """The UAV a message is from (any system for one UAV)."""
        if team_system_ids is None:
            return 0
        system = msg.get_srcSystem()
        return team_system_ids.index(system) if system in team_system_ids else None

    end = time.monotonic() + duration_s
    next_sense = time.monotonic()
    try:
        while time.monotonic() < end and not (stop is not None and stop.is_set()):
            msg = link.recv_match(blocking=True, timeout=min(0.02, 1.0 / rate_hz))
            while msg is not None:
                kind = msg.get_type()
                j = vehicle_of(msg)
                name = "vehicle" if team_system_ids is None else f"vehicle {j}"
                if j is None:
                    counts["other_positions"] += kind == "LOCAL_POSITION_NED"
                elif kind == "HEARTBEAT" and msg.get_srcComponent() == 1:
                    counts["heartbeats"] += 1
                    offboard = (msg.custom_mode >> 16) & 0xFF == PX4_OFFBOARD_MAIN_MODE
                    telemetry = seen[ids[j]]
                    if offboard and not telemetry.offboard:
                        say(f"{name} in OFFBOARD")
                        if not detector.started:
                            detector.start(time.time())
                            say("mission started: targets moving")
                    elif telemetry.offboard and not offboard:
                        say(f"{name} left OFFBOARD")
                    telemetry.offboard = offboard
                elif kind == "GLOBAL_POSITION_INT":
                    seen[ids[j]].geodetic = (msg.lat * 1e-7, msg.lon * 1e-7)
                elif kind == "LOCAL_POSITION_NED":
                    counts["positions"] += 1
                    by_vehicle[j] += 1
                    seen[ids[j]].position_ned = np.array([msg.x, msg.y, msg.z], dtype=float)
                msg = link.recv_match(blocking=False)
            now = time.monotonic()
            if now >= next_sense:
                next_sense = now + 1.0 / rate_hz
                for j, system in enumerate(ids):
                    ned = seen[system].position_ned
                    if ned is not None and math.isfinite(ned.sum()) and -ned[2] > min_altitude_m:
                        if j == 0:
                            east, north, _ = ned_to_enu(*ned)
                            here: np.ndarray | None = np.array([east, north])
                        else:
                            here = team_position(seen[ids[0]], seen[system])
                        if here is not None:
                            detector.sense(time.time(), here, j)
    finally:
        link.close()
        detector.close()
    return {
        **counts,
        **({} if team_system_ids is None else {"positions_by_vehicle": by_vehicle}),
        "mission_started": detector.started,
        "datagrams": detector.stats.datagrams,
        "detections_sent": detector.stats.detections,
        "false_alarms_sent": detector.stats.false_alarms,
    }
