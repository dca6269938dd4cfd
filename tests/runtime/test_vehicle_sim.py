"""The vehicle stub speaks PX4's protocol: a test plays the ground station with pymavlink."""

import json
import socket
import threading
import time

import numpy as np
import pytest

pytest.importorskip("pymavlink")
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from hptrack.interface import InputError  # noqa: E402
from hptrack.runtime.network import udp_address  # noqa: E402
from hptrack.runtime.vehicle_sim import PX4_AUTO_SUB_MODE, PX4_MAIN_MODE, VehicleSim  # noqa: E402


def _udp_socket():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    return sock


class GroundStation:
    """A minimal MAVLink peer on a loopback port."""

    def __init__(self):
        self.sock = _udp_socket()
        self.port = self.sock.getsockname()[1]
        self.peer = None
        self.mav = mavlink.MAVLink(self, srcSystem=255, srcComponent=190)
        self.messages = []

    def write(self, buffer):
        self.sock.sendto(buffer, self.peer)

    def pump(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data, self.peer = self.sock.recvfrom(65535)
            except TimeoutError:
                continue
            self.messages.extend(self.mav.parse_buffer(data) or [])

    def wait(self, predicate, seconds=3.0):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for msg in self.messages:
                if predicate(msg):
                    return msg
            self.pump(0.05)
        raise AssertionError("no matching message")

    def command(self, command, *params):
        self.messages.clear()
        params = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(1, 1, command, 0, *params)
        ack = self.wait(lambda m: m.get_type() == "COMMAND_ACK" and m.command == command)
        return ack.result


def _heartbeat(gcs):
    gcs.messages.clear()
    return gcs.wait(lambda m: m.get_type() == "HEARTBEAT", seconds=2.5)


def test_loopback_addresses_only(flight_scenario):
    with pytest.raises(InputError, match="loopback"):
        VehicleSim(flight_scenario, "udpout://192.168.1.5:14540")
    with pytest.raises(InputError, match="loopback"):
        VehicleSim(flight_scenario, detections_url="udp://example.com:5005")
    assert udp_address("udp://localhost:5005", "--x", loopback_only=True) == ("127.0.0.1", 5005)
    with pytest.raises(InputError, match="expected udp://HOST:PORT"):
        udp_address("tcp://127.0.0.1:1", "--x")


def test_the_stub_arms_takes_off_flies_offboard_and_detects(flight_scenario):
    gcs = GroundStation()
    detector = _udp_socket()
    vehicle = VehicleSim(
        flight_scenario,
        f"udpout://127.0.0.1:{gcs.port}",
        f"udp://127.0.0.1:{detector.getsockname()[1]}",
        climb_rate_m_s=10.0,
    )
    stop = threading.Event()
    result = {}
    thread = threading.Thread(target=lambda: result.update(vehicle.run(20.0, stop)))
    thread.start()
    try:
        beat = _heartbeat(gcs)
        assert (beat.type, beat.autopilot) == (
            mavlink.MAV_TYPE_QUADROTOR,
            mavlink.MAV_AUTOPILOT_PX4,
        )
        assert not beat.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        assert gcs.command(mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mavlink.MAV_RESULT_ACCEPTED
        assert _heartbeat(gcs).base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        assert gcs.command(mavlink.MAV_CMD_NAV_TAKEOFF) == mavlink.MAV_RESULT_ACCEPTED
        gcs.wait(lambda m: m.get_type() == "LOCAL_POSITION_NED" and m.z < -2.4)
        offboard = (
            mavlink.MAV_CMD_DO_SET_MODE,
            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            PX4_MAIN_MODE["offboard"],
        )
        assert gcs.command(*offboard) == mavlink.MAV_RESULT_DENIED  # no setpoints yet
        start = time.monotonic()

        def stream(seconds):
            # north, east, down: chase target p1 (x = 30 + 3 t east, y = 10 north)
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                east = 30.0 + 3.0 * (time.monotonic() - start)
                gcs.mav.set_position_target_local_ned_send(
                    0,
                    1,
                    1,
                    mavlink.MAV_FRAME_LOCAL_NED,
                    0b110111111000,
                    10.0,
                    east,
                    -2.5,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                    0,
                )
                gcs.pump(0.05)

        stream(0.3)
        assert gcs.command(*offboard) == mavlink.MAV_RESULT_ACCEPTED
        start = time.monotonic()
        beat = _heartbeat(gcs)
        assert beat.custom_mode >> 16 & 0xFF == PX4_MAIN_MODE["offboard"]
        stream(1.0)
        gcs.messages.clear()
        position = gcs.wait(lambda m: m.get_type() == "LOCAL_POSITION_NED")
        travelled = np.hypot(position.x, position.y)  # at 8 m/s, the scenario's speed
        assert travelled == pytest.approx(8.0 * (time.monotonic() - start), rel=0.15)
        stream(3.5)
        lines = []
        detector.settimeout(1.0)
        while True:
            try:
                lines += detector.recvfrom(65535)[0].decode().splitlines()
            except TimeoutError:
                break
        seen = [json.loads(line) for line in lines]
        assert seen and {d["id"] for d in seen} == {"p1"}
        assert all(abs(d["t"] - time.time()) < 10 for d in seen)
        hold = (
            mavlink.MAV_CMD_DO_SET_MODE,
            mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
            PX4_MAIN_MODE["auto"],
            PX4_AUTO_SUB_MODE["hold"],
        )
        assert gcs.command(*hold) == mavlink.MAV_RESULT_ACCEPTED
    finally:
        stop.set()
        thread.join(5.0)
        gcs.sock.close()
        detector.close()
    assert result["final_mode"] == "hold"
    assert [m["mode"] for m in result["modes"]] == ["hold", "takeoff", "hold", "offboard", "hold"]
    assert result["offboard_setpoints"] > 50 and result["max_speed_m_s"] <= 8.0 + 1e-9
