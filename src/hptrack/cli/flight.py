"""``hptrack fly``, ``hptrack vehicle-sim``, ``hptrack targets-sim`` and ``hptrack replay``: a
mission on a PX4 vehicle through MAVSDK, a PX4-like MAVLink vehicle stub for dry runs, simulated
targets and detections for any autopilot in software-in-the-loop, and the replay of a mission
log.

Also runnable as ``python3 -m hptrack COMMAND ...`` (as every command).
"""

from __future__ import annotations

import json
import math
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Annotated, Any

import typer
from pydantic import ValidationError
from rich.console import Group
from rich.live import Live
from rich.markup import escape
from rich.table import Table

from hptrack.cli.common import (
    check_output_path,
    check_seed,
    console,
    error_console,
    planner_options,
    planner_settings_for,
    write_json,
)
from hptrack.interface import CurrentPlan, InputError
from hptrack.registry import PLANNERS, check_team, make_planner, planner_entry
from hptrack.scenario import Scenario, load_scenario
from hptrack.scenario.io import file_data, format_validation_error, parse_scenario

FLY_ITERATIONS = 2000
"""Tree-search simulations per decision in ``fly`` when neither effort flag is given (a
re-plan takes well under the default 1 s deadline on a 2-core machine, and a replay repeats
it exactly)."""

EXIT_ABORTED = 3
"""Exit code of a flight that could not start (a failed take-off, offboard never entered...)
or ended early for safety."""
EXIT_PILOT = 4
"""Exit code of a flight whose vehicle left OFFBOARD during the mission (a pilot or a failsafe
took over)."""


FLIGHT_MCTS_OPTIONS = {"preset": "improved", "readmit": "true"}
"""``mcts`` options, as ``-o`` text, that ``fly`` sets unless given (or ``preset=paper`` is):
the preset its flights were measured with at `FLY_ITERATIONS` (the revisit tour inside a
flight's searches is not measured), and a vehicle never idles while targets are unmeasured."""
SEARCH_PLANNERS = ("mcts", "team-mcts", "team-cbba")
"""The planners that ``fly`` flies with `FLY_ITERATIONS` and `FLIGHT_MCTS_OPTIONS` (each
UAV's search, for a team)."""
TEAM_PORT = 14540
"""``fly``'s default connection of a team's UAV ``j``: ``udpin://127.0.0.1:(TEAM_PORT + j)``
(PX4's multi-vehicle SITL sends instance ``j``'s API link to port 14540 + j, as
``vehicle-sim --instances`` does)."""


def flight_planner_settings(
    planner: str, pairs: list[str] | None, iterations: int | None, time_limit: float | None
) -> Any:
    """The settings ``fly`` flies ``planner`` with: the ``-o`` options and effort flags, with
    `FLY_ITERATIONS` and `FLIGHT_MCTS_OPTIONS` for ``mcts`` (and the team planners that
    search, `SEARCH_PLANNERS`) where they are not given."""
    if planner in SEARCH_PLANNERS:
        if iterations is None and time_limit is None:
            iterations = FLY_ITERATIONS
        given = planner_options(pairs, (planner,))[planner]
        if given.get("preset") != "paper":
            options = FLIGHT_MCTS_OPTIONS.items()
            prefix = "mcts." if planner == "mcts" else ""  # one planner runs: a bare key
            extra = [f"{prefix}{k}={v}" for k, v in options if k not in given]
            pairs = [*extra, *(pairs or [])]
    return planner_settings_for((planner,), pairs, iterations, time_limit)[planner]


def _controller_settings(deadline: float, stale_after: float, keep_lag: bool = True) -> Any:
    from hptrack.runtime.inputs import ControllerSettings

    try:
        return ControllerSettings(
            planner_deadline_s=deadline, stale_odometry_s=stale_after, keep_lag=keep_lag
        )
    except ValidationError as err:
        message = format_validation_error(err).replace("planner_deadline_s", "--deadline")
        raise InputError(message.replace("stale_odometry_s", "--stale-after")) from None


FLIGHT_FLAGS = {
    "altitude_m": "--altitude",
    "max_distance_m": "--max-distance",
    "setpoint_rate_hz": "--rate",
    "lost_link_s": "--lost-link",
    "connect_timeout_s": "--connect-timeout",
    "first_plan_timeout_s": "--first-plan-timeout",
    "log_failure": "--on-log-failure",
    "fence_action": "--fence-action",
}
"""`FlightOptions` fields by the ``fly`` option that sets them."""


def _flag_names(message: str) -> str:
    """A `FlightOptions` message with its field named as the ``fly`` option."""
    field_name = message.split(" ", 1)[0]
    return FLIGHT_FLAGS.get(field_name, field_name) + message[len(field_name) :]


def _positive(value: float, option: str, low: float = 0.0, high: float = math.inf) -> None:
    if not (math.isfinite(value) and low < value <= high):
        raise InputError(f"{option} must be a number in ({low:g}, {high:g}], got {value}")


def _subtask_text(plan: CurrentPlan | None, target_ids: tuple[str, ...]) -> str:
    if plan is None or plan.subtask is None:
        return "-"
    sub = plan.subtask
    if sub.target is None:
        return f"{sub.kind} (since step {sub.start_step})"
    name = target_ids[sub.target]
    if sub.kind == "pursue":
        extra = "" if sub.p_find is None else f", p_find {sub.p_find:.2f}"
        return f"pursue {name} (since step {sub.start_step}{extra})"
    verb = "dwell on" if sub.kind == "dwell" else "follow"
    return f"{verb} {name} (since step {sub.start_step})"


def _live_view(status: dict) -> Group:
    head = Table.grid(padding=(0, 2))
    head.add_column(style="bold")
    head.add_column()
    head.add_row("mission time", f"{status['t']:.1f} / {status['budget']:g} s")
    head.add_row(
        "setpoint",
        escape(
            f"{status.get('mode')}  (vehicle "
            f"{status.get('flight_mode')}, "
            f"{status.get('setpoint_rate_hz', 0):.1f} Hz)"
        ),
    )
    head.add_row("sub-task", escape(_subtask_text(status["plan"], status["target_ids"])))
    if "min_separation_m" in status:
        yielding = [
            f"{j} to {i}" for j, i in enumerate(status.get("yielding") or []) if i is not None
        ]
        head.add_row(
            "separation",
            f"smallest {status['min_separation_m']:.1f} m at the ticks; yielding: "
            + (", ".join(yielding) or "none"),
        )
    last = status.get("last_detection")
    name = (
        None
        if not last
        else last["target"] or "report at ({:.1f}, {:.1f}) m".format(*last["position"])
    )
    head.add_row(
        "last detection",
        "-"
        if not last
        else escape(f"{name} at {last['t']:.1f} s ({status['t'] - last['t']:.1f} s ago)"),
    )
    head.add_row(
        "from home",
        f"{status.get('distance_from_home_m', 0):.0f} m at "
        f"{status.get('altitude_m', 0):.0f} m altitude",
    )
    fence = status.get("fence")
    if fence is not None:
        where = {None: "", True: "; vehicle inside", False: "; vehicle in the margin"}
        head.add_row(
            "fence",
            f"margin {fence['margin_m']:g} m{where[fence['vehicle_free']]}; "
            f"{fence['projections']} setpoints projected inside",
        )
    rejected = status.get("rejected") or {}
    refused = ", ".join(f"{k} {v}" for k, v in rejected.items()) or "none"
    if status.get("dropped_lines"):
        refused += f"; {status['dropped_lines']} detection lines dropped"
    head.add_row("refused inputs", escape(refused))
    targets = Table(show_edge=False)
    targets.add_column("target")
    targets.add_column("log det Σxy", justify="right")
    for tid, value in (status.get("logdet") or {}).items():
        targets.add_row(escape(tid), f"{value:.2f}")
    tracking = status.get("tracking")
    if tracking is None:
        return Group(head, targets)
    return Group(head, targets, *_tracking_view(tracking))


def _tracking_view(tracking: dict) -> list[Table]:
    """The live view's part without identity: the counts, the last look's associations (each
    report to a belief with its weight, or to none) and claims, the tentative tracks."""
    counts = tracking["counts"]
    head = Table.grid(padding=(0, 2))
    head.add_column(style="bold")
    head.add_column()
    head.add_row(
        "associations",
        f"{counts.get('reports', 0)} reports in {counts.get('looks', 0)} looks, "
        f"{counts.get('taken by a belief', 0)} taken by a belief, "
        f"{counts.get('claims', 0)} claimed by a tentative track"
        + (f", {counts['superseded']} superseded" if counts.get("superseded") else ""),
    )
    look = tracking["look"]
    if look is not None:
        went = [
            "none" if belief is None else f"{belief} ({weight:.2f})"
            for belief, weight in zip(look["belief"], look["weight"], strict=True)
        ]
        claims = "".join(f"; {tid} claimed by a tentative track" for tid, _ in look["claims"])
        head.add_row(
            "last look",
            escape(
                f"tick {look['k']} at {look['time']:.1f} s: "
                + (", ".join(f"report -> {w}" for w in went) or "no report")
                + claims
            ),
        )
    head.add_row("waiting reports", str(tracking["waiting"]))
    tracks = Table(show_edge=False)
    tracks.add_column("tentative track")
    tracks.add_column("x, y (m)", justify="right")
    tracks.add_column("hits / looks", justify="right")
    for number, (x, y, looks, hits) in enumerate(tracking["tentative"], start=1):
        tracks.add_row(str(number), f"{x:.1f}, {y:.1f}", f"{hits} / {looks}")
    return [head, tracks] if tracking["tentative"] else [head]


def load_flight_scenario(path: Path, synthetic: bool = False) -> Scenario:
    """The scenario of a flight command: a team that flight cannot fly is refused in one line
    (`hptrack.runtime.team.team_flight_problem`), and, for the synthetic targets
    (``synthetic``), one whose UAVs they cannot look with
    (`hptrack.runtime.team.synthetic_team_problem`)."""
    scenario = load_scenario(path)
    if scenario.n_vehicles > 1:
        from hptrack.runtime.team import synthetic_team_problem, team_flight_problem

        problem = team_flight_problem(scenario)
        if problem is None and synthetic:
            problem = synthetic_team_problem(scenario)
        if problem is not None:
            raise InputError(f"{path}: agents: lists {scenario.n_vehicles} UAVs; {problem}")
    return scenario


def team_connections(connections: list[str] | None, n_vehicles: int) -> list[str]:
    """One connection URL per UAV: those given (one per UAV, in the order of ``agents:``), or
    the defaults (`TEAM_PORT`; ``udpin://127.0.0.1:14540`` for one UAV).

    Raises:
        InputError: not one ``--connection`` per UAV.
    """
    if not connections:
        return [f"udpin://127.0.0.1:{TEAM_PORT + j}" for j in range(n_vehicles)]
    if len(connections) != n_vehicles:
        raise InputError(
            f"--connection given {len(connections)} times; the scenario flies {n_vehicles} "
            f"UAV{'s' if n_vehicles > 1 else ''}: give one --connection per UAV, in the order "
            "of agents:"
        )
    for j, url in enumerate(connections):
        if url in connections[:j]:
            raise InputError(f"--connection {url[:80]!r} is given twice: one per UAV")
    return list(connections)


def fly(
    scenario_path: Annotated[Path, typer.Argument(metavar="SCENARIO", help="Scenario YAML file.")],
    connection: Annotated[
        list[str] | None,
        typer.Option(
            help="MAVSDK connection URL of the vehicle (the default listens on loopback; "
            "udpin://0.0.0.0:14540 listens on every interface); for a team, one per UAV in the "
            "order of agents: (default udpin://127.0.0.1:14540, 14541, ...)."
        ),
    ] = None,
    detections: Annotated[
        str, typer.Option(help="UDP address where detections arrive as JSON lines.")
    ] = "udp://127.0.0.1:5005",
    cap_speed: Annotated[
        bool,
        typer.Option(
            "--cap-speed",
            help="Plan with the vehicle's MPC_XY_VEL_MAX when the scenario's agent speed is "
            "higher (else such a flight is refused).",
        ),
    ] = False,
    first_plan_timeout: Annotated[
        float,
        typer.Option(help="Wait this long for the planner's first plan before offboard, s."),
    ] = 600.0,
    altitude: Annotated[
        float, typer.Option(help="Mission altitude above the local origin, m.")
    ] = 30.0,
    log_path: Annotated[
        Path | None,
        typer.Option("--log", help="Mission log (JSON lines); default hptrack-flight-TIME.jsonl."),
    ] = None,
    log_max_mb: Annotated[
        float, typer.Option(help="The mission log stops growing at this size, MB.")
    ] = 1000.0,
    on_log_failure: Annotated[
        str,
        typer.Option(
            help="When the mission log stops growing (a full disk, --log-max-mb): continue "
            "(say so and fly on) or hold (end the mission in hold)."
        ),
    ] = "continue",
    max_distance: Annotated[
        float, typer.Option(help="A setpoint farther than this from home ends the mission, m.")
    ] = 1000.0,
    planner: Annotated[
        str | None,
        typer.Option(
            help="One of: "
            + ", ".join(name for name, entry in PLANNERS.items() if not entry.reads_truth)
            + " (default mcts; team-mcts for a team)."
        ),
    ] = None,
    separation: Annotated[
        float | None,
        typer.Option(
            help="A team's minimum horizontal distance between two vehicles' references, m "
            "(default 10)."
        ),
    ] = None,
    iterations: Annotated[
        int | None,
        typer.Option(help=f"Tree-search iterations per decision (default {FLY_ITERATIONS})."),
    ] = None,
    time_limit: Annotated[
        float | None,
        typer.Option(help="Planning seconds per decision (a replay may then decide differently)."),
    ] = None,
    option: Annotated[
        list[str] | None, typer.Option("--option", "-o", help="Planner option KEY=VALUE.")
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Planner seed (default the scenario's).")] = None,
    takeoff: Annotated[
        bool, typer.Option("--takeoff/--no-takeoff", help="Arm and take off to --altitude first.")
    ] = False,
    return_to_launch: Annotated[
        bool, typer.Option("--return-to-launch", help="End in return-to-launch instead of hold.")
    ] = False,
    rate: Annotated[float, typer.Option(help="Offboard setpoints per second.")] = 20.0,
    deadline: Annotated[float, typer.Option(help="Planner deadline per decision, s.")] = 1.0,
    stale_after: Annotated[
        float, typer.Option(help="Hold when odometry is older than this, s.")
    ] = 1.0,
    keep_lag: Annotated[
        bool,
        typer.Option(
            "--keep-lag/--no-keep-lag",
            help="Start each leg the vehicle's lag ahead of it, as the last leg's reference was "
            "(PX4 flies about 0.8 of its velocity setpoint); --no-keep-lag starts every leg at "
            "the odometry.",
        ),
    ] = True,
    lost_link: Annotated[
        float, typer.Option(help="End the mission after this long without telemetry, s.")
    ] = 3.0,
    connect_timeout: Annotated[
        float, typer.Option(help="Wait this long for the autopilot and its position, s.")
    ] = 30.0,
    live: Annotated[
        bool | None,
        typer.Option(
            "--live/--no-live", help="Live view (default: when the console is a terminal)."
        ),
    ] = None,
    fence_action: Annotated[
        int,
        typer.Option(
            help="PX4's GF_ACTION set with a fence: 0 none, 1 warning, 2 hold, 3 return, "
            "4 terminate, 5 land."
        ),
    ] = 2,
    fence_from_vehicle: Annotated[
        bool,
        typer.Option(
            "--fence-from-vehicle",
            help="Fly the fence the vehicle holds (downloaded; the scenario's margin) instead "
            "of uploading the scenario's.",
        ),
    ] = False,
) -> None:
    """Fly SCENARIO on a PX4 vehicle: offboard position setpoints from the mission
    controller, detections as JSON lines over UDP, a safe end in hold (or return)."""
    check_seed(seed)
    _positive(log_max_mb, "--log-max-mb", 0.01, 1e7)
    settings = _controller_settings(deadline, stale_after, keep_lag)
    scenario = load_flight_scenario(scenario_path)
    team = scenario.n_vehicles > 1
    if planner is None:
        planner = "team-mcts" if team else "mcts"
    if planner_entry(planner).reads_truth:
        raise InputError(
            f"--planner {planner}: it reads the true target states, which no flight has; "
            "it runs in hptrack simulate and benchmark only"
        )
    check_team([planner], scenario.n_vehicles)
    connections = team_connections(connection, scenario.n_vehicles)
    if separation is not None and not team:
        raise InputError(f"--separation {separation:g}: the scenario flies one UAV (agent:)")
    planner_settings = flight_planner_settings(planner, option, iterations, time_limit)
    if log_path is None:
        log_path = Path(f"hptrack-flight-{time.strftime('%Y%m%d-%H%M%S')}.jsonl")
    check_output_path(log_path, "--log")

    from hptrack.models.fence import FenceSpec
    from hptrack.runtime.controller import MissionController
    from hptrack.runtime.geofence import fence_block
    from hptrack.runtime.links import bind_check, check_connection
    from hptrack.runtime.log import MissionLog
    from hptrack.runtime.mavsdk_adapter import (
        PILOT_TOOK_OVER,
        FlightError,
        FlightOptions,
        VehicleLimits,
        run_flight,
    )
    from hptrack.runtime.network import udp_address
    from hptrack.runtime.team import DEFAULT_SEPARATION_M, TeamController

    if team:
        from hptrack.runtime.team_flight import run_team_flight
    try:
        options = FlightOptions(
            connection=connections[0],
            detections=detections,
            altitude_m=altitude,
            max_distance_m=max_distance,
            takeoff=takeoff,
            return_to_launch=return_to_launch,
            setpoint_rate_hz=rate,
            lost_link_s=lost_link,
            connect_timeout_s=connect_timeout,
            first_plan_timeout_s=first_plan_timeout,
            log_failure=on_log_failure,
            fence_action=fence_action,
            fence_from_vehicle=fence_from_vehicle,
        )
    except ValueError as err:
        raise InputError(_flag_names(str(err))) from None
    for url in connections:
        check_connection(url)
    bind_check(*udp_address(detections, "--detections"), "--detections", detections)
    use_live = console.is_terminal if live is None else live
    view = Live(console=console, refresh_per_second=4, transient=False) if use_live else None

    def on_status(status: dict) -> None:
        if view is not None:
            view.update(_live_view(status))

    def on_message(text: str) -> None:
        target = view.console if view is not None else console
        target.print(escape(text), highlight=False, soft_wrap=True)  # paths stay whole

    scenario_fence = scenario.fence.spec() if scenario.fence is not None else None

    def build(limits: VehicleLimits, fence: FenceSpec | None) -> MissionController:
        scenario_speed = scenario.vehicle_spec().speed
        speed = planned_speed(scenario_speed, limits, cap_speed)
        on_message(
            f"vehicle limits: {limits.detail}; planning with {speed:g} m/s "
            f"(the scenario's agent speed is {scenario_speed:g} m/s)"
        )
        data = file_data(scenario)
        data["agent"].pop("speed", None)
        data["vehicle"] = {**data.get("vehicle", {}), "speed": speed}
        if fence is not None and fence != scenario_fence:  # the vehicle's
            data["fence"] = fence_block(fence)
        flown = parse_scenario(data, f"{scenario_path} with the vehicle's speed and fence")
        on_message(f"mission log: {log_path}")
        return MissionController(
            flown,
            make_planner(planner, planner_settings),
            seed=seed,
            settings=settings,
            log=log,
            header={
                "source": "fly",
                "flight": options.as_json(),
                "vehicle_limits": limits.__dict__,
                "scenario_agent_speed": scenario_speed,
                "warm_up_s": warm_up_s,
            },
        )

    def build_team(limits: list[VehicleLimits], fence: FenceSpec | None) -> TeamController:
        data = file_data(scenario)
        details = []
        for j, (vehicle_limits, agent) in enumerate(zip(limits, data["agents"], strict=True)):
            scenario_speed = scenario.vehicle_spec(j).speed
            speed = planned_speed(scenario_speed, vehicle_limits, cap_speed)
            details.append(f"vehicle {j}: {vehicle_limits.detail}; planning with {speed:g} m/s")
            agent["speed"] = speed
        if "vehicle" in data:
            data["vehicle"].pop("speed", None)
        for line in details:
            on_message(line)
        if fence is not None and fence != scenario_fence:  # the vehicles'
            data["fence"] = fence_block(fence)
        flown = parse_scenario(data, f"{scenario_path} with the vehicles' speeds and fence")
        on_message(f"mission log: {log_path}")
        return TeamController(
            flown,
            make_planner(planner, planner_settings),
            separation_m=DEFAULT_SEPARATION_M if separation is None else separation,
            seed=seed,
            settings=settings,
            log=log,
            header={
                "source": "fly",
                "flight": options.as_json(),
                "connections": connections,
                "vehicle_limits": [vehicle_limits.__dict__ for vehicle_limits in limits],
                "scenario_agent_speed": [
                    scenario.vehicle_spec(j).speed for j in range(scenario.n_vehicles)
                ],
                "warm_up_s": warm_up_s,
            },
        )

    from hptrack.runtime.warm_up import warm_up_flight

    on_message(
        "compiling or loading every kernel the flight can need before arming (hptrack warm-up "
        "does it ahead)"
    )
    try:
        warm_up_s = warm_up_flight(scenario, planner, planner_settings)
    except KeyboardInterrupt:
        error_console.print("[bold red]error:[/] interrupted before connecting; nothing was flown")
        sys.exit(130)
    on_message(f"kernels ready in {warm_up_s:.1f} s")
    # the file is created at the header, once the vehicle is connected
    log = MissionLog(log_path, max_bytes=round(log_max_mb * 1e6), keep_records=False)
    try:
        if view is not None:
            view.start()
        if team:
            result = run_team_flight(
                build_team, log, options, connections, on_status, on_message, scenario_fence
            )
        else:
            result = run_flight(
                build,
                log,
                options,
                on_status,
                on_message,
                fence=scenario_fence,
            )
    except FlightError as err:
        error_console.print(
            f"[bold red]error:[/] {escape(str(err))}", highlight=False, soft_wrap=True
        )
        sys.exit(EXIT_ABORTED)
    finally:
        if view is not None:
            view.stop()
        log.close()
    end = result.end
    console.print(
        escape(
            f"ended by {result.reason} ({result.detail}); "
            f"{'' if team else 'vehicle '}{result.action}: "
            f"{result.confirmed or 'not confirmed'}; U = {end.get('U', math.nan):.3f} at "
            f"{end.get('time', 0.0):.1f} s; {result.setpoints_sent} setpoints "
            f"({result.setpoint_rate_hz:.1f} Hz, largest gap {result.max_setpoint_gap_s:.2f} s)"
            + _tracking_text(end.get("tracking"))
            + (f"; logging stopped: {result.log_stopped}" if result.log_stopped else "")
            + (
                f"; {sum(result.foreign_odometry.values())} odometry messages refused from "
                f"other MAVLink sources"
                if result.foreign_odometry
                else ""
            )
            + (
                f"; {result.follow_warnings} not-following warnings"
                if result.follow_warnings
                else ""
            )
        ),
        highlight=False,
        soft_wrap=True,
    )
    if result.error:
        error_console.print(escape(result.error), highlight=False, soft_wrap=True)
        sys.exit(1)
    if result.reason == "interrupted":
        sys.exit(130)
    if result.reason == PILOT_TOOK_OVER:
        sys.exit(EXIT_PILOT)
    if result.reason != "budget":
        sys.exit(EXIT_ABORTED)


def _false_alarms_text(count: int) -> str:
    """The false alarms a synthetic detector sent, for its summary line (``""`` for none)."""
    return f", false alarms {count}" if count else ""


def _tracking_text(tracking: dict | None) -> str:
    """Without identity, the tracker's counts for a summary line (``""`` with identity)."""
    if tracking is None:
        return ""
    return (
        f"; {tracking.get('reports', 0)} reports in {tracking.get('looks', 0)} looks, "
        f"{tracking.get('taken by a belief', 0)} taken by a belief, "
        f"{tracking.get('claims', 0)} claimed by a tentative track"
    )


def _separation_text(summary: dict) -> str:
    """A team's separation for a summary line (``""`` for one UAV)."""
    if "separation_m" not in summary:
        return ""
    return (
        f"; separation {summary['separation_m']:g} m: smallest "
        f"{summary['min_separation_m']:.1f} m between vehicles at the ticks, "
        f"{summary['min_reference_separation_m']:.1f} m between references, "
        f"{summary['yields']} yields"
    )


def planned_speed(scenario_speed: float, limits: Any, cap: bool) -> float:
    """The speed to plan with: the scenario's, unless the vehicle's limit (``limits``, a
    `VehicleLimits`) is lower, m/s.

    Raises:
        InputError: the scenario asks for more than the vehicle's limit and ``cap`` is off.
    """
    limit = limits.speed_m_s
    if limit is None or scenario_speed <= limit:
        return scenario_speed
    if not cap:
        raise InputError(
            f"agent.speed {scenario_speed:g} m/s is above the vehicle's MPC_XY_VEL_MAX "
            f"{limit:g} m/s: pass --cap-speed to plan with {limit:g} m/s, or raise "
            "MPC_XY_VEL_MAX on the vehicle"
        )
    return limit


def _parameters(pairs: list[str] | None) -> dict[str, float]:
    from hptrack.runtime.vehicle_sim import PX4_PARAMETERS

    out = {}
    for pair in pairs or []:
        name, sep, text = pair.partition("=")
        if not sep or name not in PX4_PARAMETERS:
            raise InputError(
                f"--param {pair[:60]!r}: expected NAME=VALUE with NAME one of "
                f"{', '.join(PX4_PARAMETERS)}"
            )
        try:
            value = float(text)
        except ValueError:
            raise InputError(f"--param {pair[:60]!r}: {text[:20]!r} is not a number") from None
        _positive(value, f"--param {name}", 0.0, 1e4)
        out[name] = value
    return out


def _misbehaviour_flags(message: str) -> str:
    """A `Misbehaviour` message with its field named as the ``vehicle-sim`` option."""
    field_name = message.split(" ", 1)[0]
    flag = "--" + field_name.removesuffix("_s").removesuffix("_m").replace("_", "-")
    return flag + message[len(field_name) :]


def vehicle_sim(
    scenario_path: Annotated[Path, typer.Argument(metavar="SCENARIO", help="Scenario YAML file.")],
    mavlink: Annotated[str, typer.Option(help="Where MAVSDK listens (loopback).")] = (
        "udpout://127.0.0.1:14540"
    ),
    detections: Annotated[
        str, typer.Option(help="Where to send detections (loopback).")
    ] = "udp://127.0.0.1:5005",
    targets: Annotated[
        bool,
        typer.Option(
            "--targets/--no-targets",
            help="Simulate the scenario's targets here (--no-targets: run hptrack targets-sim "
            "on the --gcs link instead).",
        ),
    ] = True,
    gcs: Annotated[
        str | None,
        typer.Option(help="A second telemetry link, as PX4's ground-station port (loopback)."),
    ] = None,
    param: Annotated[
        list[str] | None,
        typer.Option("--param", help="A PX4 parameter NAME=VALUE other than its default."),
    ] = None,
    seed: Annotated[
        int | None,
        typer.Option(help="Seed of the true targets and the noise (default the scenario's)."),
    ] = None,
    duration: Annotated[
        float | None, typer.Option(help="Stop after this many seconds (default budget + 300 s).")
    ] = None,
    detection_rate: Annotated[
        float | None, typer.Option(help="Sensing per second (default one per time step).")
    ] = None,
    stats: Annotated[
        Path | None,
        typer.Option(
            help="Write what the vehicle saw (setpoints, modes, detections) as JSON at exit."
        ),
    ] = None,
    system_id: Annotated[int, typer.Option(help="Its MAVLink system id (PX4's MAV_SYS_ID).")] = 1,
    instances: Annotated[
        int | None,
        typer.Option(
            help="How many vehicles (default the scenario's UAVs): instance i is UAV i of "
            "agents:, at its position, on the --mavlink port + i with system id --system-id "
            "+ i (PX4's multi-vehicle SITL convention); all send detections to one port and "
            "telemetry to one --gcs port."
        ),
    ] = None,
    refuse_offboard: Annotated[
        str | None,
        typer.Option(
            help="Refuse offboard: deny (the command is denied) or ignore (accepted, the mode "
            "stays)."
        ),
    ] = None,
    leave_offboard_after: Annotated[
        float | None,
        typer.Option(help="Leave offboard this long after entering it (a pilot's switch), s."),
    ] = None,
    leave_offboard_to: Annotated[
        str, typer.Option(help="The mode it then switches to: posctl or hold.")
    ] = "posctl",
    takeoff_failure: Annotated[
        str | None,
        typer.Option(
            help="Fail the take-off: disarm (motors stop), sensors (no position, failsafe "
            "LAND) or posctl (a pilot switches to position mode)."
        ),
    ] = None,
    takeoff_failure_after: Annotated[
        float, typer.Option(help="That long after the take-off began, s.")
    ] = 2.0,
    velocity_tracking: Annotated[
        float | None,
        typer.Option(
            help="The share of its velocity setpoint the vehicle flies (default PX4's SIH "
            "quadrotor's, 0.8; 1 for an ideal velocity loop)."
        ),
    ] = None,
    fence_shift: Annotated[
        float,
        typer.Option(
            help="Keep an uploaded fence moved this far north (a vehicle whose fence is not "
            "the one sent), m."
        ),
    ] = 0.0,
    hold_fence: Annotated[
        bool,
        typer.Option(
            "--hold-fence",
            help="Start holding the scenario's fence, as a vehicle it was uploaded to before "
            "(for fly --fence-from-vehicle).",
        ),
    ] = False,
) -> None:
    """A MAVLink vehicle stub for dry runs: a quadrotor that flies as PX4 does (take-off,
    position loop, speed and acceleration limits, offboard-loss failsafe, parameters, the
    geofence and GF_ACTION) and sends detections of the scenario's simulated targets; it
    prints its mode changes."""
    check_seed(seed)
    scenario = load_flight_scenario(scenario_path, synthetic=True)
    duration = scenario.budget + 300.0 if duration is None else duration
    _positive(duration, "--duration", 0.0, 86400.0)
    if detection_rate is not None:
        _positive(detection_rate, "--detection-rate", 0.0, 1000.0)
    parameters = _parameters(param)
    check_output_path(stats, "--stats")
    m = scenario.n_vehicles if instances is None else instances
    if m != scenario.n_vehicles:
        raise InputError(
            f"--instances {instances}: the scenario flies {scenario.n_vehicles} "
            f"UAV{'s' if scenario.n_vehicles > 1 else ''} (one stub per UAV)"
        )
    if not 1 <= system_id <= 256 - m:
        raise InputError(f"--system-id must be an integer in [1, {256 - m}], got {system_id}")
    from hptrack.runtime.network import udp_address
    from hptrack.runtime.targets import TargetDetector
    from hptrack.runtime.vehicle_sim import PX4_VELOCITY_TRACKING, Misbehaviour, VehicleSim

    mav_host, mav_port = udp_address(mavlink, "--mavlink", loopback_only=True)
    if mav_port + m - 1 > 65535:
        raise InputError(f"--mavlink {mavlink!r}: no room for {m} consecutive ports")

    try:
        misbehaviour = Misbehaviour(
            refuse_offboard=refuse_offboard,
            leave_offboard_after_s=leave_offboard_after,
            leave_offboard_to=leave_offboard_to,
            takeoff_failure=takeoff_failure,
            takeoff_failure_after_s=takeoff_failure_after,
            fence_shift_m=fence_shift,
        )
    except ValueError as err:
        raise InputError(_misbehaviour_flags(str(err))) from None
    if hold_fence and scenario.fence is None:
        raise InputError(f"--hold-fence: {scenario_path} has no fence: block")

    def on_event_of(j: int) -> Any:
        name = "vehicle stub" if m == 1 else f"vehicle stub {j}"

        def on_event(text: str) -> None:
            console.print(escape(f"{name} {text}"), highlight=False)

        return on_event

    shared = TargetDetector(scenario, detections, seed) if targets and m > 1 else None
    urls = [mavlink] if m == 1 else [f"udpout://{mav_host}:{mav_port + j}" for j in range(m)]
    vehicles = [
        VehicleSim(
            scenario,
            url,
            detections if targets else None,
            seed=seed,
            detection_rate_hz=detection_rate,
            gcs_url=gcs,
            parameters=parameters,
            on_event=on_event_of(j),
            system_id=system_id + j,
            misbehaviour=misbehaviour,
            velocity_tracking=(
                PX4_VELOCITY_TRACKING if velocity_tracking is None else velocity_tracking
            ),
            instance=j,
            detector=shared,
        )
        for j, url in enumerate(urls)
    ]
    if hold_fence and scenario.fence is not None:
        for vehicle in vehicles:
            vehicle.hold_fence(scenario.fence.spec())
    stop = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }
    links = (
        mavlink if m == 1 else f"{urls[0]} .. {urls[-1]} (systems {system_id}..{system_id + m - 1})"
    )
    console.print(
        escape(
            f"vehicle stub{'s' if m > 1 else ''}: MAVLink to {links}"
            f"{f' and {gcs}' if gcs else ''}, "
            f"{f'detections to {detections}' if targets else 'no targets'}; "
            f"running for at most {duration:g} s (Ctrl-C stops)"
        ),
        highlight=False,
    )
    summaries: list[dict] = [{} for _ in vehicles]

    def run(j: int) -> None:
        summaries[j] = vehicles[j].run(duration, stop)

    try:
        if m == 1:
            run(0)
        else:
            threads = [threading.Thread(target=run, args=(j,), daemon=True) for j in range(m)]
            for thread in threads:
                thread.start()
            while any(thread.is_alive() for thread in threads):
                for thread in threads:
                    thread.join(0.2)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if shared is not None:
            shared.close()
    if stats is not None:
        write_json(stats, summaries[0] if m == 1 else {"instances": summaries})
    for j, summary in enumerate(summaries):
        detections_sent = summary["detections_sent"]
        if shared is not None:  # the team's detector: its counts are the team's
            detections_sent = shared.stats.detections if j == 0 else {}
        console.print(
            escape(
                f"vehicle stub{'' if m == 1 else f' {j}'} stopped in "
                f"{summary['final_mode'].upper()}: {summary['setpoints']} "
                f"setpoints ({summary['offboard_setpoint_rate_hz']:.1f} Hz in offboard), "
                f"detections sent {json.dumps(detections_sent)}"
                + _false_alarms_text(summary["false_alarms_sent"])
            ),
            highlight=False,
        )


def targets_sim(
    scenario_path: Annotated[Path, typer.Argument(metavar="SCENARIO", help="Scenario YAML file.")],
    mavlink: Annotated[
        str,
        typer.Option(
            help="Where the autopilot's telemetry arrives (PX4's ground-station port 14550)."
        ),
    ] = "udpin://127.0.0.1:14550",
    detections: Annotated[
        str, typer.Option(help="Where hptrack fly reads detections.")
    ] = "udp://127.0.0.1:5005",
    seed: Annotated[
        int | None,
        typer.Option(help="Seed of the true targets and the noise (default the scenario's)."),
    ] = None,
    duration: Annotated[
        float | None, typer.Option(help="Stop after this many seconds (default budget + 600 s).")
    ] = None,
    detection_rate: Annotated[
        float | None, typer.Option(help="Sensing per second (default one per time step).")
    ] = None,
    stats: Annotated[
        Path | None, typer.Option(help="Write what was seen and sent as JSON at exit.")
    ] = None,
    system_id: Annotated[
        int,
        typer.Option(
            help="A team's first MAVLink system id: UAV i of agents: is system --system-id + i "
            "(PX4's multi-vehicle SITL numbers instance i MAV_SYS_ID i + 1)."
        ),
    ] = 1,
) -> None:
    """Simulated targets and a footprint detector for any autopilot in software-in-the-loop:
    reads the vehicle's position from its MAVLink telemetry, starts the targets when it enters
    offboard, and sends detections to hptrack fly."""
    check_seed(seed)
    scenario = load_flight_scenario(scenario_path, synthetic=True)
    duration = scenario.budget + 600.0 if duration is None else duration
    _positive(duration, "--duration", 0.0, 86400.0)
    rate = 1.0 / scenario.time_step if detection_rate is None else detection_rate
    _positive(rate, "--detection-rate", 0.0, 1000.0)
    check_output_path(stats, "--stats")
    m = scenario.n_vehicles
    if not 1 <= system_id <= 256 - m:
        raise InputError(f"--system-id must be an integer in [1, {256 - m}], got {system_id}")
    team_ids = None if m == 1 else tuple(range(system_id, system_id + m))
    from hptrack.runtime.links import bind_check
    from hptrack.runtime.network import udp_address
    from hptrack.runtime.targets import TargetDetector, run_targets_sim

    bind_check(*udp_address(mavlink, "--mavlink"), "--mavlink", mavlink)
    detector = TargetDetector(scenario, detections, seed)
    stop = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }

    def on_event(text: str) -> None:
        console.print(escape(f"targets-sim: {text}"), highlight=False)

    on_event(
        f"listening to {mavlink}"
        + ("" if team_ids is None else f" for systems {team_ids[0]}..{team_ids[-1]}")
        + f", detections to {detections}, {rate:g} per second; "
        f"at most {duration:g} s (Ctrl-C stops)"
    )
    try:
        summary = run_targets_sim(
            detector, mavlink, duration, rate, stop, on_event=on_event, team_system_ids=team_ids
        )
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if stats is not None:
        write_json(stats, summary)
    on_event(
        f"stopped: {summary['heartbeats']} heartbeats, {summary['positions']} positions, "
        f"detections sent {json.dumps(summary['detections_sent'])}"
        + _false_alarms_text(summary["false_alarms_sent"])
    )


def replay(
    log_path: Annotated[Path, typer.Argument(metavar="LOG", help="Mission log (JSON lines).")],
    plot: Annotated[
        Path | None, typer.Option(help="Mission figure (PNG); default LOG with .png.")
    ] = None,
    json_path: Annotated[
        Path | None, typer.Option("--json", help="JSON summary; default LOG with .summary.json.")
    ] = None,
) -> None:
    """Re-run the controller on a mission log: the same events give the same beliefs and
    decisions; writes the mission figure and a JSON summary."""
    plot = plot or log_path.with_suffix(".png")
    json_path = json_path or log_path.with_suffix(".summary.json")
    check_output_path(plot, "--plot")
    check_output_path(json_path, "--json")
    from hptrack.runtime.replay import replay_log
    from hptrack.viz.mission import save_mission_figure

    result = replay_log(log_path)
    summary = result.summary
    write_json(json_path, summary)
    if summary["never_started"] is not None:
        console.print(
            escape(
                f"{log_path}: the mission never started ({summary['never_started']}); "
                f"{summary['records']} records, nothing flown to replay; summary {json_path}"
            ),
            highlight=False,
            soft_wrap=True,
        )
        return
    save_mission_figure(result.record, str(plot))
    table = Table(
        title=escape(
            f"replay of {log_path} ({summary['source']}, "
            f"{summary['planner']}, seed {summary['seed']})"
        )
    )
    table.add_column("target")
    table.add_column("final log det Σxy", justify="right")
    table.add_column("detections (ticks)", justify="right")
    for tid, value in summary["per_target_logdet"].items():
        table.add_row(escape(tid), f"{value:.3f}", str(summary["detections"][tid]))
    table.add_section()
    table.add_row("U", f"{summary['U']:.3f}", "")
    console.print(table)
    logged = summary["logged_U"]
    console.print(
        escape(
            f"{summary['records']} records"
            f"{' (last line truncated)' if summary['truncated'] else ''}"
            f", {summary['ticks']} ticks, {summary['plans']} plans; ended by "
            f"{summary['ended_by']} at {summary['time']:.1f} s; logged U "
            f"{'-' if logged is None else format(logged, '.3f')}; "
            f"{summary['mismatches']} mismatches"
            + _tracking_text(summary.get("tracking"))
            + _separation_text(summary)
            + (
                "; decisions taken from the log (it names a model file, which a replay never loads)"
                if summary["decisions"] == "logged"
                else ""
            )
        ),
        highlight=False,
    )
    for line in summary["first_mismatches"]:
        console.print(escape(f"  {line}"), highlight=False)
    console.print(f"figure {escape(str(plot))}, summary {escape(str(json_path))}")


def register(app: typer.Typer) -> None:
    """Add ``fly``, ``vehicle-sim``, ``targets-sim`` and ``replay`` to ``app``."""
    app.command("fly")(fly)
    app.command("vehicle-sim")(vehicle_sim)
    app.command("targets-sim")(targets_sim)
    app.command("replay")(replay)
