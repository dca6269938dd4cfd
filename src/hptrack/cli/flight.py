"""``hptrack fly``, ``hptrack vehicle-sim`` and ``hptrack replay``: a mission on a PX4 vehicle
through MAVSDK, a MAVLink vehicle stub for dry runs, and the replay of a mission log.

Also runnable as ``python3 -m hptrack.cli.flight COMMAND ...``.
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
    planner_settings_for,
    write_json,
)
from hptrack.interface import InputError
from hptrack.registry import PLANNERS, make_planner, planner_entry
from hptrack.scenario import load_scenario
from hptrack.scenario.io import format_validation_error

FLY_ITERATIONS = 2000
"""Tree-search simulations per decision in ``fly`` when neither effort flag is given (a
re-plan takes well under the default 1 s deadline on a 2-core machine, and a replay repeats
it exactly)."""

EXIT_ABORTED = 3
"""Exit code of a flight that could not start or ended early for safety."""


def _controller_settings(deadline: float, stale_after: float) -> Any:
    from hptrack.runtime.controller import ControllerSettings

    try:
        return ControllerSettings(planner_deadline_s=deadline, stale_odometry_s=stale_after)
    except ValidationError as err:
        message = format_validation_error(err).replace("planner_deadline_s", "--deadline")
        raise InputError(message.replace("stale_odometry_s", "--stale-after")) from None


def _positive(value: float, option: str, low: float = 0.0, high: float = math.inf) -> None:
    if not (math.isfinite(value) and low < value <= high):
        raise InputError(f"{option} must be a number in ({low:g}, {high:g}], got {value}")


def _subtask_text(subtask: dict | None) -> str:
    if not subtask:
        return "-"
    if "follow" in subtask:
        return f"follow {subtask['follow']} (since step {subtask.get('since_step')})"
    if "dwell" in subtask:
        return f"dwell on {subtask['dwell']} (since step {subtask.get('since_step')})"
    p_find = subtask.get("p_find")
    extra = f", p_find {p_find:.2f}" if isinstance(p_find, float) else ""
    return f"pursue {subtask['target']} (since step {subtask.get('since_step')}{extra})"


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
    head.add_row("sub-task", escape(_subtask_text(status.get("subtask"))))
    last = status.get("last_detection")
    head.add_row(
        "last detection",
        "-"
        if not last
        else escape(f"{last['target']} at {last['t']:.1f} s ({status['t'] - last['t']:.1f} s ago)"),
    )
    head.add_row(
        "from home",
        f"{status.get('distance_from_home_m', 0):.0f} m at "
        f"{status.get('altitude_m', 0):.0f} m altitude",
    )
    rejected = status.get("rejected") or {}
    head.add_row(
        "refused inputs", escape(", ".join(f"{k} {v}" for k, v in rejected.items()) or "none")
    )
    targets = Table(show_edge=False)
    targets.add_column("target")
    targets.add_column("log det Σxy", justify="right")
    for tid, value in (status.get("logdet") or {}).items():
        targets.add_row(escape(tid), f"{value:.2f}")
    return Group(head, targets)


def fly(
    scenario_path: Annotated[Path, typer.Argument(metavar="SCENARIO", help="Scenario YAML file.")],
    connection: Annotated[str, typer.Option(help="MAVSDK connection URL of the vehicle.")] = (
        "udpin://0.0.0.0:14540"
    ),
    detections: Annotated[
        str, typer.Option(help="UDP address where detections arrive as JSON lines.")
    ] = "udp://127.0.0.1:5005",
    altitude: Annotated[
        float, typer.Option(help="Mission altitude above the local origin, m.")
    ] = 30.0,
    log_path: Annotated[
        Path | None,
        typer.Option("--log", help="Mission log (JSON lines); default hptrack-flight-TIME.jsonl."),
    ] = None,
    max_distance: Annotated[
        float, typer.Option(help="A setpoint farther than this from home ends the mission, m.")
    ] = 1000.0,
    planner: Annotated[
        str,
        typer.Option(
            help="One of: "
            + ", ".join(name for name, entry in PLANNERS.items() if not entry.reads_truth)
            + "."
        ),
    ] = "mcts",
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
) -> None:
    """Fly SCENARIO on a PX4 vehicle: offboard position setpoints from the mission
    controller, detections as JSON lines over UDP, a safe end in hold (or return)."""
    check_seed(seed)
    _positive(altitude, "--altitude", 0.0, 1e4)
    _positive(max_distance, "--max-distance", 0.0, 1e6)
    if not (math.isfinite(rate) and 10.0 <= rate <= 1000.0):
        raise InputError(f"--rate must be 10 to 1000 setpoints per second, got {rate}")
    _positive(lost_link, "--lost-link", 0.0, 600.0)
    _positive(connect_timeout, "--connect-timeout", 0.0, 3600.0)
    settings = _controller_settings(deadline, stale_after)
    if planner_entry(planner).reads_truth:
        raise InputError(
            f"--planner {planner}: it reads the true target states, which no flight has; "
            "it runs in hptrack simulate and benchmark only"
        )
    scenario = load_scenario(scenario_path)
    if iterations is None and time_limit is None and planner == "mcts":
        iterations = FLY_ITERATIONS
    planner_settings = planner_settings_for((planner,), option, iterations, time_limit)[planner]
    if log_path is None:
        log_path = Path(f"hptrack-flight-{time.strftime('%Y%m%d-%H%M%S')}.jsonl")
    check_output_path(log_path, "--log")

    from hptrack.runtime.controller import MissionController
    from hptrack.runtime.log import MissionLog
    from hptrack.runtime.mavsdk_adapter import FlightError, FlightOptions, run_flight
    from hptrack.runtime.network import udp_address

    udp_address(detections, "--detections")
    options = FlightOptions(
        connection=connection,
        detections=detections,
        altitude_m=altitude,
        max_distance_m=max_distance,
        takeoff=takeoff,
        return_to_launch=return_to_launch,
        setpoint_rate_hz=rate,
        lost_link_s=lost_link,
        connect_timeout_s=connect_timeout,
    )
    log = MissionLog(log_path)
    controller = MissionController(
        scenario,
        make_planner(planner, planner_settings),
        seed=seed,
        settings=settings,
        log=log,
        header={"source": "fly", "flight": options.__dict__},
    )
    use_live = console.is_terminal if live is None else live
    view = Live(console=console, refresh_per_second=4, transient=False) if use_live else None

    def on_status(status: dict) -> None:
        if view is not None:
            view.update(_live_view(status))

    def on_message(text: str) -> None:
        (view.console if view is not None else console).print(escape(text), highlight=False)

    console.print(f"mission log: {escape(str(log_path))}")
    try:
        if view is not None:
            view.start()
        result = run_flight(controller, options, on_status, on_message)
    except FlightError as err:
        error_console.print(f"[bold red]error:[/] {escape(str(err))}", highlight=False)
        sys.exit(EXIT_ABORTED)
    finally:
        if view is not None:
            view.stop()
        log.close()
    end = result.end
    console.print(
        escape(
            f"ended by {result.reason} ({result.detail}); vehicle {result.action}: "
            f"{result.confirmed or 'not confirmed'}; U = {end.get('U', math.nan):.3f} at "
            f"{end.get('time', 0.0):.1f} s; {result.setpoints_sent} setpoints "
            f"({result.setpoint_rate_hz:.1f} Hz)"
        ),
        highlight=False,
    )
    if result.error:
        error_console.print(escape(result.error), highlight=False)
        sys.exit(1)
    if result.reason == "interrupted":
        sys.exit(130)
    if result.reason != "budget":
        sys.exit(EXIT_ABORTED)


def vehicle_sim(
    scenario_path: Annotated[Path, typer.Argument(metavar="SCENARIO", help="Scenario YAML file.")],
    mavlink: Annotated[str, typer.Option(help="Where MAVSDK listens (loopback).")] = (
        "udpout://127.0.0.1:14540"
    ),
    detections: Annotated[
        str, typer.Option(help="Where to send detections (loopback).")
    ] = "udp://127.0.0.1:5005",
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
) -> None:
    """A MAVLink vehicle stub for dry runs: a PX4-like quadrotor that flies the offboard
    setpoints and sends detections of the scenario's simulated targets."""
    check_seed(seed)
    scenario = load_scenario(scenario_path)
    duration = scenario.budget + 300.0 if duration is None else duration
    _positive(duration, "--duration", 0.0, 86400.0)
    if detection_rate is not None:
        _positive(detection_rate, "--detection-rate", 0.0, 1000.0)
    check_output_path(stats, "--stats")
    from hptrack.runtime.vehicle_sim import VehicleSim

    vehicle = VehicleSim(scenario, mavlink, detections, seed=seed, detection_rate_hz=detection_rate)
    stop = threading.Event()
    previous = {
        sig: signal.signal(sig, lambda *_: stop.set()) for sig in (signal.SIGINT, signal.SIGTERM)
    }
    console.print(
        escape(
            f"vehicle stub: MAVLink to {mavlink}, detections to {detections}; "
            f"running for at most {duration:g} s (Ctrl-C stops)"
        ),
        highlight=False,
    )
    try:
        summary = vehicle.run(duration, stop)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    if stats is not None:
        write_json(stats, summary)
    console.print(
        escape(
            f"vehicle stub stopped in {summary['final_mode']}: {summary['setpoints']} setpoints "
            f"({summary['offboard_setpoint_rate_hz']:.1f} Hz in offboard), detections sent "
            f"{json.dumps(summary['detections_sent'])}"
        ),
        highlight=False,
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
        ),
        highlight=False,
    )
    for line in summary["first_mismatches"]:
        console.print(escape(f"  {line}"), highlight=False)
    console.print(f"figure {escape(str(plot))}, summary {escape(str(json_path))}")


def register(app: typer.Typer) -> None:
    """Add ``fly``, ``vehicle-sim`` and ``replay`` to ``app``."""
    app.command("fly")(fly)
    app.command("vehicle-sim")(vehicle_sim)
    app.command("replay")(replay)


def main() -> None:
    """``python3 -m hptrack.cli.flight``: the main CLI, with these commands registered."""
    from hptrack.cli import app as app_module

    names = {command.name for command in app_module.app.registered_commands}
    if "fly" not in names:
        register(app_module.app)
    app_module.main()


if __name__ == "__main__":
    main()
