"""Flying on detections without identity (issue 29): reports without id, associated at each tick
by the simulator's tracker; the simulated flight is the simulator's mission, its log replays with
0 mismatches, and the synthetic detector sends what the simulator's detector draws."""

import json
import socket
from pathlib import Path

import numpy as np
import pytest
import yaml

from hptrack.registry import make_planner
from hptrack.runtime.controller import MissionController
from hptrack.runtime.log import MissionLog
from hptrack.runtime.network import DetectionMessage, Refusal, parse_detection_line
from hptrack.runtime.replay import replay_log
from hptrack.runtime.simulated import SimulatedFaults, run_simulated
from hptrack.runtime.targets import TargetDetector
from hptrack.runtime.worker import InlineRunner
from hptrack.runtime.world import TrueTargets, synthetic_detector
from hptrack.scenario import load_scenario
from hptrack.scenario.io import file_data, parse_scenario
from hptrack.sim.episode import run_episode

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "unlabelled-flight.yaml"


@pytest.fixture
def unlabelled():
    """The unlabelled-flight example (the paper's flight, no ids, Pd 0.8, clutter)."""
    return load_scenario(EXAMPLE)


def _looks(records):
    return [r for r in records if r["kind"] == "look"]


def _with_sensor(**fields):
    data = yaml.safe_load(EXAMPLE.read_text())
    data["sensor"].update(fields)
    return parse_scenario(data, "test")


@pytest.mark.parametrize(
    ("seed", "fields", "preset"),
    [
        (1, {}, "revisit"),
        (3, {}, "improved"),
        (3, {"association": "jpda", "false_alarm_density": 1e-3}, "improved"),
    ],
)
def test_a_simulated_flight_without_identity_is_the_simulators_mission(seed, fields, preset):
    # the same detector's reports at every tau and no planner delay: the controller's tracker
    # makes the simulator's associations (each report to the same belief with the same
    # weight, GNN's or JPDA's, the same claims) and ends with the same U; these seeds and
    # searches have claims
    unlabelled = _with_sensor(**fields)
    options = {"preset": preset, "iterations": 300}
    want = run_episode(unlabelled, make_planner("mcts", options), seed=seed)
    got = run_simulated(unlabelled, make_planner("mcts", options), seed=seed)
    assert got.controller.end["reason"] == "budget" and not got.controller.rejected
    assert got.uncertainty == pytest.approx(want.uncertainty, abs=1e-9)
    records = got.controller.log.records
    positions = {r["report"]: r["position"] for r in records if r["kind"] == "detection"}
    ids = list(unlabelled.target_ids)
    rows = [
        (look["k"], *positions[report], -1 if belief is None else ids.index(belief), weight)
        for look in _looks(records)
        for report, belief, weight in zip(
            look["reports"], look["belief"], look["weight"], strict=True
        )
    ]
    expected = want.associations[:, [0, 1, 2, 4, 5]]
    np.testing.assert_allclose(np.array(rows).reshape(-1, 5), expected, atol=1e-9)
    claims = [(look["k"], ids.index(c[0])) for look in _looks(records) for c in look["claims"]]
    assert len(claims) > 0
    assert claims == [(int(k), int(b)) for k, b, _ in want.claims]
    tracking = got.controller.end["tracking"]
    assert tracking["looks"] == unlabelled.mission_spec().n_steps + 1
    assert tracking["reports"] == len(want.associations)
    assert tracking["claims"] == len(want.claims)


def test_a_faulty_simulated_flight_without_identity_replays_with_no_mismatch(unlabelled, tmp_path):
    # frames at 10 Hz (four of five superseded at each look), latency and jitter (some reports
    # arrive after their look and are refused), drops and hostile inputs: the replay makes the
    # same looks, associations and decisions
    faults = SimulatedFaults(
        detection_rate_hz=10.0,
        detection_latency_s=0.05,
        detection_jitter_s=0.3,
        detection_drop_probability=0.1,
        bad_input_rate_hz=2.0,
    )
    path = tmp_path / "m.jsonl"
    scenario = unlabelled.model_copy(update={"budget": 20.0})
    with MissionLog(path) as log:
        run = run_simulated(scenario, make_planner("greedy"), seed=2, faults=faults, log=log)
    tracking = run.controller.end["tracking"]
    assert tracking["superseded"] > 0 and tracking["taken by a belief"] > 0
    assert run.controller.rejected["detection: late"] > 0
    result = replay_log(path)
    assert result.summary["mismatches"] == 0, result.summary["first_mismatches"]
    assert result.summary["tracking"] == tracking
    assert result.summary["U"] == pytest.approx(run.controller.end["U"], abs=1e-9)


def _controller(scenario):
    return MissionController(scenario, make_planner("greedy"), runner=InlineRunner())


def test_reports_are_checked_against_the_sensor_and_their_look(unlabelled, flight_scenario):
    labelled = _controller(flight_scenario)
    labelled.odometry(0.0, [0.0, 0.0])
    assert not labelled.detection(0.0, None, [30.0, 10.0])
    record = labelled.log.records[-1]
    assert record["reason"] == "no id" and "id field" in record["detail"]

    c = _controller(unlabelled)
    c.odometry(0.0, [30.0, 10.0])
    assert not c.detection(0.0, "p1", [30.0, 10.0])
    assert c.log.records[-1]["reason"] == "id without identity"
    assert "labelled: false" in c.log.records[-1]["detail"]
    assert not c.detection(0.0, None, [30.0, 10.0], [[2.0, 0.0], [0.0, 2.0]])
    assert c.log.records[-1]["reason"] == "not R"
    assert not c.detection(0.0, None, [30.0, 10.0], confidence=1.5)
    assert c.log.records[-1]["reason"] == "bad confidence"
    assert c.detection(0.0, None, [30.0, 10.0], [[1.0, 0.0], [0.0, 1.0]], confidence=0.9)
    assert c.log.records[-1]["confidence"] == 0.9 and c.log.records[-1]["report"] == 1
    assert not c.detection(0.0, None, [30.0, 10.0])
    assert c.log.records[-1]["reason"] == "duplicate"
    c.setpoint(0.0)  # tick 0: the look of the report stamped 0
    look = _looks(c.log.records)[-1]
    assert look["k"] == 0 and look["reports"] == [1] and look["belief"] == ["p1"]
    assert c.status()["tracking"]["look"]["belief"] == ["p1"]
    assert not c.detection(0.0, None, [30.0, 10.5])
    assert c.log.records[-1]["reason"] == "late"
    assert c.detection(0.3, None, [30.0, 10.5])  # waits for tick 1
    assert c.status()["tracking"]["waiting"] == 1


def test_a_detection_line_without_id_is_a_report():
    assert parse_detection_line('{"x": 1.5, "y": -2, "confidence": 0.7}') == DetectionMessage(
        None, (1.5, -2.0), None, None, 0.7
    )
    refused = parse_detection_line('{"x": 1, "y": 2, "confidence": 1.2}')
    assert isinstance(refused, Refusal) and refused.detail.startswith("confidence:")
    # a team's report names the vehicle whose camera took it: a whole number in 0..255
    assert parse_detection_line('{"x": 1, "y": 2, "vehicle": 1}').vehicle == 1
    for bad in ("1.5", '"1"', "-1", "256", "true"):
        refused = parse_detection_line(f'{{"x": 1, "y": 2, "vehicle": {bad}}}')
        assert isinstance(refused, Refusal) and refused.detail.startswith("vehicle:"), bad


def _received(sock):
    lines = []
    sock.settimeout(0.5)
    while True:
        try:
            data = sock.recv(65536)
        except TimeoutError:
            return lines
        lines += [json.loads(line) for line in data.decode().split("\n")]


def test_the_synthetic_detector_sends_the_simulators_draws_without_ids(unlabelled):
    # TargetDetector (vehicle-sim, targets-sim) with the seed's detector stream: the same
    # misses, false alarms and noise as the simulator's detector over the same looks, no ids
    scenario = _with_sensor(false_alarm_density=5e-3)  # clutter at every look or two
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sender = TargetDetector(scenario, f"udp://127.0.0.1:{sock.getsockname()[1]}", seed=5)
    sender.start(1000.0)
    agents = [np.array([30.0 + 1.5 * k, 10.0]) for k in range(20)]
    for k, agent in enumerate(agents):
        sender.sense(1000.0 + 0.5 * k, agent)
    lines = _received(sock)
    sender.close()
    sock.close()
    detector = synthetic_detector(scenario, 5)
    targets = TrueTargets(scenario, *_truth_streams(5))
    want = [detector.look(a, targets.positions_at(0.5 * k)) for k, a in enumerate(agents)]
    expected = np.concatenate([w.positions for w in want])
    assert all("id" not in line for line in lines)
    np.testing.assert_array_equal([[line["x"], line["y"]] for line in lines], expected)
    sources = np.concatenate([w.sources for w in want])
    assert sender.stats.false_alarms == np.sum(sources < 0) > 0
    assert sender.stats.detections["p1"] == np.sum(sources == 0) < len(agents)  # misses


def test_a_labelled_detector_below_certainty_misses_and_names(flight_scenario):
    # detection_probability 0.5 with ids: the stub's detector misses about half of the looks
    # and names what it detects; the paper's sensor detects at every look
    data = file_data(flight_scenario)
    data["sensor"] = {"detection_probability": 0.5}
    counts = []
    for scenario in (flight_scenario, parse_scenario(data, "test")):
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sender = TargetDetector(scenario, f"udp://127.0.0.1:{sock.getsockname()[1]}", seed=2)
        sender.start(0.0)
        for k in range(20):
            sender.sense(0.5 * k, sender._targets.positions_at(0.5 * k)[0])
        lines = _received(sock)
        sender.close()
        sock.close()
        assert {line["id"] for line in lines} == {"p1"}
        counts.append(len(lines))
    assert counts[0] == 20 and 0 < counts[1] < 20


def _truth_streams(seed):
    truth_seq, motion_seq, _, _ = np.random.SeedSequence(seed).spawn(4)
    return np.random.default_rng(truth_seq), np.random.default_rng(motion_seq)


def test_the_live_view_shows_the_associations_and_the_tentative_tracks():
    from rich.console import Console

    from hptrack.cli.flight import _live_view

    status = {
        "t": 12.0,
        "budget": 60.0,
        "plan": None,
        "target_ids": ("p1", "p2"),
        "last_detection": {"target": None, "t": 11.5, "position": [31.0, 9.0]},
        "tracking": {
            "counts": {"looks": 24, "reports": 20, "taken by a belief": 17, "claims": 1},
            "look": {
                "k": 23,
                "time": 11.5,
                "belief": ["p1", None],
                "weight": [1.0, 0.0],
                "claims": [["p2", 20]],
            },
            "tentative": [[40.0, -3.5, 2, 1]],
            "waiting": 0,
        },
    }
    console = Console(width=200, record=True)
    console.print(_live_view(status))
    text = " ".join(console.export_text().split())
    assert "report at (31.0, 9.0) m at 11.5 s" in text
    assert "20 reports in 24 looks, 17 taken by a belief, 1 claimed by a tentative track" in text
    assert "tick 23 at 11.5 s: report -> p1 (1.00), report -> none; p2 claimed" in text
    assert "40.0, -3.5 │ 1 / 2" in text
