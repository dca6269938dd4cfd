"""``hptrack fly`` for a team: the team's mission controller
(`hptrack.runtime.team.TeamController`) on several PX4 vehicles, one MAVSDK connection per
vehicle (PX4's multi-vehicle SITL runs one autopilot per vehicle, each on its own MAVLink port;
MAVSDK connects one ``System`` per vehicle).

The sequence is the single vehicle's (`hptrack.runtime.mavsdk_adapter`), done for each vehicle:
connect (each connection locks onto its first autopilot), wait for every local position, read
every vehicle's limits (the caller plans each vehicle with its own speed), put the fence on
every vehicle (the scenario's, its metres from the first vehicle's GPS origin, so that every
vehicle holds the same zones; with ``--fence-from-vehicle`` every vehicle's, which must be the
first's), hand the planner its first tick, take every vehicle off at once (if asked; a take-off
that fails holds the others), wait for the first plan, then start offboard on each vehicle in
turn. Mission time 0 is the moment the last one reports OFFBOARD. Then each setpoint period
streams every vehicle's reference (kept apart by the separation rule, then kept inside the
fence) to its own vehicle. Every vehicle's messages and
records carry its index (``vehicle j: ...``, ``"vehicle": j``).

The safe ends are the single vehicle's, for the team: the budget, Ctrl-C, a vehicle's lost
link, a vehicle's setpoint beyond ``max_distance_m`` from its home, or a controller error hold
every vehicle; a vehicle that leaves OFFBOARD (a pilot or a failsafe) is left to its pilot and
the others hold. The scenario is written in the first vehicle's local frame, and every other
vehicle's positions and setpoints are moved between its own local frame and that one by the
offset of its GPS origin from the first's (`_frame_offsets`).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import socket
import time
import traceback
from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.exceptions import MavsdkConnectionError
from mavsdk.asyncio.plugins.action import ActionAsync, ActionError
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync
from mavsdk.asyncio.plugins.offboard import (
    OffboardAsync,
    OffboardError,
    PositionNedYaw,
    VelocityNedYaw,
)
from mavsdk.asyncio.plugins.telemetry import FlightMode, TelemetryAsync, TelemetryError

from hptrack.interface import InputError
from hptrack.models.fence import FenceSpec
from hptrack.runtime.frames import enu_to_ned, geodetic_to_local
from hptrack.runtime.geofence import fence_difference
from hptrack.runtime.intake import DetectionIntake
from hptrack.runtime.links import connection_problem
from hptrack.runtime.log import ABORT, MISSION_START_MESSAGE, MissionLog
from hptrack.runtime.mavsdk_adapter import (
    PILOT_TOOK_OVER,
    FlightError,
    FlightOptions,
    FlightResult,
    VehicleLimits,
    _first_autopilot,
    _Flight,
    _lock_ids,
    _route_mavsdk_logs,
    _say_intake,
    _take_off,
    open_detections,
    plain_error,
    read_limits,
    say_fence_margin,
    say_fence_projections,
    sync_fence,
    wait_for_first_plan,
)
from hptrack.runtime.network import kernel_drops, udp_address
from hptrack.runtime.team import TeamController


def _prefixed(on_message: Callable[[str], None], prefix: str, text: str) -> None:
    on_message(prefix + text)


class _VehicleLog:
    """The mission log as one vehicle of the team writes to it: every record with the
    vehicle's index (``"vehicle": j``)."""

    def __init__(self, log: MissionLog, index: int) -> None:
        self._log, self._index = log, index

    def write(self, record: dict) -> dict:
        return self._log.write({**record, "vehicle": self._index})

    def __getattr__(self, name: str) -> Any:
        return getattr(self._log, name)


class _Member(_Flight):
    """One vehicle of the team: the single vehicle's flight with its index on every message,
    record and odometry."""

    def __init__(self, index: int, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.index = index
        self.team_controller: TeamController | None = None
        self.offset = np.zeros(2)
        """Where this vehicle's local origin is in the team's frame (the first vehicle's
        local frame), east-north m (`_frame_offsets`)."""

    def position_enu(self) -> np.ndarray:
        """The vehicle's position in the team's frame, m."""
        return super().position_enu() + self.offset

    def say(self, message: str, *, show: bool = True, kind: str = "status", **fields: Any) -> None:
        """`_Flight.say` with the vehicle's index in the record (its console lines start
        with it: the member's ``on_message``; the records it writes later carry it too,
        `_VehicleLog`)."""
        super().say(message, show=show, kind=kind, vehicle=self.index, **fields)

    def attach(self, controller: Any) -> None:
        """`_Flight.attach`, then every record this vehicle writes carries its index."""
        super().attach(controller)
        self.log = _VehicleLog(self.log, self.index)  # type: ignore[assignment]
        self.team_controller = controller

    def feed_odometry(self, t: float, position: tuple[float, float]) -> None:
        assert self.team_controller is not None
        self.team_controller.odometry(t, np.asarray(position) + self.offset, self.index)


async def _connect(member: _Member, mavsdk: Mavsdk, tasks: list[asyncio.Task]) -> Any:
    """Connect ``member`` and lock onto its autopilot; starts its telemetry watches."""
    url = member.options.connection
    try:
        await mavsdk.add_any_connection(url)
    except MavsdkConnectionError as err:
        raise InputError(connection_problem(url, str(err))) from None
    system = await _first_autopilot(mavsdk, member)
    await _lock_ids(member, system)
    tasks += [
        asyncio.create_task(member.watch_position(MavlinkDirectAsync(system))),
        asyncio.create_task(member.watch_state(TelemetryAsync(system))),
        asyncio.create_task(member.watch_other_systems(mavsdk)),
    ]
    return system


async def _take_off_all(members: list[_Member], systems: list[Any]) -> None:
    """Take every vehicle off at once; one that fails holds the others and raises its
    failure."""
    results = await asyncio.gather(
        *(_take_off(m, s) for m, s in zip(members, systems, strict=True)), return_exceptions=True
    )
    failed = [(m, r) for m, r in zip(members, results, strict=True) if isinstance(r, Exception)]
    if not failed:
        return
    for member, system in zip(members, systems, strict=True):
        if all(member is not f for f, _ in failed):
            with contextlib.suppress(ActionError):
                await ActionAsync(system).hold()
    member, error = failed[0]
    if isinstance(error, FlightError):
        raise FlightError(f"vehicle {member.index}: {error}", error.reason)
    raise error


async def _start_offboard_all(
    members: list[_Member], systems: list[Any], altitude_m: float
) -> list[OffboardAsync]:
    """Start offboard on each vehicle in turn at its position (the mission altitude); one that
    never enters OFFBOARD stops offboard on those started and raises. Returns each vehicle's
    `OffboardAsync`."""
    offboards: list[OffboardAsync] = []
    for member, system in zip(members, systems, strict=True):
        offboard = OffboardAsync(system)
        home = member.home = member.position_enu()
        east, north = home - member.offset
        n, e, d = enu_to_ned(east, north, altitude_m)
        first = (PositionNedYaw(n, e, d, 0.0), VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        try:
            await offboard.set_position_velocity_ned(*first)
            await member.start_offboard(offboard, first)
        except FlightError as err:
            for started in offboards:
                with contextlib.suppress(OffboardError):
                    await started.stop()
            raise FlightError(f"vehicle {member.index}: {err}", err.reason) from None
        offboards.append(offboard)
    return offboards


async def _frame_offsets(
    members: list[_Member], systems: list[Any]
) -> list[tuple[float, float] | None]:
    """Put every vehicle's local frame into the first's: each vehicle's ``GPS_GLOBAL_ORIGIN``
    (the origin of its local frame) as east-north metres from the first's
    (`hptrack.runtime.frames.geodetic_to_local`); a vehicle that gives none is taken to share
    the first's frame, and said so. PX4 SITL instances each set their origin where they start;
    the stubs of ``vehicle-sim --instances`` share one. Returns every vehicle's origin
    (latitude, longitude, degrees; ``None``: it gave none)."""
    origins: list[tuple[float, float] | None] = []
    for member, system in zip(members, systems, strict=True):
        try:
            origin = await TelemetryAsync(system).get_gps_global_origin()
            origins.append((float(origin.latitude_deg), float(origin.longitude_deg)))
        except TelemetryError as err:
            origins.append(None)
            member.say(f"no GPS_GLOBAL_ORIGIN ({err}): its local frame is taken to be vehicle 0's")
    first = origins[0]
    for member, origin in zip(members, origins, strict=True):
        if first is not None and origin is not None:
            north, east = geodetic_to_local(*first, *origin)
            member.offset = np.array([east, north])
        member.say(
            f"local frame origin at ({member.offset[0]:.1f}, {member.offset[1]:.1f}) m in "
            "vehicle 0's",
            show=member.index > 0,
            kind="frame",
            offset=member.offset,
            origin=origin,
        )
    return origins


async def _sync_fences(
    members: list[_Member],
    systems: list[Any],
    fence: FenceSpec | None,
    origin: tuple[float, float] | None,
) -> FenceSpec | None:
    """The fence the team flies, put on every vehicle (`sync_fence` for each, the fence's
    metres from ``origin``, the first vehicle's ``GPS_GLOBAL_ORIGIN``, so that every vehicle
    holds the same zones on the ground); with ``fence_from_vehicle`` every vehicle's fence,
    which must be the first's. ``None``: no fence (the vehicles' are left alone).

    Raises:
        InputError: a vehicle's fence differs from the scenario's or from the first's.
    """
    flown: FenceSpec | None = None
    for member, system in zip(members, systems, strict=True):
        held = await sync_fence(member, system, fence, origin)
        if flown is None or held is None:
            flown = held
            continue
        difference = fence_difference(flown, held)
        if difference is not None:
            raise InputError(
                f"--fence-from-vehicle: vehicle {member.index}'s fence differs from vehicle "
                f"0's: {difference}; nothing was flown"
            )
    return flown


def _team_status(members: list[_Member], controller: TeamController, t: float) -> dict:
    """The live view's snapshot of the team: the first vehicle's, with every vehicle's mode
    and the farthest from its home."""
    statuses = [m.status(t, m.home - m.offset) for m in members if m.home is not None]
    status = statuses[0] if statuses else {**controller.status(), "t": t}
    status["flight_mode"] = ", ".join(str(s.get("flight_mode")) for s in statuses)
    status["distance_from_home_m"] = max((s["distance_from_home_m"] for s in statuses), default=0)
    status["setpoint_rate_hz"] = min((s["setpoint_rate_hz"] for s in statuses), default=0.0)
    return status


async def _fly_team(
    members: list[_Member], offboards: list, controller: TeamController
) -> tuple[str, str, int | None]:
    """Stream every vehicle's setpoint until a safe end; returns its ``(reason, detail)`` and
    the vehicle that left OFFBOARD (``None``: none did)."""
    lead = members[0]
    options = lead.options
    mono0 = time.monotonic()
    unix0 = time.time()
    for member in members:  # one mission clock
        member.unix0, member.mono0 = unix0, mono0
    lead.say(
        MISSION_START_MESSAGE,
        unix_time=unix0,
        home=[m.home for m in members],
        altitude_m=options.altitude_m,
    )
    period = 1.0 / options.setpoint_rate_hz
    next_at = next_status = mono0
    last_sent: float | None = None
    while True:
        now = time.monotonic()
        t = now - mono0
        if lead.error is None and lead.intake is not None:
            lead.error = lead.intake.error
        error = next((m.error for m in members if m.error is not None), None)
        if error is not None:
            lead.error = error
            return "controller error", error.strip().splitlines()[-1], None
        if lead.stop.is_set():
            return "interrupted", "Ctrl-C or a termination signal", None
        if lead.log_failed():
            return "log failure", f"the mission log stopped ({lead.log.stopped})", None
        for member in members:
            if member.vehicle.flight_mode != FlightMode.OFFBOARD:
                return (
                    PILOT_TOOK_OVER,
                    (
                        f"vehicle {member.index} left OFFBOARD for {member.mode_name()} at mission "
                        f"time {t:.1f} s (a pilot or a failsafe took over)"
                    ),
                    member.index,
                )
            link_age = now - member.vehicle.received_at
            if link_age > options.lost_link_s:
                return (
                    "lost link",
                    (
                        f"no telemetry from vehicle {member.index} for {link_age:.1f} s (limit "
                        f"{options.lost_link_s:g} s)"
                    ),
                    None,
                )
        try:
            setpoints = controller.setpoints(t)
        except Exception:  # noqa: BLE001 - a controller bug ends the mission safely
            lead.error = traceback.format_exc()
            continue
        if controller.finished:
            assert controller.end is not None
            return controller.end["reason"], f"mission time {t:.1f} s", None
        for member, setpoint in zip(members, setpoints, strict=True):
            distance = float(np.hypot(*(setpoint.position - member.home)))
            if distance > options.max_distance_m:
                return (
                    "geofence",
                    (
                        f"vehicle {member.index}'s setpoint {distance:.0f} m from its home, beyond "
                        f"--max-distance {options.max_distance_m:g} m"
                    ),
                    None,
                )
        for member, offboard, setpoint in zip(members, offboards, setpoints, strict=True):
            member.check_following(t, setpoint.reference)
            x, y = setpoint.reference - member.offset
            n, e, d = enu_to_ned(x, y, options.altitude_m)
            v_n, v_e, _ = enu_to_ned(setpoint.velocity[0], setpoint.velocity[1], 0.0)
            try:
                await offboard.set_position_velocity_ned(
                    PositionNedYaw(n, e, d, 0.0), VelocityNedYaw(v_n, v_e, 0.0, 0.0)
                )
            except OffboardError as err:
                return (
                    "offboard error",
                    plain_error(
                        err,
                        f"sending vehicle {member.index} a setpoint",
                        f"it reports {member.mode_name()}",
                    ),
                    None,
                )
            member.sent += 1
            member.recent.append(time.monotonic())
        sent_at = time.monotonic()
        if last_sent is not None:
            gap = sent_at - last_sent
            for member in members:
                member.max_gap_s = max(member.max_gap_s, gap)
        last_sent = sent_at
        if now >= next_status:
            lead.on_status(_team_status(members, controller, t))
            next_status = now + 0.25
        next_at += period
        await asyncio.sleep(max(0.0, next_at - time.monotonic()))


async def _safe_end_all(
    members: list[_Member], systems: list[Any], reason: str, detail: str, left: int | None
) -> tuple[str, str | None]:
    """End the mission on every vehicle: the one that left OFFBOARD (``left``) to its pilot,
    the others in hold (or return); returns the actions and the confirmed modes, one line
    each."""
    controller = members[0].team_controller
    assert controller is not None
    if not controller.finished:
        controller.finish(members[0].mission_time() or 0.0, reason)
    ends = []
    for member, system in zip(members, systems, strict=True):
        if left is not None and member.index != left:
            why = f"vehicle {left} left OFFBOARD"
            ends.append(await member.safe_end(system, why, detail))
        else:
            ends.append(await member.safe_end(system, reason, detail))
    actions = ", ".join(f"{m.index} {a}" for m, (a, _) in zip(members, ends, strict=True))
    confirmed = [c for _, c in ends]
    shown = (
        ", ".join(f"{m.index} {c}" for m, c in zip(members, confirmed, strict=True))
        if all(c is not None for c in confirmed)
        else None
    )
    return f"vehicles {actions}", shown


async def fly_team_mission(
    build: Callable[[list[VehicleLimits], FenceSpec | None], TeamController],
    log: MissionLog,
    options: FlightOptions,
    connections: list[str],
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
    stop: asyncio.Event | None = None,
    fence: FenceSpec | None = None,
) -> FlightResult:
    """Fly the team mission of the controller ``build`` makes from every vehicle's limits and
    the fence flown (`_sync_fences` with the scenario's ``fence``), on the vehicles at
    ``connections`` (one URL per UAV, in the order of ``agents:``), logging to ``log``
    (module docstring).

    Raises:
        FlightError: the mission could not start.
        InputError: a connection or the detection address cannot be opened.
    """
    stop = stop or asyncio.Event()
    members = [
        _Member(j, None, dataclasses.replace(options, connection=url), on_status,
                partial(_prefixed, on_message, f"vehicle {j}: "), stop, log)
        for j, url in enumerate(connections)
    ]  # fmt: skip
    lead = members[0]
    host, port = udp_address(options.detections, "--detections")
    _route_mavsdk_logs()
    tasks: list[asyncio.Task] = []
    sock: socket.socket | None = None
    intake: DetectionIntake | None = None
    controller: TeamController | None = None
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with contextlib.AsyncExitStack() as stack:
        try:
            systems = []
            for member in members:
                mavsdk = await stack.enter_async_context(Mavsdk(config))
                systems.append(await _connect(member, mavsdk, tasks))
            if not await lead.wait_for(
                lambda: all(m.vehicle.position_ned is not None for m in members),
                options.connect_timeout_s,
            ):
                missing = [m.index for m in members if m.vehicle.position_ned is None]
                raise FlightError(
                    f"no local position from vehicles {missing} within "
                    f"{options.connect_timeout_s:g} s"
                )
            for member in members:
                member.say("vehicle found; local position received")
            origins = await _frame_offsets(members, systems)
            limits = [await read_limits(system) for system in systems]
            flown_fence = await _sync_fences(members, systems, fence, origins[0])
            controller = build(limits, flown_fence)
            for member in members:
                member.attach(controller)
            if flown_fence is not None:
                for member, system in zip(members, systems, strict=True):
                    speed = controller.mission.vehicle_mission(member.index).agent_speed
                    await say_fence_margin(member, system, speed, flown_fence.margin)
            if lead.log_failed():
                raise FlightError(
                    f"the mission log cannot be written ({log.stopped}); nothing was flown"
                )
            sock, drops_before, intake = open_detections(options, host, port, lead)
            started = time.monotonic()
            controller.prepare(np.array([m.position_enu() for m in members]))
            on_message("computing the first plan (the planner compiles or loads its kernels)")
            if options.takeoff:
                await _take_off_all(members, systems)
            elif not await lead.wait_for(
                lambda: all(m.vehicle.armed and m.vehicle.in_air for m in members), 3.0
            ):
                raise FlightError(
                    "a vehicle is not armed and in the air; pass --takeoff to arm and take off"
                )
            await wait_for_first_plan(
                lead, controller, options, stop, started, "the vehicles stay in their current modes"
            )
            offboards = await _start_offboard_all(members, systems, options.altitude_m)
            left: int | None = None
            try:
                reason, detail, left = await _fly_team(members, offboards, controller)
            except FlightError:
                raise
            except Exception:  # noqa: BLE001 - end safely first, report after
                lead.error = traceback.format_exc()
                reason, detail = "controller error", lead.error.strip().splitlines()[-1]
            flown_s = lead.mission_time() or 0.0
            for member in members:
                member.say(
                    f"{member.sent} setpoints sent in {flown_s:.1f} s, largest gap "
                    f"{member.max_gap_s:.3f} s",
                    show=False,
                    setpoints=member.sent,
                    mission_time_s=flown_s,
                    max_gap_s=member.max_gap_s,
                    foreign_odometry=member.foreign,
                )
            if flown_fence is not None:
                say_fence_projections(lead, controller)
            intake.stop()
            _say_intake(lead, intake, drops_before, kernel_drops(sock))
            action, confirmed = await _safe_end_all(members, systems, reason, detail, left)
        except FlightError as err:
            if controller is not None:
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
            if controller is not None:
                controller.close()
    t = lead.mission_time() or 0.0
    sent = min(m.sent for m in members)
    foreign: dict[str, int] = {}
    for member in members:
        for source, count in member.foreign.items():
            foreign[f"vehicle {member.index}: {source}"] = count
    return FlightResult(
        reason,
        detail,
        action,
        confirmed,
        controller.end or {},
        sum(m.sent for m in members),
        sent / t if t > 0 else 0.0,
        max(m.max_gap_s for m in members),
        intake.counts(),
        log.stopped,
        lead.error,
        foreign,
        sum(m.follow_warnings for m in members),
    )


def run_team_flight(
    build: Callable[[list[VehicleLimits], FenceSpec | None], TeamController],
    log: MissionLog,
    options: FlightOptions,
    connections: list[str],
    on_status: Callable[[dict], None] = lambda status: None,
    on_message: Callable[[str], None] = lambda text: None,
    fence: FenceSpec | None = None,
) -> FlightResult:
    """`fly_team_mission` in its own event loop; Ctrl-C and SIGTERM end it safely."""
    import signal

    async def main() -> FlightResult:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.add_signal_handler(sig, stop.set)
        try:
            return await fly_team_mission(
                build, log, options, connections, on_status, on_message, stop, fence
            )
        finally:
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.remove_signal_handler(sig)

    return asyncio.run(main())
