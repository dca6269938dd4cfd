"""``hptrack fly`` flies a team: the team-flight example on two vehicle stubs (``vehicle-sim
--instances 2``, one MAVSDK connection each) ends by its budget, keeps the separation in every
logged step and replays with 0 mismatches; with a fence, the fence is put on both stubs and
every setpoint of both stays inside it, or the stubs' own fence is flown."""

import json
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

pytest.importorskip("mavsdk")
pytest.importorskip("pymavlink")

from hptrack.models.fence import point_free  # noqa: E402
from hptrack.runtime.log import read_log  # noqa: E402
from hptrack.scenario.io import parse_scenario  # noqa: E402

# one stub flight at a time on one test worker, as the other stub flights
pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("stub-flights")]

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "team-flight.yaml"
CLI = [sys.executable, "-m", "hptrack"]
BUDGET_S = 15.0
SEPARATION_M = 10.0


def _free_port_pair() -> int:
    """A UDP port ``p`` on loopback with ``p + 1`` free too."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as first:
            first.bind(("127.0.0.1", 0))
            port = first.getsockname()[1]
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as second:
                try:
                    second.bind(("127.0.0.1", port + 1))
                except OSError:
                    continue
                return port
    raise AssertionError("no two consecutive free UDP ports")


def _end(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
    try:
        process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        process.communicate()


def _fly_team(tmp_path, data, targets="stubs", stub_args=(), fly_args=()):
    """The team scenario ``data`` flown by ``fly`` on ``vehicle-sim --instances 2`` (its
    targets from the stubs or from ``targets-sim``); ``fly``'s run, its log and the stubs'
    statistics."""
    scenario = tmp_path / "team.yaml"
    scenario.write_text(yaml.safe_dump(data))
    mav, det, gcs = _free_port_pair(), _free_port_pair(), _free_port_pair()
    own = ["--no-targets", "--gcs", f"udpout://127.0.0.1:{gcs}"] if targets != "stubs" else []
    stats = tmp_path / "stubs.json"
    stub = subprocess.Popen(
        [*CLI, "vehicle-sim", str(scenario), "--instances", "2", "--mavlink",
         f"udpout://127.0.0.1:{mav}", "--detections", f"udp://127.0.0.1:{det}",
         "--duration", str(BUDGET_S + 150), "--stats", str(stats), *own, *stub_args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    sim = None
    if targets != "stubs":  # both stubs' telemetry on one port, as PX4 SITL's instances
        sim = subprocess.Popen(
            [*CLI, "targets-sim", str(scenario), "--mavlink", f"udpin://127.0.0.1:{gcs}",
             "--detections", f"udp://127.0.0.1:{det}", "--duration", str(BUDGET_S + 150),
             "--stats", str(tmp_path / "targets.json")],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
    log = tmp_path / "team.jsonl"
    try:
        fly = subprocess.run(
            [*CLI, "fly", str(scenario), "--connection", f"udpin://127.0.0.1:{mav}",
             "--connection", f"udpin://127.0.0.1:{mav + 1}", "--detections",
             f"udp://127.0.0.1:{det}", "--altitude", "5", "--takeoff", "--no-live",
             "--connect-timeout", "20", "--iterations", "300", "--separation",
             str(SEPARATION_M), "--log", str(log), *fly_args],
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
    finally:
        _end(stub)
        if sim is not None:
            _end(sim)
    instances = json.loads(stats.read_text())["instances"] if stats.exists() else None
    return fly, log, instances


def _replay(log, tmp_path):
    summary = tmp_path / "replay.json"
    replay = subprocess.run(
        [*CLI, "replay", str(log), "--json", str(summary), "--plot", str(tmp_path / "r.png")],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert replay.returncode == 0, replay.stderr
    return json.loads(summary.read_text())


@pytest.mark.parametrize("targets", ["stubs", "targets-sim"])
def test_a_team_of_two_stubs_flies_to_its_budget_apart_and_replays(tmp_path, targets):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["budget"] = BUDGET_S
    fly, log, _ = _fly_team(tmp_path, data, targets)
    sim = targets != "stubs"
    assert fly.returncode == 0, fly.stdout + fly.stderr
    out = " ".join(fly.stdout.split())
    assert "ended by budget" in out and "vehicles 0 hold, 1 hold: 0 HOLD, 1 HOLD" in out
    records = read_log(log).records
    header = read_log(log).header
    assert header["planner"] == "team-mcts" and header["separation_m"] == SEPARATION_M
    systems = [r["system_id"] for r in records if "system_id" in r and r["kind"] == "status"]
    assert systems == [1, 2]  # one autopilot per connection
    frames = [(r["vehicle"], r["offset"]) for r in records if r["kind"] == "frame"]
    assert frames == [(0, [0.0, 0.0]), (1, [0.0, 0.0])]  # the stubs share one origin
    odometry = [r for r in records if r["kind"] == "odometry" and r["accepted"]]
    assert {r["vehicle"] for r in odometry} == {0, 1}
    ticks = [r for r in records if r["kind"] == "tick" and r["agent"] is not None]
    assert len(ticks) == BUDGET_S / 0.5
    assert all(r["separation_m"] >= SEPARATION_M for r in ticks)
    assert all(len(r["agent"]) == 2 for r in ticks)
    end = next(r for r in records if r["kind"] == "end")
    assert end["reason"] == "budget" and end["min_reference_separation_m"] >= SEPARATION_M - 1e-9
    detections = [r for r in records if r["kind"] == "detection" and r["accepted"]]
    assert detections
    if sim:  # targets-sim read both vehicles; what fly took, it sent
        seen = json.loads((tmp_path / "targets.json").read_text())
        assert seen["mission_started"] and seen["other_positions"] == 0
        assert min(seen["positions_by_vehicle"]) > 10 * BUDGET_S  # both at 30 Hz
        assert set(seen["detections_sent"]) >= {r["target"] for r in detections}
    safety = [r for r in records if r["kind"] == "safety"]
    assert [r["confirmed"] for r in safety] == ["HOLD", "HOLD"]

    replayed = _replay(log, tmp_path)
    assert replayed["mismatches"] == 0, replayed["first_mismatches"]
    assert replayed["ended_by"] == "budget" and replayed["U"] == end["U"]
    assert replayed["min_separation_m"] == end["min_separation_m"]
    assert (tmp_path / "r.png").read_bytes()[:4] == b"\x89PNG"


# An operating area, a no-fly square across vehicle 0's straight way to p1 and a no-fly circle
# south of p3's walk (metres in the shared local frame).
FENCE = {
    "inclusion": {"polygon": [[-40, -70], [200, -70], [200, 70], [-40, 70]]},
    "exclusions": [
        {"polygon": [[12, 20], [20, 20], [20, 30], [12, 30]]},
        {"circle": [25.0, -27.0, 4.0]},
    ],
    "margin": 5.0,
}


def test_a_fenced_team_puts_the_fence_on_both_stubs_and_flies_inside_it(tmp_path):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["budget"] = BUDGET_S
    data["fence"] = FENCE
    fly, log, instances = _fly_team(tmp_path, data)
    assert fly.returncode == 0, fly.stdout + fly.stderr
    out = " ".join(fly.stdout.split())
    assert "ended by budget" in out
    for j in (0, 1):
        assert (
            f"vehicle {j}: fence: the scenario's, uploaded and read back (within 0.1 m), an "
            "inclusion polygon, 1 exclusion polygon, 1 exclusion circle; GF_ACTION 2 (hold)"
        ) in out
    spec = parse_scenario(data, "team").fence.spec()
    free, fence = spec.compiled(), spec._replace(margin=0.0).compiled()
    for stats in instances:
        assert len(stats["setpoint_positions"]) > 10 * BUDGET_S
        outside = [(n, e) for _, n, e in stats["setpoint_positions"] if not point_free(free, e, n)]
        assert outside == []
        assert all(point_free(fence, e, n) for _, n, e, _, _ in stats["track"])
        assert stats["fence_breaches"] == [] and stats["final_mode"] == "hold"
    contents = read_log(log)
    synced = [r for r in contents.records if r["kind"] == "geofence" and "source" in r]
    assert [(r["vehicle"], r["source"], r["action"]) for r in synced] == [
        (0, "scenario", 2),
        (1, "scenario", 2),
    ]
    assert synced[0]["origin"] == synced[1]["origin"]  # the first vehicle's, for both
    margins = [r for r in contents.records if r["kind"] == "geofence" and "margin_m" in r]
    assert [r["vehicle"] for r in margins] == [0, 1]
    projections = [r for r in contents.records if r["kind"] == "fence"]
    assert all(point_free(free, *r["projected"]) for r in projections)
    assert {r["vehicle"] for r in projections} <= {0, 1}
    end = next(r for r in contents.records if r["kind"] == "end")
    assert end["reason"] == "budget"
    said = next(r for r in contents.records if r["kind"] == "geofence" and "projections" in r)
    assert said["projections"] == len(projections)
    assert contents.header["scenario"]["fence"] == json.loads(
        json.dumps(parse_scenario(data, "team").fence.model_dump())
    )
    replayed = _replay(log, tmp_path)
    assert replayed["mismatches"] == 0, replayed["first_mismatches"]
    assert replayed["U"] == end["U"]


def test_a_team_flies_the_fence_both_vehicles_hold(tmp_path):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["budget"] = 6.0
    data["fence"] = FENCE
    fly, log, _ = _fly_team(
        tmp_path, data, stub_args=["--hold-fence", "--fence-shift", "0.5"],
        fly_args=["--fence-from-vehicle"],
    )  # fmt: skip
    assert fly.returncode == 0, fly.stdout + fly.stderr
    out = " ".join(fly.stdout.split())
    assert "vehicle 1: fence: the vehicle's, an inclusion polygon" in out
    flown = read_log(log).header["scenario"]["fence"]
    np.testing.assert_allclose(
        np.array(flown["inclusion"]["polygon"]),
        np.array(FENCE["inclusion"]["polygon"]) + [0.0, 0.5],
        atol=0.012,
    )
    replayed = _replay(log, tmp_path)
    assert replayed["mismatches"] == 0, replayed["first_mismatches"]


def test_a_team_without_identity_flies_to_its_budget_with_each_camera_s_looks_and_replays(
    tmp_path,
):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["budget"] = BUDGET_S
    data["sensor"] = {
        "labelled": False,
        "detection_probability": 0.8,
        "false_alarm_density": 2.0e-4,  # per m^2 per look: 0.063 a look in each footprint
    }
    fly, log, _ = _fly_team(tmp_path, data)
    assert fly.returncode == 0, fly.stdout + fly.stderr
    assert "ended by budget" in " ".join(fly.stdout.split())
    records = read_log(log).records
    reports = [r for r in records if r["kind"] == "detection" and r["accepted"]]
    assert reports and all(r["target"] is None for r in reports)
    assert {r["vehicle"] for r in reports} == {0, 1}  # each camera's reports name it
    looks = [r for r in records if r["kind"] == "look"]
    ticks = round(BUDGET_S / 0.5) + 1
    assert [r["vehicle"] for r in looks] == [0, 1] * ticks  # every tick, each camera in turn
    taken = {b for look in looks for b in look["belief"] if b is not None}
    assert taken & {"p1", "p2"} and taken & {"p3", "p4"}  # both vehicles' targets
    end = next(r for r in records if r["kind"] == "end")
    assert end["reason"] == "budget" and end["tracking"]["looks"] == 2 * ticks
    replayed = _replay(log, tmp_path)
    assert replayed["mismatches"] == 0, replayed["first_mismatches"]
    assert replayed["U"] == end["U"]
