"""The detection-datagram boundary: every line is a detection or a counted refusal, never an
exception, and the controller survives every one of them (fuzzed); floods of datagrams through
the detection intake keep its bounds, and every line received is handed on or counted as
dropped."""

import json
import os
import socket
import threading
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.registry import make_planner
from hptrack.runtime.controller import MissionController
from hptrack.runtime.intake import (
    LEFT_AT_END,
    OVER_DATAGRAM,
    QUEUE_FULL,
    DetectionIntake,
    IntakeLimits,
)
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


class TestDetectionFloods:
    """Floods through `DetectionIntake` on loopback: the handled rate stays at its
    limit, a datagram gives at most its line limit, the queue stays bounded, and
    ``received == handled + dropped`` whatever arrives."""

    LIMITS = IntakeLimits(lines_per_s=2000, lines_per_datagram=50, queue_lines=300, slice_s=0.02)

    @staticmethod
    def _settle(intake, expected=None, timeout_s=10.0):
        """Wait until ``expected`` lines (else no more) were received and none waits."""
        end = time.monotonic() + timeout_s
        last = None
        while time.monotonic() < end:
            time.sleep(0.05)
            now = (intake.received, intake.handled)
            done = intake.handled + intake.dropped_total == intake.received
            if done and (now == last if expected is None else now[0] == expected):
                return
            last = now

    @classmethod
    def _flood(cls, limits, datagrams, wait=None, handle=None, pause_s=0.0):
        """Send ``datagrams`` on loopback to a fresh intake (``pause_s`` after each), then
        ``wait(intake)`` (default: until it settles) and stop it; returns the intake, the
        ``(time, line)`` pairs handed on, and when the flood started."""
        receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        seen = []
        lock = threading.Lock()

        def keep(line, received_s):
            with lock:
                seen.append((time.monotonic(), line))
            if handle is not None:
                handle(line)

        try:
            receiver.bind(("127.0.0.1", 0))
            enlarge_receive_buffer(receiver)
            intake = DetectionIntake(receiver, keep, lambda: 1.0, limits)
            intake.start()
            start = time.monotonic()
            for datagram in datagrams:
                sender.sendto(datagram, receiver.getsockname())
                time.sleep(pause_s)
            (wait or cls._settle)(intake)
            intake.stop()
        finally:
            sender.close()
            receiver.close()
        return intake, seen, start

    def test_lines_are_handed_on_at_the_limit_and_the_rest_is_counted(self):
        datagram = b"\n".join(b"line %d" % i for i in range(40))
        # 20,000 lines in about 0.5 s
        intake, seen, start = self._flood(self.LIMITS, [datagram] * 500, pause_s=0.001)
        counts = intake.counts()
        assert counts["received"] % 40 == 0 and counts["received"] > 0
        assert counts["received"] == counts["handled"] + sum(counts["dropped"].values())
        assert counts["handled"] == len(seen) and counts["dropped"].get(QUEUE_FULL, 0) > 0
        # handled at no more than the limit: count the lines handled in the first second
        first_second = sum(1 for t, _ in seen if t - start < 1.0)
        per_slice = round(self.LIMITS.lines_per_s * self.LIMITS.slice_s)
        assert first_second <= self.LIMITS.lines_per_s + per_slice

    def test_a_datagram_gives_at_most_its_line_limit(self):
        huge = b"\n".join(b"x%d" % i for i in range(1700))
        blank = b"\n\n  \r\n"  # blank lines are no lines
        intake, seen, _ = self._flood(self.LIMITS, [huge, blank])
        assert intake.counts() == {
            "received": 1700,
            "handled": 50,
            "dropped": {OVER_DATAGRAM: 1650},
        }
        assert [line for _, line in seen] == [b"x%d" % i for i in range(50)]

    def test_lines_still_queued_at_the_stop_are_counted(self):
        slow = IntakeLimits(lines_per_s=10, lines_per_datagram=100, queue_lines=100, slice_s=0.1)
        datagram = b"\n".join(b"y%d" % i for i in range(80))
        intake, _, _ = self._flood(slow, [datagram], wait=lambda intake: time.sleep(0.3))
        counts = intake.counts()
        assert counts["received"] == 80 and counts["dropped"][LEFT_AT_END] > 50
        assert counts["handled"] + counts["dropped"][LEFT_AT_END] == 80

    def test_costly_lines_take_no_more_than_their_share_of_the_time(self):
        limits = IntakeLimits(
            lines_per_s=1000, lines_per_datagram=100, queue_lines=100, slice_s=0.05
        )
        intake, _, _ = self._flood(
            limits,
            [b"\n".join(b"z%d" % i for i in range(100))],
            wait=lambda intake: time.sleep(1.0),
            handle=lambda line: time.sleep(0.02),
        )
        # 0.3 of each slice: about 15 lines of 20 ms in a second, not 50
        assert 5 <= intake.handled <= 25, intake.counts()

    def test_a_failing_handler_stops_the_intake_and_is_kept(self):
        def fail(line):
            if line == b"bad":
                raise RuntimeError("a bug in the handler")

        intake, seen, _ = self._flood(
            self.LIMITS, [b"ok\nbad\nnever"], wait=lambda intake: time.sleep(0.3), handle=fail
        )
        assert "RuntimeError: a bug in the handler" in intake.error
        assert [line for _, line in seen] == [b"ok", b"bad"]
        assert intake.counts() == {"received": 3, "handled": 2, "dropped": {LEFT_AT_END: 1}}

    @FUZZ
    @given(
        datagrams=st.lists(
            st.tuples(st.integers(0, 400), st.sampled_from([b"", b"\n", b"\r\n", b" \n"])),
            min_size=1,
            max_size=10,
        )
    )
    def test_fuzz_floods_keep_every_line_counted(self, datagrams):
        expected = sum(n for n, _ in datagrams)
        intake, seen, _ = self._flood(
            self.LIMITS,
            [b"\n".join(b"d%d" % i for i in range(n)) + tail for n, tail in datagrams],
            wait=lambda intake: self._settle(intake, expected),
        )
        counts = intake.counts()
        assert counts["received"] == expected  # a few datagrams: the kernel keeps them all
        assert counts["received"] == counts["handled"] + sum(counts["dropped"].values())
        assert counts["handled"] == len(seen)
        per_datagram = sum(max(0, n - self.LIMITS.lines_per_datagram) for n, _ in datagrams)
        assert counts["dropped"].get(OVER_DATAGRAM, 0) == per_datagram
