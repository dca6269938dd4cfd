"""The MAVSDK adapter's detection input: JSON lines over UDP, through the detection intake,
into the controller."""

import asyncio
import json
import socket
import time

import pytest

pytest.importorskip("mavsdk")
from hptrack.interface import CurrentPlan  # noqa: E402
from hptrack.runtime.controller import MissionController  # noqa: E402
from hptrack.runtime.intake import DetectionIntake  # noqa: E402
from hptrack.runtime.mavsdk_adapter import FlightOptions, _Flight  # noqa: E402
from hptrack.runtime.worker import InlineRunner  # noqa: E402
from hptrack.settings import NoSettings  # noqa: E402


def _wait(condition, timeout_s=10.0):
    end = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < end, "timed out"
        time.sleep(0.01)


def test_detection_datagrams_feed_the_controller_and_bad_lines_are_refused(flight_scenario):
    ctrl = MissionController(flight_scenario, _Still(), runner=InlineRunner())
    flight = _Flight(ctrl, FlightOptions(), lambda s: None, lambda m: None, asyncio.Event())
    with (
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as receiver,
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sender,
    ):
        receiver.bind(("127.0.0.1", 0))
        intake = DetectionIntake(receiver, flight.detection_line, flight.mission_time)
        intake.start()
        address = receiver.getsockname()
        sender.sendto(b'{"id": "p1", "x": 30.0, "y": 10.0}', address)  # before offboard
        _wait(lambda: intake.handled == 1)
        flight.mono0, flight.unix0 = time.monotonic() - 2.0, time.time() - 2.0
        ctrl.odometry(2.0, [0.0, 0.0])
        good = json.dumps(
            {
                "id": "p1",
                "x": 36.0,
                "y": 10.0,
                "t": flight.unix0 + 1.5,
                "cov": [[2.0, 0.0], [0.0, 2.0]],
            }
        )
        lines = [good, "not json", '{"x": 1, "y": 2}', "", '{"id": "p2", "x": 30, "y": -10}']
        sender.sendto("\n".join(lines).encode(), address)
        sender.sendto(b"\xff\xfe", address)
        _wait(lambda: intake.handled == 6)
        intake.stop()
    assert intake.error is None and intake.counts() == {
        "received": 6,
        "handled": 6,
        "dropped": {},
    }
    assert ctrl.accepted["detection"] == 2
    assert dict(ctrl.rejected) == {"detection: before the start": 1, "detection: malformed": 3}
    stamps = {
        r["target"]: r["t"] for r in ctrl.log.records if r["kind"] == "detection" and r["accepted"]
    }
    assert stamps["p1"] == pytest.approx(1.5, abs=1e-6)  # the detector's own time stamp
    assert stamps["p2"] == pytest.approx(2.0, abs=0.5)  # no stamp: the time of arrival


class _Still:
    name = "stationary"
    settings = NoSettings()

    def current_plan(self):
        return CurrentPlan()

    def reset(self, mission, observation, rng):
        pass

    def act(self, observation):
        return observation.agent_position

    def episode_info(self):
        return {}


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"altitude_m": -5.0}, "altitude_m must be a number in (0, 10000], got -5.0"),
        ({"setpoint_rate_hz": 5.0}, "setpoint_rate_hz must be a number in [10, 1000], got 5.0"),
        ({"setpoint_rate_hz": 10.0}, None),
        ({"lost_link_s": float("nan")}, "lost_link_s must be a number in (0, 600], got nan"),
        ({"max_distance_m": True}, "max_distance_m must be a number"),
        ({"first_plan_timeout_s": 86400.0}, None),
        ({"log_failure": "panic"}, "log_failure 'panic': expected continue or hold"),
    ],
)
def test_flight_options_hold_their_own_bounds(changes, message):
    """The bounds of a flight's options are the library's, so Python users get the same one-line
    errors as ``hptrack fly`` (which names the options by their flags)."""
    if message is None:
        assert FlightOptions(**changes)
        return
    with pytest.raises(ValueError) as err:
        FlightOptions(**changes)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)
