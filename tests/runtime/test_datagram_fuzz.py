"""The detection-datagram boundary: every line is a detection or a counted refusal, never an
exception, and the controller survives every one of them (fuzzed)."""

import json
import os
import socket

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.registry import make_planner
from hptrack.runtime.controller import MissionController
from hptrack.runtime.log import MissionLog
from hptrack.runtime.network import (
    MAX_DETECTION_LINE_CHARS,
    DetectionMessage,
    Refusal,
    enlarge_receive_buffer,
    kernel_drops,
    parse_detection_line,
)

FUZZ = settings.get_profile(os.environ.get("HPTRACK_FUZZ", "fuzz-ci"))

HOSTILE = [
    '{"id":"p1","x":1' + "0" * 400 + ',"y":1.0}',
    "[" * 5000 + "]" * 5000,
    '{"id":"p1","x":' + "9" * 5000 + ',"y":1}',
    '{"id":"p1","x":NaN,"y":1}',
    '{"id":"p1","x":Infinity,"y":1}',
    '{"id":"p1","x":1e999,"y":1}',
    '{"id":"p1","x":"3","y":1}',
    '{"id":"p1","x":true,"y":1}',
    '{"id":["p1"],"x":1,"y":1}',
    '{"id":"p1","x":1,"y":1,"cov":[[1,0],[0]]}',
    '{"id":"p1","x":1,"y":1,"t":"now"}',
    '{"id":"p1","x":1}',
    "null",
    "",
    "x" * (MAX_DETECTION_LINE_CHARS + 1),
    '{"id":"p1","x":1,"y":1,"cov":' + "[" * 20 + "]" * 20 + "}",
]


@pytest.mark.parametrize("line", HOSTILE)
def test_hostile_lines_are_refused_with_a_reason(line):
    parsed = parse_detection_line(line)
    assert isinstance(parsed, Refusal), parsed
    assert parsed.reason in ("malformed", "non-finite")
    assert "\n" not in parsed.detail and len(parsed.detail) < 300


def test_a_detection_line_is_read_as_written():
    line = '{"id": "p1", "x": 3, "y": -4.5, "t": 1700000000.25, "cov": [[2, 0.5], [0.5, 3]]}'
    assert parse_detection_line(line) == DetectionMessage(
        "p1", (3.0, -4.5), ((2.0, 0.5), (0.5, 3.0)), 1700000000.25
    )


def test_kernel_drops_of_a_flood_are_counted():
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        receiver.bind(("127.0.0.1", 0))
        enlarge_receive_buffer(receiver)
        before = kernel_drops(receiver)
        if before is None:
            pytest.skip("no /proc/net/udp on this system")
        for _ in range(30_000):  # nobody reads: the buffer fills, the rest is dropped
            sender.sendto(b"x" * 200, receiver.getsockname())
        assert kernel_drops(receiver) - before > 0
    finally:
        receiver.close()
        sender.close()


NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**500), 10**500),
    st.booleans(),
    st.none(),
    st.text(max_size=5),
)
FIELDS = st.dictionaries(
    st.sampled_from(["id", "x", "y", "t", "cov", "extra"]),
    st.one_of(
        NUMBERS,
        st.sampled_from(["p1", "p2", "\x1b[2J", "x" * 300]),
        st.lists(st.lists(NUMBERS, max_size=3), max_size=3),
        st.recursive(st.integers(), lambda c: st.lists(c, max_size=2), max_leaves=30),
    ),
)


def _text(fields):
    try:
        return json.dumps(fields)
    except ValueError:
        return str(fields)


LINES = st.one_of(
    FIELDS.map(_text),
    st.text(max_size=200),
    st.builds(lambda n, o: o * n + "]" * n, st.integers(0, 6000), st.sampled_from(["[", "{"])),
)


@pytest.fixture(scope="module")
def controller(tmp_path_factory):
    from hptrack.scenario import load_scenario

    example = os.path.join(os.path.dirname(__file__), "..", "..", "examples", "paper-flight.yaml")
    scenario = load_scenario(example)
    c = MissionController(scenario, make_planner("greedy", {}), seed=0, log=MissionLog())
    c.odometry(0.0, (0.0, 0.0))
    yield c
    c.close()


@FUZZ
@given(lines=st.lists(LINES, min_size=1, max_size=5))
def test_fuzz_datagrams_never_raise_and_are_all_counted(controller, lines):
    before = sum(controller.rejected.values()) + controller.accepted["detection"]
    for line in lines:
        parsed = parse_detection_line(line)
        if isinstance(parsed, Refusal):
            controller.bad_input("detection", parsed.reason, parsed.detail, line[:200])
        else:
            controller.detection(1.0, parsed.target, parsed.position, parsed.covariance)
    after = sum(controller.rejected.values()) + controller.accepted["detection"]
    assert after - before == len(lines)
    assert not controller.finished
