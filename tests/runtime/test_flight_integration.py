"""``hptrack fly`` against ``hptrack vehicle-sim`` (the PX4-like stub): two processes talking
MAVLink through MAVSDK on loopback, a real-time mission with its first plan before offboard and
the planned speed flown, its safe ends, the replay of its log, and ``hptrack targets-sim`` fed by
the stub's second telemetry link."""

import json
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
import yaml

pytest.importorskip("mavsdk")
pytest.importorskip("pymavlink")

from hptrack.runtime.log import read_log  # noqa: E402
from hptrack.scenario import load_scenario  # noqa: E402

pytestmark = pytest.mark.slow

BUDGET_S = 15.0
LONG_BUDGET_S = 30.0
"""Long enough for straight legs at full speed (a first plan that stalled would show)."""
CLI = [sys.executable, "-m", "hptrack.cli.flight"]


def _free_udp_port():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _start_dry_run(tmp_path, example_path, budget, stub_args=()):
    """A copy of the paper-flight example with ``budget``, free ports, and the vehicle stub
    running."""
    data = yaml.safe_load(example_path.read_text())
    data["budget"] = budget
    scenario = tmp_path / "flight.yaml"
    scenario.write_text(yaml.safe_dump(data))
    mav, det = _free_udp_port(), _free_udp_port()
    stats = tmp_path / "vehicle.json"
    stub = subprocess.Popen(
        [
            *CLI,
            "vehicle-sim",
            str(scenario),
            "--mavlink",
            f"udpout://127.0.0.1:{mav}",
            "--detections",
            f"udp://127.0.0.1:{det}",
            "--duration",
            "150",
            "--stats",
            str(stats),
            *stub_args,
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    fly = [
        *CLI,
        "fly",
        str(scenario),
        "--connection",
        f"udpin://127.0.0.1:{mav}",
        "--detections",
        f"udp://127.0.0.1:{det}",
        "--altitude",
        "5",
        "--takeoff",
        "--no-live",
        "--connect-timeout",
        "20",
    ]
    return {
        "scenario": scenario,
        "fly": fly,
        "stub": stub,
        "stats": stats,
        "log": tmp_path / "flight.jsonl",
        "detections_port": det,
    }


def _end(process):
    """Stop ``process`` if it runs and close its pipes."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()


@pytest.fixture
def dry_run(tmp_path, example_path):
    """A short copy of the paper-flight example, free ports, and the vehicle stub running."""
    run = _start_dry_run(tmp_path, example_path, BUDGET_S)
    yield run
    _end(run["stub"])


@pytest.fixture
def long_dry_run(tmp_path, example_path):
    """The same with a budget long enough for straight legs."""
    run = _start_dry_run(tmp_path, example_path, LONG_BUDGET_S)
    yield run
    _end(run["stub"])


def _stop_stub(run):
    run["stub"].send_signal(signal.SIGINT)
    out, err = run["stub"].communicate(timeout=10)
    assert run["stub"].returncode == 0, err
    stats = json.loads(run["stats"].read_text())
    stats["stdout"] = out
    return stats


def _records(path, kind):
    return [r for r in read_log(path).records if r["kind"] == kind]


def _straight_leg_speeds(records, min_run_s=3.0, heading_tolerance_deg=3.0):
    """``(planned, flown)`` speeds (m/s) between consecutive plans that continue a straight run
    of at least ``min_run_s`` at full planned speed (the leg at least one step long, its heading
    within the tolerance of the run's), flown speed from the odometry."""
    odometry = np.array(
        [[r["t"], *r["position"]] for r in records if r["kind"] == "odometry" and r["accepted"]]
    )
    ticks = {r["k"]: r for r in records if r["kind"] == "tick"}
    plans = [r for r in records if r["kind"] == "plan" and r["status"] == "ok"]
    out = []
    run_start, run_heading = None, None
    for plan, following in zip(plans, plans[1:], strict=False):
        leg = np.asarray(plan["waypoint"]) - np.asarray(ticks[plan["k"]]["agent"])
        heading = np.degrees(np.arctan2(leg[1], leg[0]))
        full = np.hypot(*leg) >= plan["speed_m_s"] * 0.5
        if not full or run_heading is None or abs(heading - run_heading) > heading_tolerance_deg:
            run_start, run_heading = (plan["t"], heading) if full else (None, None)
            continue
        if plan["t"] - run_start < min_run_s:
            continue
        inside = odometry[(odometry[:, 0] >= plan["t"]) & (odometry[:, 0] <= following["t"])]
        if len(inside) >= 2:
            flown = np.hypot(*(inside[-1, 1:] - inside[0, 1:])) / (inside[-1, 0] - inside[0, 0])
            out.append((plan["speed_m_s"], float(flown)))
    return out


def test_a_dry_run_plans_before_offboard_flies_the_planned_speed_ends_in_hold_and_replays(
    long_dry_run, tmp_path
):
    fly = subprocess.run(
        [*long_dry_run["fly"], "--log", str(long_dry_run["log"])],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert fly.returncode == 0, fly.stdout + fly.stderr
    assert "ended by budget" in fly.stdout
    assert "first plan ready before offboard" in fly.stdout
    assert "planning with 8 m/s" in fly.stdout
    assert "datagrams dropped" not in fly.stdout  # none lost: nothing to say
    stats = _stop_stub(long_dry_run)
    log = long_dry_run["log"]

    # offboard started, and setpoints arrived at the promised rate (>= 10 Hz; 20 Hz is sent)
    assert any(r["message"].startswith("offboard started") for r in _records(log, "status"))
    modes = [m["mode"] for m in stats["modes"]]
    assert modes[:2] == ["hold", "takeoff"] and modes[-2:] == ["offboard", "hold"]
    assert stats["offboard_setpoint_rate_hz"] >= 15.0
    assert stats["offboard_max_gap_s"] < 0.5

    # the first plan was made before offboard started, the vehicle never waited for a plan
    records = read_log(log).records
    first = next(r for r in records if r["kind"] == "plan")
    offboard = next(r for r in records if r.get("message", "").startswith("offboard started"))
    assert first["k"] == 0 and first["status"] == "ok" and first["seq"] < offboard["seq"]
    modes = [r["mode"] for r in records if r["kind"] == "mode" and r["seq"] > offboard["seq"]]
    assert "waiting for the first plan" not in modes and "fallback" not in modes
    assert not _records(log, "late")

    # flown speed within 10 % of the planned 8 m/s on straight legs
    straight = _straight_leg_speeds(records)
    assert len(straight) >= 3, straight
    for planned, flown in straight:
        assert flown == pytest.approx(planned, rel=0.10), straight

    # at least one target detected and its belief updated
    accepted = [r for r in _records(log, "detection") if r["accepted"]]
    assert accepted
    end = _records(log, "end")[0]
    assert end["reason"] == "budget" and end["time"] == LONG_BUDGET_S
    scenario = load_scenario(long_dry_run["scenario"])
    mission = scenario.mission_spec()
    _, unseen = mission.motion.predict(
        scenario.means(), scenario.covariances(), mission.process_noise, LONG_BUDGET_S
    )
    seen = {r["target"] for r in accepted}
    for i, tid in enumerate(scenario.target_ids):
        if tid in seen:
            unseen_logdet = np.log(np.linalg.det(unseen[i, :2, :2]))
            assert end["per_target_logdet"][tid] < unseen_logdet - 1.0

    # the mission ended in hold, confirmed by telemetry
    safety = _records(log, "safety")
    assert [(s["reason"], s["action"], s["confirmed"]) for s in safety] == [
        ("budget", "hold", "HOLD")
    ]
    assert stats["final_mode"] == "hold" and "mode HOLD (commanded)" in stats["stdout"]

    # the log replays with the same beliefs and decisions
    summary_path, figure = tmp_path / "replay.json", tmp_path / "replay.png"
    replay = subprocess.run(
        [*CLI, "replay", str(log), "--json", str(summary_path), "--plot", str(figure)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert replay.returncode == 0, replay.stderr
    summary = json.loads(summary_path.read_text())
    assert summary["mismatches"] == 0, summary["first_mismatches"]
    assert summary["U"] == end["U"] and summary["ended_by"] == "budget"
    assert figure.read_bytes()[:4] == b"\x89PNG"


def _wait_for_offboard(path, timeout_s=90.0):
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists() and "offboard started" in path.read_text():
            return
        time.sleep(0.1)
    raise AssertionError("offboard never started")


@pytest.mark.parametrize("end", ["interrupt", "geofence", "lost link"])
def test_safe_ends_switch_to_hold_and_say_why(dry_run, end):
    log = dry_run["log"]
    extra = {
        "interrupt": [],
        "geofence": ["--max-distance", "10"],
        "lost link": ["--lost-link", "1"],
    }[end]
    fly = subprocess.Popen(
        [*dry_run["fly"], "--log", str(log), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        _wait_for_offboard(log)
        if end == "interrupt":
            time.sleep(1.0)
            fly.send_signal(signal.SIGINT)
        elif end == "lost link":
            time.sleep(1.0)
            _stop_stub(dry_run)
        out, err = fly.communicate(timeout=40)
    finally:
        if fly.poll() is None:
            fly.kill()
            fly.wait()
    expected = {
        "interrupt": ("interrupted", 130),
        "geofence": ("geofence", 3),
        "lost link": ("lost link", 3),
    }[end]
    assert fly.returncode == expected[1], out + err
    assert f"ended by {expected[0]}" in out
    safety = _records(log, "safety")
    assert len(safety) == 1 and safety[0]["reason"] == expected[0]
    assert safety[0]["action"] == "hold"
    end_record = _records(log, "end")[0]
    assert end_record["reason"] == expected[0] and end_record["time"] < BUDGET_S
    if end == "lost link":
        assert safety[0]["confirmed"] is None  # nobody is there to confirm it
    else:
        assert safety[0]["confirmed"] == "HOLD"
        assert _stop_stub(dry_run)["final_mode"] == "hold"


def test_targets_sim_feeds_fly_from_the_vehicles_own_telemetry(tmp_path, example_path):
    """stub (no targets, telemetry also to a ground-station port) -> targets-sim over MAVLink
    -> detections over UDP -> fly."""
    gcs = _free_udp_port()
    run = _start_dry_run(
        tmp_path, example_path, BUDGET_S, ["--no-targets", "--gcs", f"udpout://127.0.0.1:{gcs}"]
    )
    targets_stats = tmp_path / "targets.json"
    targets = subprocess.Popen(
        [
            *CLI,
            "targets-sim",
            str(run["scenario"]),
            "--mavlink",
            f"udpin://127.0.0.1:{gcs}",
            "--detections",
            f"udp://127.0.0.1:{run['detections_port']}",
            "--duration",
            "150",
            "--stats",
            str(targets_stats),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        fly = subprocess.run(
            [*run["fly"], "--log", str(run["log"]), "--planner", "greedy"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert fly.returncode == 0, fly.stdout + fly.stderr
        stub = _stop_stub(run)
        targets.send_signal(signal.SIGINT)
        out, err = targets.communicate(timeout=10)
    finally:
        _end(run["stub"])
        _end(targets)
    assert targets.returncode == 0, err
    assert stub["detections_sent"] == {}  # the stub simulated no targets itself
    sent = json.loads(targets_stats.read_text())
    assert sent["mission_started"] and sent["positions"] > 100
    assert "mission started: targets moving" in out and "vehicle in OFFBOARD" in out
    accepted = [r for r in _records(run["log"], "detection") if r["accepted"]]
    assert accepted and sum(sent["detections_sent"].values()) >= len(accepted) > 0
    # the detections are where the truth is: p1 starts at (30.5, 9.5) walking east at 3 m/s
    first = min(accepted, key=lambda r: r["t"])
    truth = {"p1": (30.5, 9.5, 3.0, 0.1), "p2": (29.5, -10.5, 3.0, -0.1)}[first["target"]]
    expected = np.array(truth[:2]) + first["t"] * np.array(truth[2:])
    assert np.hypot(*(np.asarray(first["position"]) - expected)) < 8.0  # 1 s offset + noise
