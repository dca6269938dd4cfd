"""``hptrack fly``: the mission controller on a PX4 vehicle through MAVSDK (the ``mavsdk``
package, 4.x, a binding of the MAVSDK C library), as offboard position setpoints.

Sequence: connect and wait for an autopilot; wait for a local position; read the vehicle's
horizontal speed and acceleration limits (PX4's ``MPC_XY_VEL_MAX`` and ``MPC_ACC_HOR``) and
build the mission controller with them (the caller decides the planned speed); hand the planner
its first tick (it compiles or loads its kernels then) and, meanwhile, arm and take off to the
mission altitude if asked (else the vehicle must already be armed and in the air); wait for the
first plan; send a first setpoint (where the vehicle is, at the mission altitude) and start
offboard mode. Mission time 0 is that moment. Then, until the budget's end: telemetry
(``position_velocity_ned``) feeds :meth:`~hptrack.runtime.controller.MissionController.odometry`,
detections arriving as JSON lines on a UDP port feed ``detection``, and the controller's
reference position and planned velocity are streamed at ``setpoint_rate_hz`` as offboard
position setpoints with velocity feed-forward (converted to NED by
:func:`~hptrack.runtime.frames.enu_to_ned`), so that PX4 flies the planned speed.

Safe ends: the budget's end, Ctrl-C (or SIGTERM), a lost link (no telemetry for
``lost_link_s``), a setpoint beyond ``max_distance_m`` from home (the vehicle's position at the
mission's start), an offboard error, or a controller error each stop the stream and switch the
vehicle to hold (offboard stop) or to return-to-launch, wait for the flight mode to confirm it,
and log and report why. Every MAVSDK error is told as one plain sentence (:func:`plain_error`):
what happened, what the vehicle is doing now, what to do.

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
from mavsdk.asyncio.exceptions import MavsdkConnectionError
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.offboard import (
    OffboardAsync,
    OffboardError,
    PositionNedYaw,
    VelocityNedYaw,
)
from mavsdk.asyncio.plugins.param import ParamAsync, ParamError
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync

from hptrack.interface import InputError
from hptrack.runtime.controller import MissionController
from hptrack.runtime.frames import enu_to_ned, ned_to_enu
from hptrack.runtime.links import connection_problem
from hptrack.runtime.log import MissionLog
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
        first_plan_timeout_s: wait for the planner's first plan at most this long, s.
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
    first_plan_timeout_s: float = 600.0


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


def plain_error(err: ActionError | OffboardError | ParamError, doing: str, now: str) -> str:
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


class _Detections(asyncio.DatagramProtocol):
    """JSON-line detections from UDP into the controller."""

    def __init__(self, flight: _Flight) -> None:
        self.flight = flight

    def datagram_received(self, data: bytes, addr: tuple) -> None:
        self.flight.on_datagram(data)


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
        self.recent: deque[float] = deque(maxlen=200)
        self.home: np.ndarray | None = None
        self.early: list[dict] = []

    def say(self, message: str, **fields: Any) -> None:
        record = {"kind": "status", "t": self.mission_time(), "message": message, **fields}
        if self.controller is None:  # the log starts with the controller's header
            self.early.append({**record, "said_at_unix_s": time.time()})
        else:
            self.log.write(record)
        self.on_message(message)

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
        if received is None or self.controller is None:
            if self.controller is not None:
                self._guard(
                    lambda: self.controller.bad_input(
                        "detection",
                        "before the start",
                        "arrived before offboard started",
                        data[:200],
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

    def position_enu(self) -> np.ndarray:
        east, north, _ = ned_to_enu(*self.vehicle.position_ned)
        return np.array([east, north])

    async def fly(self, system: Any) -> tuple[str, str]:
        """Stream setpoints until a safe end; returns its ``(reason, detail)``."""
        options, controller = self.options, self.controller
        offboard = OffboardAsync(system)
        home = self.home = self.position_enu()
        n, e, d = enu_to_ned(home[0], home[1], options.altitude_m)
        await offboard.set_position_velocity_ned(
            PositionNedYaw(n, e, d, 0.0), VelocityNedYaw(0.0, 0.0, 0.0, 0.0)
        )
        try:
            await offboard.start()
        except OffboardError as err:
            return "offboard error", plain_error(
                err, "switching to offboard", f"the vehicle stays in {self.mode_name()}"
            )
        self.mono0, self.unix0 = time.monotonic(), time.time()
        self.say(
            "offboard started: mission time 0",
            unix_time=self.unix0,
            home=home,
            altitude_m=options.altitude_m,
        )
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


async def fly_mission(
    build: Callable[[VehicleLimits], MissionController],
    log: MissionLog,
    options: FlightOptions,
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
    stop: asyncio.Event | None = None,
) -> FlightResult:
    """Fly the mission of the controller that ``build`` makes from the vehicle's limits, on the
    vehicle at ``options.connection``, logging to ``log`` (module docstring).

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
    loop = asyncio.get_running_loop()
    tasks: list[asyncio.Task] = []
    transport = None
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as mavsdk:
        try:
            flight.say(f"connecting to {options.connection}")
            try:
                await mavsdk.add_any_connection(options.connection)
            except MavsdkConnectionError as err:
                raise InputError(connection_problem(options.connection, str(err))) from None
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
            limits = await read_limits(system)
            controller = build(limits)
            flight.attach(controller)
            try:
                transport, _ = await loop.create_datagram_endpoint(
                    lambda: _Detections(flight), local_addr=(host, port)
                )
            except OSError as err:
                raise InputError(
                    f"--detections {options.detections!r}: cannot receive there ({err.strerror})"
                ) from None
            detection_socket = transport.get_extra_info("socket")
            enlarge_receive_buffer(detection_socket)
            drops_before = kernel_drops(detection_socket)
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
            if not await flight.wait_for(
                lambda: (
                    controller.first_plan(0.0) is not None or controller.planner_error is not None
                ),
                options.first_plan_timeout_s,
            ):
                if stop.is_set():
                    raise FlightError("interrupted before the mission started")
                raise FlightError(
                    f"the planner gave no first plan within {options.first_plan_timeout_s:g} s; "
                    "the vehicle stays in its current mode (offboard never started)"
                )
            if controller.first_plan_s is None:
                raise FlightError(
                    f"the planner failed on its first plan ({controller.planner_error}); "
                    "the vehicle stays in its current mode (offboard never started)"
                )
            flight.say(
                f"first plan ready before offboard: {controller.first_plan_s:.2f} s of "
                f"planning, {time.monotonic() - started:.1f} s after the start of the "
                "take-off phase",
                first_plan_s=controller.first_plan_s,
            )
            if stop.is_set():
                raise FlightError("interrupted before the mission started")
            try:
                reason, detail = await flight.fly(system)
            except Exception:  # noqa: BLE001 - end safely first, report after
                flight.error = traceback.format_exc()
                reason, detail = "controller error", flight.error.strip().splitlines()[-1]
            drops_after = kernel_drops(detection_socket)
            # said only when some were lost (the counts are known on Linux only)
            if drops_before is not None and drops_after is not None and drops_after > drops_before:
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
        flight.error,
    )


async def _take_off(flight: _Flight, system: Any) -> None:
    options = flight.options
    action = ActionAsync(system)
    step = "arming"
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

    def high_enough() -> bool:
        return -flight.vehicle.position_ned[2] >= options.altitude_m - 0.5

    if not await flight.wait_for(high_enough, options.takeoff_timeout_s):
        with contextlib.suppress(ActionError):
            await action.hold()
        raise FlightError(
            f"the vehicle did not reach {options.altitude_m:g} m within "
            f"{options.takeoff_timeout_s:g} s (switched to hold)"
        )
    flight.say(f"at {options.altitude_m:g} m")


def run_flight(
    build: Callable[[VehicleLimits], MissionController],
    log: MissionLog,
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
            return await fly_mission(build, log, options, on_status, on_message, stop)
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)

    return asyncio.run(main())
