"""The MAVSDK adapter's detection input: JSON lines over UDP, through the detection intake,
into the controller."""

import asyncio
import json
import socket
import time

import numpy as np
import pytest

pytest.importorskip("mavsdk")
from mavsdk.asyncio.plugins.telemetry import FlightMode  # noqa: E402

from hptrack.interface import CurrentPlan  # noqa: E402
from hptrack.runtime.controller import MissionController  # noqa: E402
from hptrack.runtime.intake import DetectionIntake  # noqa: E402
from hptrack.runtime.mavsdk_adapter import FlightOptions, _Flight, _watch_take_off  # noqa: E402
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
    assert dict(ctrl.rejected) == {
        "detection: before the start": 1,
        "detection: malformed": 2,
        "detection: no id": 1,  # a line without id on a mission whose sensor names targets
    }
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


def _flight(scenario, messages=None, **options):
    """A `_Flight` on a controller with an in-memory log and no vehicle."""
    ctrl = MissionController(scenario, _Still(), runner=InlineRunner())
    sink = messages.append if messages is not None else (lambda m: None)
    return _Flight(ctrl, FlightOptions(**options), lambda s: None, sink, asyncio.Event())


def _said(flight, kind=None):
    return [r for r in flight.log.records if kind is None or r["kind"] == kind]


def _take_off_with(flight, steps, ground=0.0):
    """`_watch_take_off` from the height ``ground`` (m) while ``steps`` (``(delay s,
    changes)``) change the vehicle's state: ``height`` (m), ``mode`` (a `FlightMode` name),
    ``armed``, ``position`` (``False``: no more position messages)."""
    vehicle = flight.vehicle
    vehicle.position_ned, vehicle.received_at = np.array([0.0, 0.0, -ground]), time.monotonic()
    feeding = {"on": True}

    async def drive():
        for delay, changes in steps:
            end = time.monotonic() + delay
            while time.monotonic() < end:
                if feeding["on"]:
                    vehicle.received_at = time.monotonic()
                await asyncio.sleep(0.01)
            if "height" in changes:
                vehicle.position_ned = np.array([0.0, 0.0, -changes["height"]])
            if "mode" in changes:
                vehicle.flight_mode = getattr(FlightMode, changes["mode"])
            if "armed" in changes:
                vehicle.armed = changes["armed"]
            if "position" in changes:
                feeding["on"] = changes["position"]
        while True:
            if feeding["on"]:
                vehicle.received_at = time.monotonic()
            await asyncio.sleep(0.01)

    async def run():
        driver = asyncio.create_task(drive())
        try:
            return await _watch_take_off(flight)
        finally:
            driver.cancel()

    return asyncio.run(run())


CLIMB = [
    (0.0, {"mode": "HOLD"}),
    (0.1, {"armed": True}),
    (0.1, {"mode": "TAKEOFF", "height": 1.0}),
    (0.1, {"height": 3.0}),
]


@pytest.mark.parametrize(
    ("then", "outcome"),
    [
        ([(0.1, {"height": 9.9}), (0.2, {"mode": "HOLD"})], None),
        ([(0.1, {"height": 8.5}), (0.1, {"mode": "HOLD"})], "left TAKEOFF for HOLD at 8.5 m"),
        ([(0.1, {"armed": False})], "the vehicle disarmed at 3.0 m of 10 m"),
        ([(0.1, {"mode": "LAND"})], "the vehicle left TAKEOFF for LAND at 3.0 m"),
        ([(0.1, {"mode": "POSCTL"})], "the vehicle left TAKEOFF for POSCTL at 3.0 m"),
        ([(0.1, {"position": False})], "no position from the vehicle for 0.5 s at 3.0 m"),
        ([], "did not end its take-off at 10 m within 2 s (it reports TAKEOFF"),
    ],
)
def test_a_take_off_is_done_on_takeoff_to_hold_at_the_altitude_and_fails_at_once(
    flight_scenario, then, outcome
):
    """The take-off is watched: done when TAKEOFF ends in HOLD within 1 m of the altitude;
    a disarm, another mode, a lost position end it at once, the timeout last."""
    from hptrack.runtime.mavsdk_adapter import TAKEOFF_DONE_TOLERANCE_M

    assert TAKEOFF_DONE_TOLERANCE_M == 1.0
    flight = _flight(flight_scenario, altitude_m=10.0, lost_link_s=0.5, takeoff_timeout_s=2.0)
    result = _take_off_with(flight, CLIMB + then)
    if outcome is None:
        assert result is None
    else:
        assert outcome in result, result


@pytest.mark.parametrize(
    ("ground", "hold_at", "outcome"),
    [
        (-0.8, 8.5, None),  # PX4 took off from 0.8 m below its local origin, 9.3 m up
        (0.8, 9.5, "left TAKEOFF for HOLD at 9.5 m"),  # 8.7 m above where it began
    ],
)
def test_a_take_off_is_measured_from_where_it_began(flight_scenario, ground, hold_at, outcome):
    """PX4 takes off to the altitude above its home (where it armed), not above its local
    origin: PX4 SIH once armed low enough to end its take-off 18.9 m above the origin, 1.1 m
    below a 20 m mission altitude, and the flight was refused as a failed take-off."""
    flight = _flight(flight_scenario, altitude_m=10.0, lost_link_s=0.5, takeoff_timeout_s=2.0)
    climb = [(0.0, {"mode": "HOLD"}), (0.1, {"armed": True}), (0.1, {"mode": "TAKEOFF"})]
    climb += [(0.1, {"height": hold_at}), (0.1, {"mode": "HOLD"})]
    result = _take_off_with(flight, climb, ground=ground)
    if outcome is None:
        assert result is None
    else:
        assert outcome in result, result


def test_hold_before_the_take_off_began_is_not_its_end(flight_scenario):
    """HOLD seen before TAKEOFF (the mode before the command) and low is no failure."""
    flight = _flight(flight_scenario, altitude_m=5.0, takeoff_timeout_s=5.0)
    steps = [(0.0, {"mode": "HOLD", "armed": True}), (0.3, {"height": 0.5})]
    steps += [(0.2, {"mode": "TAKEOFF"}), (0.2, {"height": 5.0}), (0.1, {"mode": "HOLD"})]
    assert _take_off_with(flight, steps) is None


def test_a_vehicle_that_does_not_move_towards_its_reference_is_warned_of_rate_limited(
    flight_scenario,
):
    from hptrack.runtime.mavsdk_adapter import (
        FOLLOW_CLOSING_M_S,
        FOLLOW_DISTANCE_M,
        FOLLOW_PERSIST_S,
        FOLLOW_WARN_EVERY_S,
    )

    messages = []
    flight = _flight(flight_scenario, messages)
    flight.vehicle.position_ned = np.zeros(3)
    flight.mono0 = time.monotonic()
    reference = np.array([FOLLOW_DISTANCE_M + 2.0, 0.0])  # east of the vehicle
    # still, then closing just under the limit (north-east-down: east is the second axis)
    for k in range(80):  # 0 to 19.75 s
        flight.vehicle.velocity_ned = np.array([0.0, FOLLOW_CLOSING_M_S * 0.99 * (k > 40), 0])
        flight.check_following(k * 0.25, reference)
    warnings = [r for r in _said(flight, "status") if r.get("warning") == "not following"]
    # at 3 s (persisted), then at 13 s (10 s later), not in between
    assert [r["distance_m"] for r in warnings] == [FOLLOW_DISTANCE_M + 2.0] * 2
    assert [round(m.split("for ")[1].split(" s")[0] == "3.0") for m in messages] == [1, 0]
    assert FOLLOW_PERSIST_S == 3.0 and FOLLOW_WARN_EVERY_S == 10.0
    assert flight.follow_warnings == 2 and "not moving towards its reference" in messages[0]
    # closing fast enough, or near enough: no warning, and the persistence restarts
    for k in range(40):
        flight.vehicle.velocity_ned = np.array([0.0, FOLLOW_CLOSING_M_S, 0.0])
        flight.check_following(20.0 + k * 0.25, reference)
        flight.vehicle.velocity_ned = np.zeros(3)
        flight.check_following(20.0 + k * 0.25, np.array([FOLLOW_DISTANCE_M, 0.0]))
    assert flight.follow_warnings == 2 and flight.not_following_since is None


def test_odometry_from_another_source_is_counted_and_said_once(flight_scenario):
    messages = []
    flight = _flight(flight_scenario, messages)
    flight.system_id, flight.component_id = 1, 1
    for _ in range(3):
        flight.refuse_source(2, 1)
    flight.refuse_source(1, 42)
    assert flight.foreign == {"system 2 component 1": 3, "system 1 component 42": 1}
    assert (
        len(messages) == 2
        and "refusing odometry from MAVLink system 2 component 1" in (messages[0])
    )
    assert [(r["system_id"], r["component_id"]) for r in _said(flight, "foreign")] == [
        (2, 1),
        (1, 42),
    ]
