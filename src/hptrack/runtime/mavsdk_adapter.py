"""``hptrack fly``: the mission controller on a PX4 vehicle through MAVSDK (the ``mavsdk``
package, 4.x, a binding of the MAVSDK C library), as offboard position setpoints.

Sequence: connect and wait for an autopilot; wait for a local position; arm and take off to
the mission altitude if asked (else the vehicle must already be armed and in the air); send a
first setpoint (where the vehicle is, at the mission altitude) and start offboard mode. Mission
time 0 is that moment. Then, until the budget's end: telemetry (``position_velocity_ned``)
feeds :meth:`~hptrack.runtime.controller.MissionController.odometry`, detections arriving as
JSON lines on a UDP port feed ``detection``, and the controller's setpoint is streamed at
``setpoint_rate_hz`` (converted to NED by :func:`~hptrack.runtime.frames.enu_to_ned`).

Safe ends: the budget's end, Ctrl-C (or SIGTERM), a lost link (no telemetry for
``lost_link_s``), a setpoint beyond ``max_distance_m`` from home (the vehicle's position at the
mission's start), an offboard error, or a controller error each stop the stream and switch the
vehicle to hold (offboard stop) or to return-to-launch, wait for the flight mode to confirm it,
and log and report why.

Detection lines: ``{"id": "t1", "x": east_m, "y": north_m}`` with optional ``"t"`` (Unix time
of the measurement, s; default the time of arrival) and ``"cov"`` (2x2 noise covariance, m^2).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import signal
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from mavsdk import LogLevel, log_subscribe
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.offboard import OffboardAsync, OffboardError, PositionNedYaw
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

from hptrack.runtime.controller import MissionController
from hptrack.runtime.frames import enu_to_ned, ned_to_enu
from hptrack.runtime.network import (
    Refusal,
    enlarge_receive_buffer,
    kernel_drops,
    parse_detection_line,
    udp_address,
)

logger = logging.getLogger(__name__)
mavsdk_logger = logging.getLogger("mavsdk")


@dataclass(frozen=True)
class FlightOptions:
    """How ``hptrack fly`` connects and flies (m, s, Hz).

    Attributes:
        connection: MAVSDK connection URL (``udpin://0.0.0.0:14540``, ``serial:///dev/...``).
        detections: where detections arrive, ``udp://HOST:PORT`` (bound here).
        altitude_m: mission altitude above the local origin, m.
        max_distance_m: a setpoint farther than this from home ends the mission, m.
        takeoff: arm and take off to ``altitude_m`` first.
        return_to_launch: end in return-to-launch instead of hold.
        setpoint_rate_hz: offboard setpoints per second (PX4 needs more than 2).
        lost_link_s: no telemetry for this long ends the mission, s.
        connect_timeout_s: wait for an autopilot at most this long, s.
        takeoff_timeout_s: wait for the take-off altitude at most this long, s.
    """

    connection: str = "udpin://0.0.0.0:14540"
    detections: str = "udp://127.0.0.1:5005"
    altitude_m: float = 30.0
    max_distance_m: float = 1000.0
    takeoff: bool = False
    return_to_launch: bool = False
    setpoint_rate_hz: float = 20.0
    lost_link_s: float = 3.0
    connect_timeout_s: float = 30.0
    takeoff_timeout_s: float = 120.0


class FlightError(Exception):
    """The mission could not start (no autopilot, no position, arming refused...); the
    message is one line."""


@dataclass
class FlightResult:
    """How a flight ended.

    Attributes:
        reason: ``"budget"``, ``"interrupted"``, ``"lost link"``, ``"geofence"``,
            ``"offboard error"`` or ``"controller error"``.
        detail: one line with the figures.
        action: ``"hold"`` or ``"return to launch"``.
        confirmed: the flight mode telemetry reported after the switch, or ``None``.
        end: the controller's ``end`` record.
        setpoints_sent: offboard setpoints streamed.
        setpoint_rate_hz: their mean rate over the mission.
        error: the traceback of a controller error.
    """

    reason: str
    detail: str
    action: str
    confirmed: str | None
    end: dict
    setpoints_sent: int
    setpoint_rate_hz: float
    error: str | None = None


@dataclass
class _Vehicle:
    """What telemetry last said."""

    position_ned: np.ndarray | None = None
    received_at: float = -math.inf
    flight_mode: Any = None
    armed: bool = False
    in_air: bool = False


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


class _Detections(asyncio.DatagramProtocol):
    """JSON-line detections from UDP into the controller."""

    def __init__(self, flight: _Flight) -> None:
        self.flight = flight

    def datagram_received(self, data: bytes, addr: tuple) -> None:
        self.flight.on_datagram(data)


class _Flight:
    def __init__(
        self,
        controller: MissionController,
        options: FlightOptions,
        on_status: Callable[[dict], None],
        on_message: Callable[[str], None],
        stop: asyncio.Event,
    ) -> None:
        self.controller, self.options = controller, options
        self.on_status, self.on_message, self.stop = on_status, on_message, stop
        self.vehicle = _Vehicle()
        self.mono0: float | None = None
        self.unix0: float | None = None
        self.error: str | None = None
        self.sent = 0
        self.recent: deque[float] = deque(maxlen=200)
        self.home: np.ndarray | None = None

    def say(self, message: str, **fields: Any) -> None:
        self.controller.log.write(
            {"kind": "status", "t": self.mission_time(), "message": message, **fields}
        )
        self.on_message(message)

    def mission_time(self) -> float | None:
        return None if self.mono0 is None else time.monotonic() - self.mono0

    def _guard(self, call: Callable[[], Any]) -> None:
        """Run a controller call; an exception is a controller error that ends the mission."""
        try:
            call()
        except Exception:  # noqa: BLE001 - recorded, then the mission ends safely
            if self.error is None:
                self.error = traceback.format_exc()
            self.stop.set()

    # --- inputs ---------------------------------------------------------------------------
    async def watch_position(self, telemetry: TelemetryAsync) -> None:
        async for pv in telemetry.subscribe_position_velocity_ned():
            now = time.monotonic()
            ned = np.array([pv.position.north_m, pv.position.east_m, pv.position.down_m])
            self.vehicle.position_ned, self.vehicle.received_at = ned, now
            if self.mono0 is not None:
                east, north, _ = ned_to_enu(*ned)
                t = now - self.mono0
                self._guard(lambda t=t, p=(east, north): self.controller.odometry(t, p))

    async def watch_state(self, telemetry: TelemetryAsync) -> None:
        async def modes() -> None:
            async for mode in telemetry.subscribe_flight_mode():
                self.vehicle.flight_mode = mode

        async def armed() -> None:
            async for value in telemetry.subscribe_armed():
                self.vehicle.armed = bool(value)

        async def in_air() -> None:
            async for value in telemetry.subscribe_in_air():
                self.vehicle.in_air = bool(value)

        await asyncio.gather(modes(), armed(), in_air())

    def on_datagram(self, data: bytes) -> None:
        received = self.mission_time()
        if received is None:
            self._guard(
                lambda: self.controller.bad_input(
                    "detection", "before the start", "arrived before offboard started", data[:200]
                )
            )
            return
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            self._guard(
                lambda: self.controller.bad_input(
                    "detection", "malformed", "a datagram that is not UTF-8 text", data[:200]
                )
            )
            return
        for line in text.splitlines():
            if line.strip():
                self._guard(lambda line=line: self._detection_line(line, received))

    def _detection_line(self, line: str, received: float) -> None:
        parsed = parse_detection_line(line)
        if isinstance(parsed, Refusal):
            self.controller.bad_input("detection", parsed.reason, parsed.detail, line[:200])
            return
        t = received if parsed.stamp is None else parsed.stamp - self.unix0
        self.controller.detection(t, parsed.target, parsed.position, parsed.covariance)

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
        }

    async def fly(self, system: Any) -> tuple[str, str]:
        """Stream setpoints until a safe end; returns its ``(reason, detail)``."""
        options, controller = self.options, self.controller
        offboard = OffboardAsync(system)
        east, north, _ = ned_to_enu(*self.vehicle.position_ned)
        home = self.home = np.array([east, north])
        n, e, d = enu_to_ned(east, north, options.altitude_m)
        await offboard.set_position_ned(PositionNedYaw(n, e, d, 0.0))
        try:
            await offboard.start()
        except OffboardError as err:
            return "offboard error", f"offboard mode refused: {err}"
        self.mono0, self.unix0 = time.monotonic(), time.time()
        self.say(
            "offboard started: mission time 0",
            unix_time=self.unix0,
            home=home,
            altitude_m=options.altitude_m,
        )
        self._guard(lambda: controller.odometry(0.0, home))
        period = 1.0 / options.setpoint_rate_hz
        next_at = self.mono0
        next_status = self.mono0
        while True:
            now = time.monotonic()
            t = now - self.mono0
            if self.error is not None:
                return "controller error", self.error.strip().splitlines()[-1]
            if self.stop.is_set():
                return "interrupted", "Ctrl-C or a termination signal"
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
            n, e, d = enu_to_ned(setpoint.position[0], setpoint.position[1], options.altitude_m)
            try:
                await offboard.set_position_ned(PositionNedYaw(n, e, d, 0.0))
            except OffboardError as err:
                return "offboard error", str(err)
            self.sent += 1
            self.recent.append(time.monotonic())
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
            error = str(err)
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
        self.controller.log.write(record)
        self.on_message(
            f"vehicle in {mode} ({'confirmed' if confirmed else 'NOT confirmed'}"
            f"{'; ' + error if error else ''})"
        )
        return action, mode if confirmed else None


async def fly_mission(
    controller: MissionController,
    options: FlightOptions,
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
    stop: asyncio.Event | None = None,
) -> FlightResult:
    """Fly ``controller``'s mission on the vehicle at ``options.connection`` (module
    docstring).

    Raises:
        FlightError: the mission could not start (nothing was commanded, or the vehicle was
            switched to hold before raising).
    """
    stop = stop or asyncio.Event()
    flight = _Flight(controller, options, on_status, on_message, stop)
    host, port = udp_address(options.detections, "--detections")
    _route_mavsdk_logs()
    loop = asyncio.get_running_loop()
    tasks: list[asyncio.Task] = []
    transport = None
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        try:
            flight.say(f"connecting to {options.connection}")
            await mavsdk.add_any_connection(options.connection)
            system = await mavsdk.first_autopilot(timeout_s=options.connect_timeout_s)
            if system is None:
                raise FlightError(
                    f"no autopilot found on {options.connection} within "
                    f"{options.connect_timeout_s:g} s"
                )
            telemetry = TelemetryAsync(system)
            tasks = [
                asyncio.create_task(flight.watch_position(telemetry)),
                asyncio.create_task(flight.watch_state(telemetry)),
            ]
            if not await flight.wait_for(
                lambda: flight.vehicle.position_ned is not None, options.connect_timeout_s
            ):
                raise FlightError(
                    f"no local position from the vehicle within {options.connect_timeout_s:g} s"
                )
            flight.say("vehicle found; local position received")
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _Detections(flight), local_addr=(host, port)
            )
            detection_socket = transport.get_extra_info("socket")
            enlarge_receive_buffer(detection_socket)
            drops_before = kernel_drops(detection_socket)
            if options.takeoff:
                await _take_off(flight, system)
            elif not await flight.wait_for(
                lambda: flight.vehicle.armed and flight.vehicle.in_air, 3.0
            ):
                raise FlightError(
                    "the vehicle is not armed and in the air; pass --takeoff to arm and take off"
                )
            if stop.is_set():
                raise FlightError("interrupted before the mission started")
            try:
                reason, detail = await flight.fly(system)
            except Exception:  # noqa: BLE001 - end safely first, report after
                flight.error = traceback.format_exc()
                reason, detail = "controller error", flight.error.strip().splitlines()[-1]
            drops_after = kernel_drops(detection_socket)
            if drops_before is not None and drops_after is not None:
                dropped = drops_after - drops_before
                flight.say(
                    f"{dropped} detection datagrams dropped by the system (receive buffer full)",
                    dropped_datagrams=dropped,
                )
            action, confirmed = await flight.safe_end(system, reason, detail)
        finally:
            if transport is not None:
                transport.close()
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await task
            controller.close()
    t = flight.mission_time() or 0.0
    return FlightResult(
        reason,
        detail,
        action,
        confirmed,
        controller.end or {},
        flight.sent,
        flight.sent / t if t > 0 else 0.0,
        flight.error,
    )


async def _take_off(flight: _Flight, system: Any) -> None:
    options = flight.options
    action = ActionAsync(system)
    try:
        flight.say("arming")
        await action.arm()
        await action.set_takeoff_altitude(options.altitude_m)
        flight.say(f"taking off to {options.altitude_m:g} m")
        await action.takeoff()
    except ActionError as err:
        raise FlightError(f"take-off refused: {err}") from None

    def high_enough() -> bool:
        return -flight.vehicle.position_ned[2] >= options.altitude_m - 0.5

    if not await flight.wait_for(high_enough, options.takeoff_timeout_s):
        with contextlib.suppress(ActionError):
            await action.hold()
        raise FlightError(
            f"the vehicle did not reach {options.altitude_m:g} m within "
            f"{options.takeoff_timeout_s:g} s (switched to hold)"
        )


def run_flight(
    controller: MissionController,
    options: FlightOptions,
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
) -> FlightResult:
    """:func:`fly_mission` in its own event loop; Ctrl-C and SIGTERM end the mission safely
    (hold or return) instead of killing the program."""

    async def main() -> FlightResult:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        try:
            return await fly_mission(controller, options, on_status, on_message, stop)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)

    return asyncio.run(main())
