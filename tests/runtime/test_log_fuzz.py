"""Mission logs into replay: a tampered log replays (differences reported) or is refused in one
line naming the line and the field; never a traceback (fuzzed over fields and values)."""

import json
import os
import sys

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.interface import InputError
from hptrack.registry import make_planner
from hptrack.runtime.log import MissionLog
from hptrack.runtime.replay import replay_log
from hptrack.runtime.simulated import SimulatedFaults, run_simulated

FUZZ = settings.get_profile(os.environ.get("HPTRACK_FUZZ", "fuzz-ci"))


@pytest.fixture(scope="module")
def log_lines(tmp_path_factory):
    from hptrack.scenario import load_scenario

    example = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "paper-flight.yaml")
    scenario = load_scenario(example).model_copy(update={"budget": 10.0})
    path = tmp_path_factory.mktemp("log") / "m.jsonl"
    log = MissionLog(path)
    faults = SimulatedFaults(bad_input_rate_hz=2.0)
    run_simulated(scenario, make_planner("greedy", {}), seed=1, faults=faults, log=log)
    log.close()
    return path.read_text().splitlines()


def replayed_or_refused(tmp_path, lines):
    path = tmp_path / "tampered.jsonl"
    path.write_text("\n".join(lines) + "\n")
    try:
        return replay_log(path).summary
    except InputError as err:
        message = str(err)
        assert "\n" not in message and len(message) <= 600, message
        return message


@pytest.mark.parametrize(
    ("kind", "field", "value", "needle"),
    [
        ("odometry", "t", KeyError, "t: Field required"),
        ("odometry", "position", KeyError, "position: Field required"),
        ("odometry", "t", "abc", "valid number"),
        ("plan", "k", "x", "valid integer"),
        ("plan", "k", 10**300, "less than or equal"),
        ("truth", "states", "x", "valid list"),
        ("end", "reason", KeyError, "reason: Field required"),
        ("end", "U", "abc", "U: Input should be a valid number"),
        ("header", "seed", 10**300, "seed"),
        ("header", "controller", "x", "valid dictionary"),
        ("header", "planner_settings", "x", "valid dictionary"),
        ("odometry", "kind", ["odometry"], "valid string"),
    ],
)
def test_tampered_fields_are_one_line(tmp_path, log_lines, kind, field, value, needle):
    lines = list(log_lines)
    i = next(i for i, line in enumerate(lines) if json.loads(line)["kind"] == kind)
    record = json.loads(lines[i])
    if value is KeyError:
        record.pop(field)
    else:
        record[field] = value
    lines[i] = json.dumps(record)
    outcome = replayed_or_refused(tmp_path, lines)
    assert isinstance(outcome, str) and f"line {i + 1}" in outcome and needle in outcome, outcome


@pytest.mark.parametrize(
    "line",
    [
        '{"kind": "odometry", "t": 1, "position": ' + "[" * 50000 + "]" * 50000 + "}",
        '{"kind": "odometry", "t": ' + "9" * 5000 + ', "position": [1, 2]}',
    ],
)
def test_deep_json_and_long_integers_are_one_line(tmp_path, log_lines, line):
    outcome = replayed_or_refused(tmp_path, [*log_lines[:3], line, *log_lines[3:]])
    assert isinstance(outcome, str) and "line 4" in outcome


VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**30), 10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=6),
    st.sampled_from(["nan", "inf", "-inf", "header", "plan", "end"]),
    st.lists(st.floats(allow_nan=False), max_size=4),
    st.recursive(st.integers(0, 3), lambda c: st.lists(c, max_size=2), max_leaves=20),
    st.just(KeyError),
)


@FUZZ
@given(data=st.data())
def test_fuzz_tampered_logs_replay_or_are_refused_in_one_line(tmp_path_factory, log_lines, data):
    lines = list(log_lines)
    for _ in range(data.draw(st.integers(1, 3))):
        i = data.draw(st.integers(0, len(lines) - 1))
        record = json.loads(lines[i])
        field = data.draw(st.sampled_from(sorted(record) + ["extra"]))
        value = data.draw(VALUES)
        if value is KeyError:
            record.pop(field, None)
        else:
            record[field] = value
        lines[i] = json.dumps(record)
    outcome = replayed_or_refused(tmp_path_factory.mktemp("fuzz"), lines)
    if isinstance(outcome, dict):
        assert json.dumps(outcome, allow_nan=True)


def test_truth_of_the_wrong_shape_is_left_out(tmp_path, log_lines):
    lines = list(log_lines)
    i = next(i for i, line in enumerate(lines) if json.loads(line)["kind"] == "truth")
    record = json.loads(lines[i])
    record["states"] = []
    lines[i] = json.dumps(record)
    summary = replayed_or_refused(tmp_path, lines)
    assert isinstance(summary, dict) and summary["mismatches"] == 0


@pytest.mark.skipif(sys.platform == "win32", reason="devices and FIFOs")
def test_a_device_or_a_fifo_is_refused_at_once(tmp_path):
    fifo = tmp_path / "log.fifo"
    os.mkfifo(fifo)  # reading it would wait for a writer forever
    for path in (fifo, "/dev/zero", "/dev/urandom", tmp_path):
        with pytest.raises(InputError, match="not a mission log .a folder, a device, a FIFO"):
            replay_log(path)


def test_a_header_that_asks_for_hours_of_search_is_refused(tmp_path, log_lines):
    header = json.loads(log_lines[0])
    header.update(planner="mcts", planner_settings={"iterations": 10**9})
    outcome = replayed_or_refused(tmp_path, [json.dumps(header), *log_lines[1:]])
    assert isinstance(outcome, str), outcome
    assert "searches 1,000,000,000 iterations per decision; replaying its" in outcome
