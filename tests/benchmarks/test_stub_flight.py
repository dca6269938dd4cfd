"""``benchmarks/stub_flight.py``'s figures of a flight, from mission-log records of the shapes
``hptrack fly`` writes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from hptrack.subtasks import Subtask

BENCHMARKS = Path(__file__).parents[2] / "benchmarks"


@pytest.fixture(scope="module")
def stub_flight():
    spec = importlib.util.spec_from_file_location("stub_flight", BENCHMARKS / "stub_flight.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _plan(k, subtask):
    plan = {"kind": "plan", "k": k, "t": 0.5 * k, "status": "ok", "subtask": subtask}
    return {**plan, "waypoint": [0.0, 0.0], "speed_m_s": 8.0, "compute_s": 0.01}


def test_sub_tasks_are_read_from_the_logs_subtask_records(stub_flight):
    """A pursuit of p1 found at step 13 and followed, then a pursuit of p2: three sub-tasks,
    one target change, in `Subtask.to_json`'s shape and in the older one."""
    ids = ["p1", "p2"]
    pursue = Subtask("pursue", 0, 0, p_find=0.9).to_json(ids)
    follow = Subtask("follow", 0, 13).to_json(ids)
    other = Subtask("pursue", 1, 40, p_find=0.5).to_json(ids)
    steps = [pursue] * 13 + [follow] * 27 + [other] * 5
    records = [_plan(k, sub) for k, sub in enumerate(steps)]
    assert stub_flight.subtasks(records) == ["pursue p1", "follow p1", "pursue p2"]
    older = [{"target": "p1", "since_step": 0}] * 2 + [{"follow": "p1", "since_step": 2}]
    assert stub_flight.subtasks([_plan(k, s) for k, s in enumerate(older)]) == [
        "pursue p1",
        "follow p1",
    ]
    assert stub_flight.subtasks([_plan(0, None)]) == ["none"]
    ticks = [{"kind": "tick", "k": k, "agent": [0.0, 0.0]} for k in range(len(steps))]
    figures = stub_flight.summary(records + ticks, {})
    assert figures["subtasks"] == 3 and figures["target_changes"] == 1


def test_the_take_off_and_offboard_times_are_read_from_the_status_lines(stub_flight):
    """From ``taking off to`` to ``take-off done:`` and from there to ``offboard started``."""
    lines = [
        (100.0, "taking off to 20 m"),
        (119.5, "take-off done: HOLD at 19.7 m (19.9 m above where it began)"),
        (120.5, "offboard started: mission time 0"),
    ]
    records = [{"kind": "status", "wall": wall, "message": text} for wall, text in lines]
    figures = stub_flight.summary(records, {"warm_up_s": 3.0})
    assert figures["takeoff_s"] == pytest.approx(19.5)
    assert figures["offboard_after_altitude_s"] == pytest.approx(1.0)
    assert figures["warm_up_s"] == 3.0
