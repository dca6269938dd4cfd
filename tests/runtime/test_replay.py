"""Replaying a mission log gives the same beliefs and decisions, also from a truncated log."""

import json
import time

import numpy as np
import pytest

from hptrack.registry import make_planner
from hptrack.runtime.controller import MissionController
from hptrack.runtime.log import MissionLog
from hptrack.runtime.replay import replay_log
from hptrack.runtime.simulated import SimulatedFaults, run_simulated
from hptrack.runtime.worker import ThreadedRunner
from hptrack.subtasks import Subtask

FAULTS = SimulatedFaults(
    detection_rate_hz=4.0,
    detection_latency_s=0.2,
    detection_jitter_s=0.5,
    odometry_drop_probability=0.1,
    planner_slow_probability=0.3,
    planner_slow_delay_s=1.2,
    bad_input_rate_hz=2.0,
)


@pytest.fixture
def mission_log(flight_scenario, tmp_path):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    run = run_simulated(
        flight_scenario, make_planner("mcts", {"iterations": 300}), seed=2, faults=FAULTS, log=log
    )
    log.close()
    return path, run


def _ticks(records):
    return [
        (r["k"], r["submitted"], r["logdet"], r["means"]) for r in records if r["kind"] == "tick"
    ]


def test_replay_reproduces_beliefs_and_decisions(mission_log):
    path, run = mission_log
    result = replay_log(path)
    summary = result.summary
    assert summary["mismatches"] == 0, summary["first_mismatches"]
    assert summary["U"] == run.uncertainty and summary["logged_U"] == run.uncertainty
    assert summary["ended_by"] == "budget" and not summary["truncated"]
    original, replayed = run.controller.log.records, result.controller.log.records
    assert _ticks(replayed) == _ticks(original)
    plans = [
        [(r["k"], r["status"], r["waypoint"]) for r in records if r["kind"] == "plan"]
        for records in (original, replayed)
    ]
    assert plans[0] == plans[1] and len(plans[0]) > 50
    assert (
        result.controller.end["planner_info"]["subtasks"]
        == run.controller.end["planner_info"]["subtasks"]
    )
    np.testing.assert_array_equal(result.record.true_states, run.record.true_states)
    assert json.dumps(summary, allow_nan=False)


def test_a_log_of_an_older_hptrack_replays(mission_log):
    """A log whose plan records name their sub-task in the shape older hptrack wrote
    (``{"target" | "follow" | "dwell": id, "since_step", "p_find"}``) replays the same, and
    reads as the same sub-tasks."""
    path, run = mission_log
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    ids = run.controller.mission.target_ids
    new, old = [], []
    for record in lines:
        sub = record.get("subtask") if record.get("kind") == "plan" else None
        if sub:
            key = {"pursue": "target", "follow": "follow", "dwell": "dwell"}[sub["kind"]]
            record["subtask"] = {key: sub["target"], "since_step": sub["start_step"]}
            if "p_find" in sub:
                record["subtask"]["p_find"] = sub["p_find"]
            new.append(Subtask.from_json(sub, ids))
            old.append(Subtask.from_json(record["subtask"], ids))
    path.write_text("".join(json.dumps(r) + "\n" for r in lines))
    result = replay_log(path)
    assert result.summary["mismatches"] == 0, result.summary["first_mismatches"]
    assert result.summary["U"] == run.uncertainty
    assert len(old) > 10
    assert [(s.kind, s.target, s.start_step, s.p_find) for s in old] == [
        (s.kind, s.target, s.start_step, s.p_find) for s in new
    ]


def test_a_truncated_log_replays_up_to_where_it_ends(mission_log):
    path, run = mission_log
    text = path.read_text()
    cut = text.index("\n", len(text) // 2) + 40  # inside the line after the middle
    path.write_text(text[:cut])
    summary = replay_log(path).summary
    assert summary["truncated"] and summary["mismatches"] == 0
    assert summary["ended_by"] == "log ended" and summary["logged_U"] is None
    assert 0 < summary["time"] < run.controller.end["time"]
    kept = [json.loads(line) for line in text[:cut].splitlines()[:-1]]
    last_tick = max(r["k"] for r in kept if r["kind"] == "tick")
    assert summary["ticks"] == last_tick + 1


def test_a_tampered_log_is_reported(mission_log):
    path, _ = mission_log
    lines = path.read_text().splitlines()
    for i, line in enumerate(lines):
        record = json.loads(line)
        if record["kind"] == "detection" and record["accepted"] and record["t"] > 10:
            record["position"][0] += 25.0
            lines[i] = json.dumps(record)
            break
    path.write_text("\n".join(lines) + "\n")
    summary = replay_log(path).summary
    assert summary["mismatches"] > 0
    assert any(
        "tick logdet differs" in m or "means differs" in m for m in summary["first_mismatches"]
    )


def test_a_threaded_real_time_run_replays_exactly(flight_scenario, tmp_path):
    path = tmp_path / "rt.jsonl"
    log = MissionLog(path)
    scenario = flight_scenario.model_copy(update={"budget": 4.0})
    ctrl = MissionController(
        scenario, make_planner("mcts", {"iterations": 300}), log=log, runner=ThreadedRunner()
    )
    start = time.perf_counter()
    position = np.zeros(2)
    while not ctrl.finished:
        t = time.perf_counter() - start
        ctrl.odometry(t, position)
        if int(t * 10) % 3 == 0:
            ctrl.detection(t, "p1", [30.0 + 3.0 * t, 10.0])
        position = position + 0.02 * (ctrl.setpoint(t).position - position)
        time.sleep(0.01)
    log.close()
    summary = replay_log(path).summary
    assert summary["mismatches"] == 0, summary["first_mismatches"]
    assert summary["U"] == ctrl.end["U"] and summary["plans"] >= 5


@pytest.mark.parametrize("limit_bytes", [60_000, 150_000])
def test_a_log_stopped_at_its_size_limit_replays_up_to_there(
    flight_scenario, tmp_path, limit_bytes
):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path, max_bytes=limit_bytes)
    run_simulated(flight_scenario, make_planner("greedy"), seed=1, log=log)
    log.close()
    assert log.stopped is not None and path.stat().st_size <= limit_bytes
    summary = replay_log(path).summary
    assert summary["mismatches"] == 0, summary["first_mismatches"]
    assert summary["ended_by"] == "log ended" and not summary["truncated"]
    assert 0 < summary["ticks"] < flight_scenario.mission_spec().n_steps
