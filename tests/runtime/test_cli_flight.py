"""``hptrack fly``, ``vehicle-sim`` and ``replay`` on the command line: bad input is one line and
exit code 2; a vehicle that never answers is exit code 3."""

import json
import socket

import pytest

from hptrack.registry import make_planner
from hptrack.runtime.log import MissionLog
from hptrack.runtime.simulated import SimulatedFaults, run_simulated


def test_replay_writes_the_figure_and_the_summary(flight_cli, flight_scenario, tmp_path):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    run = run_simulated(
        flight_scenario,
        make_planner("greedy"),
        seed=1,
        log=log,
        faults=SimulatedFaults(detection_latency_s=0.2, bad_input_rate_hz=1.0),
    )
    log.close()
    result = flight_cli("replay", path)
    assert result.code == 0, result.err
    out = " ".join(result.out.split())
    assert "0 mismatches" in out and "ended by budget" in out
    summary = json.loads(path.with_suffix(".summary.json").read_text())
    assert summary["U"] == run.uncertainty and summary["source"] == "simulated"
    assert sum(summary["rejected"].values()) > 0
    assert path.with_suffix(".png").read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["replay", "{scenario}"], "not a mission log"),
        (["vehicle-sim", "{scenario}", "--mavlink", "udpout://10.1.2.3:14540"], "loopback"),
        (["vehicle-sim", "{scenario}", "--detections", "udp://127.0.0.1:99999"], "1-65535"),
        (["fly", "{scenario}", "--altitude", "-5"], "--altitude"),
        (["fly", "{scenario}", "--rate", "5"], "--rate"),
        (["fly", "{scenario}", "--deadline", "0"], "--deadline"),
        (["fly", "{scenario}", "--planner", "nope"], "unknown planner"),
        (["fly", "{scenario}", "--planner", "clairvoyant"], "reads the true target states"),
        (["fly", "{scenario}", "--detections", "tcp://x:1"], "--detections"),
        (["fly", "{scenario}", "--connection", "bogus"], "--connection 'bogus': expected"),
        (["fly", "{scenario}", "--connection", "udpin://0.0.0.0:99999"], "port 1-65535"),
        (
            ["fly", "{scenario}", "--connection", "serial:///dev/ttyNOPE0:57600"],
            "no serial device /dev/ttyNOPE0",
        ),
        (["fly", "{scenario}", "--connection", "udpin://{busy}"], "the port is in use"),
        (["fly", "{scenario}", "--connection", "udpin://10.254.254.1:14540"], "cannot receive"),
        (["fly", "{scenario}", "--detections", "udp://{busy}"], "the port is in use"),
        (["fly", "{scenario}", "--detections", "udp://10.254.254.1:5005"], "cannot receive"),
        (["fly", "{scenario}", "--first-plan-timeout", "0"], "--first-plan-timeout"),
        (["fly", "{scenario}", "--on-log-failure", "panic"], "--on-log-failure 'panic'"),
        (["fly", "{scenario}", "--log-max-mb", "0"], "--log-max-mb"),
        (["vehicle-sim", "{scenario}", "--param", "NOPE=1"], "--param 'NOPE=1'"),
        (["vehicle-sim", "{scenario}", "--gcs", "udpout://10.1.2.3:14550"], "loopback"),
        (["vehicle-sim", "{scenario}", "--system-id", "0"], "--system-id must be an integer"),
        (
            ["vehicle-sim", "{scenario}", "--refuse-offboard", "maybe"],
            "--refuse-offboard 'maybe': expected one of deny, ignore",
        ),
        (
            ["vehicle-sim", "{scenario}", "--leave-offboard-after", "-1"],
            "--leave-offboard-after must be a number in (0, 86400]",
        ),
        (
            ["vehicle-sim", "{scenario}", "--takeoff-failure", "fire"],
            "--takeoff-failure 'fire': expected one of disarm, sensors, posctl",
        ),
        (["targets-sim", "{scenario}", "--mavlink", "udpin://{busy}"], "the port is in use"),
        (["fly", "{scenario}", "--fence-action", "6"], "--fence-action 6: expected one of 0..5"),
        (["vehicle-sim", "{scenario}", "--hold-fence"], "has no fence: block"),
        (
            ["vehicle-sim", "{scenario}", "--fence-shift", "1e5"],
            "--fence-shift must be a number in [-1e4, 1e4], got 100000.0",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(flight_cli, example_path, tmp_path, args, message):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as busy:
        busy.bind(("127.0.0.1", 0))
        address = f"127.0.0.1:{busy.getsockname()[1]}"
        args = [a.format(scenario=example_path, busy=address) for a in args]
        result = flight_cli(*args, *(["--log", tmp_path / "l.jsonl"] if args[0] == "fly" else []))
    assert result.code == 2, result.out + result.err
    assert len(result.error_lines) == 1 and message in result.err, result.err


def test_fly_without_a_vehicle_says_what_it_waits_for_then_gives_a_hint_and_no_log(
    flight_cli, example_path, tmp_path
):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    log = tmp_path / "l.jsonl"
    result = flight_cli(
        "fly",
        example_path,
        "--connection",
        f"udpin://127.0.0.1:{port}",
        "--detections",
        f"udp://127.0.0.1:{port}",
        "--connect-timeout",
        "2",
        "--log",
        log,
        "--no-live",
    )
    assert result.code == 3, result.out + result.err
    out = " ".join(result.out.split())
    waiting = f"waiting for an autopilot on udpin://127.0.0.1:{port} (at most 2 s; Ctrl-C stops)"
    # first the kernels (the vehicle waits on the ground), then at once where it waits
    assert out.startswith("compiling or loading every kernel the flight can need before arming")
    ready = out.index("kernels ready in")
    assert out[ready:].split(" s ", 1)[1].startswith(waiting)
    assert "still waiting for an autopilot" in out
    err = " ".join(result.err.split())
    assert f"no autopilot found on udpin://127.0.0.1:{port} within 2 s" in err
    assert "hptrack vehicle-sim SCENARIO" in err and "PX4 SITL" in err
    assert not log.exists()  # no empty log left behind


def test_fly_re_admits_missed_targets_unless_told_otherwise_or_flying_the_paper(monkeypatch):
    from hptrack.cli.flight import FLY_ITERATIONS, flight_planner_settings
    from hptrack.planning import hierarchical

    monkeypatch.setattr(hierarchical, "DEFAULT_PRESET", "revisit")  # fly keeps its own preset
    flown = flight_planner_settings("mcts", None, None, None)
    assert flown.readmit is True and flown.iterations == FLY_ITERATIONS
    assert flown.preset == "improved" and flown.miss == "drop" and flown.rollout == "uniform"
    revisit = flight_planner_settings("mcts", ["preset=revisit"], None, None)
    assert (revisit.rollout, revisit.readmit, revisit.iterations) == ("tour_plan", True, 2000)
    team = flight_planner_settings("team-mcts", None, None, None)
    assert (team.preset, team.readmit) == ("improved", True)
    assert flight_planner_settings("mcts", ["readmit=false"], None, None).readmit is False
    assert flight_planner_settings("mcts", ["mcts.readmit=false"], None, None).readmit is False
    paper = flight_planner_settings("mcts", ["preset=paper"], 500, None)
    assert paper.readmit is False and paper.iterations == 500
    assert not hasattr(flight_planner_settings("greedy", None, None, None), "readmit")


def test_the_planned_speed_is_the_vehicles_limit_only_when_asked():
    from hptrack.cli.flight import planned_speed
    from hptrack.interface import InputError
    from hptrack.runtime.mavsdk_adapter import VehicleLimits

    px4 = VehicleLimits(12.0, 3.0, "MPC_XY_VEL_MAX 12 m/s")
    assert planned_speed(8.0, px4, cap=False) == 8.0
    assert planned_speed(30.0, px4, cap=True) == 12.0
    with pytest.raises(InputError, match=r"agent.speed 30 m/s is above .* 12 m/s: pass --cap"):
        planned_speed(30.0, px4, cap=False)
    assert planned_speed(30.0, VehicleLimits(None, None, "not PX4"), cap=False) == 30.0


def test_plain_errors_say_what_happened_what_the_vehicle_does_and_what_to_do():
    pytest.importorskip("mavsdk")
    from mavsdk.asyncio.plugins.offboard import OffboardError, OffboardResult

    from hptrack.runtime.mavsdk_adapter import plain_error

    text = plain_error(
        OffboardError(OffboardResult.TIMEOUT, "hold()"), "switching to hold", "it last said X"
    )
    assert text == (
        "switching to hold failed: the vehicle did not answer (the link may be lost); it last "
        "said X; check the link and watch the vehicle with a ground station; PX4 leaves "
        "offboard by itself after COM_OF_LOSS_T (1 s by default) and applies its offboard-loss "
        "failsafe."
    )
    assert "\n" not in text and "origin" not in text


def test_the_live_view_shows_dropped_detection_lines():
    from rich.console import Console

    from hptrack.cli.flight import _live_view

    status = {
        "t": 12.0,
        "budget": 60.0,
        "plan": None,
        "target_ids": ("p1",),
        "rejected": {"detection: malformed": 3},
        "dropped_lines": 4200,
        "logdet": {"p1": 1.5},
    }
    console = Console(width=200, record=True)
    console.print(_live_view(status))
    text = console.export_text()
    assert "detection: malformed 3; 4200 detection lines dropped" in text
    console = Console(width=200, record=True)
    console.print(_live_view({**status, "dropped_lines": 0}))
    assert "dropped" not in console.export_text()


def test_the_live_view_shows_the_fence():
    from rich.console import Console

    from hptrack.cli.flight import _live_view

    status = {
        "t": 12.0,
        "budget": 60.0,
        "plan": None,
        "target_ids": ("p1",),
        "fence": {"margin_m": 5.0, "vehicle_free": False, "projections": 3},
    }
    console = Console(width=200, record=True)
    console.print(_live_view(status))
    assert "margin 5 m; vehicle in the margin; 3 setpoints projected inside" in (
        console.export_text()
    )
    console = Console(width=200, record=True)
    console.print(_live_view({**status, "fence": None}))
    assert "margin" not in console.export_text()


@pytest.mark.slow  # a process of its own: its imports take most of its 10-20 s
def test_ctrl_c_ends_the_wait_for_the_autopilot_at_once(example_path, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    fly = subprocess.Popen(
        [
            *(sys.executable, "-m", "hptrack", "fly", str(example_path)),
            *("--connection", f"udpin://127.0.0.1:{port}", "--detections"),
            *(f"udp://127.0.0.1:{port}", "--connect-timeout", "120", "--no-live"),
            *("--log", str(tmp_path / "l.jsonl")),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines = [fly.stdout.readline() for _ in range(3)]  # the kernels, then where it waits
        assert lines[1].startswith("kernels ready in")
        assert lines[2].startswith(f"waiting for an autopilot on udpin://127.0.0.1:{port}")
        asked = time.monotonic()
        fly.send_signal(signal.SIGINT)
        out, err = fly.communicate(timeout=30)
        stopped_after_s = time.monotonic() - asked
    finally:
        if fly.poll() is None:
            fly.kill()
            fly.wait()
    assert fly.returncode == 3, out + err
    assert "interrupted while waiting for the autopilot" in err
    assert stopped_after_s < 4.0  # not the 5 s between progress lines, nor the 120 s timeout


@pytest.mark.parametrize("abort", [True, False])
def test_replay_says_a_flight_that_never_started_never_started(
    flight_cli, flight_scenario, tmp_path, abort
):
    """A ``fly`` log that ends before offboard (a failed take-off) replays to one line that
    says so and why, with no U and no figure."""
    from hptrack.runtime.controller import MissionController
    from hptrack.runtime.worker import InlineRunner

    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    controller = MissionController(
        flight_scenario,
        make_planner("greedy"),
        seed=1,
        log=log,
        runner=InlineRunner(),
        header={"source": "fly"},
    )
    controller.prepare([0.0, 0.0])
    log.write({"kind": "status", "t": None, "message": "taking off to 20 m"})
    if abort:
        log.write(
            {
                "kind": "abort",
                "t": None,
                "reason": "take-off failed",
                "detail": "the take-off failed: the vehicle disarmed at 3.1 m of 20 m",
            }
        )
    controller.close()
    log.close()
    result = flight_cli("replay", path)
    assert result.code == 0, result.err
    out = " ".join(result.out.split())
    why = (
        "the take-off failed: the vehicle disarmed at 3.1 m of 20 m"
        if abort
        else "the log ends before offboard started"
    )
    assert f"the mission never started ({why})" in out
    assert "ended by" not in out and "logged U" not in out
    summary = json.loads(path.with_suffix(".summary.json").read_text())
    assert summary["never_started"] == why and summary["U"] is None
    assert summary["ended_by"] is None and not path.with_suffix(".png").exists()
