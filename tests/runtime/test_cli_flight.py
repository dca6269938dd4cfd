"""``hptrack fly``, ``vehicle-sim`` and ``replay`` on the command line: bad input is one line and
exit code 2; a vehicle that never answers is exit code 3."""

import json
import socket

import pytest

from hptrack.registry import make_planner
from hptrack.runtime.log import MissionLog
from hptrack.runtime.simulated import SimulatedFaults, run_simulated


@pytest.fixture
def flight_cli(cli):
    """The ``cli`` fixture with the flight commands registered."""
    from hptrack.cli import app as app_module
    from hptrack.cli.flight import register

    if "fly" not in {command.name for command in app_module.app.registered_commands}:
        register(app_module.app)
    return cli


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
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(flight_cli, example_path, tmp_path, args, message):
    args = [a.format(scenario=example_path) for a in args]
    result = flight_cli(*args, *(["--log", tmp_path / "l.jsonl"] if args[0] == "fly" else []))
    assert result.code == 2, result.out + result.err
    assert len(result.error_lines) == 1 and message in result.err, result.err


def test_fly_without_a_vehicle_gives_up_with_exit_code_3(flight_cli, example_path, tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    result = flight_cli(
        "fly",
        example_path,
        "--connection",
        f"udpin://127.0.0.1:{port}",
        "--detections",
        f"udp://127.0.0.1:{port}",
        "--connect-timeout",
        "1",
        "--log",
        tmp_path / "l.jsonl",
        "--no-live",
    )
    assert result.code == 3, result.out + result.err
    assert "no autopilot found" in result.err
