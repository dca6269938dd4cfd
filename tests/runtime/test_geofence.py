"""The fence on the vehicle: the local frame to latitude and longitude and back, the comparison
of the vehicle's fence with the scenario's, the stub's fence protocol through MAVSDK (upload,
download, clear, ``GF_ACTION``), its breach actions, and the controller's setpoints kept in the
free space."""

import asyncio
import math
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pymavlink")

from hptrack.interface import CurrentPlan, InputError  # noqa: E402
from hptrack.models.fence import point_free  # noqa: E402
from hptrack.runtime.controller import MissionController  # noqa: E402
from hptrack.runtime.frames import EARTH_RADIUS_M, geodetic_to_local, local_to_geodetic  # noqa: E402
from hptrack.runtime.geofence import (  # noqa: E402
    fence_block,
    fence_difference,
    from_geodetic,
    to_geodetic,
)
from hptrack.runtime.legs import tracking_lag_m  # noqa: E402
from hptrack.runtime.log import MissionLog  # noqa: E402
from hptrack.runtime.vehicle_sim import Misbehaviour, VehicleSim  # noqa: E402
from hptrack.runtime.worker import InlineRunner  # noqa: E402
from hptrack.scenario import load_scenario  # noqa: E402
from hptrack.settings import NoSettings  # noqa: E402

FENCED = Path(__file__).resolve().parents[2] / "examples" / "fenced-flight.yaml"
ORIGIN = (47.397742, 8.545594)


@pytest.fixture
def fenced():
    return load_scenario(FENCED)


def test_a_metre_north_is_one_earth_radius_in_radians_and_the_frames_round_trip():
    lat, lon = local_to_geodetic(*ORIGIN, 1.0, 0.0)
    assert lat - ORIGIN[0] == pytest.approx(math.degrees(1.0 / EARTH_RADIUS_M), rel=1e-9)
    assert lon == ORIGIN[1]
    lat, lon = local_to_geodetic(*ORIGIN, 0.0, 1.0)
    east = math.degrees(1.0 / (EARTH_RADIUS_M * math.cos(math.radians(ORIGIN[0]))))
    assert lon - ORIGIN[1] == pytest.approx(east, rel=1e-9)
    for north, east in [(250.0, -1800.0), (-3.5, 0.25)]:
        back = geodetic_to_local(*ORIGIN, *local_to_geodetic(*ORIGIN, north, east))
        np.testing.assert_allclose(back, (north, east), atol=1e-9)


def test_the_fence_round_trips_through_latitude_and_longitude(fenced):
    spec = fenced.fence.spec()
    zones = to_geodetic(spec, ORIGIN)
    assert [(z.inclusion, len(z.points), z.radius_m) for z in zones] == [
        (True, 4, None),
        (False, 4, None),
        (False, 1, 8.0),
    ]
    back = from_geodetic(zones, ORIGIN, spec.margin)
    assert fence_difference(spec, back, tolerance_m=1e-6) is None
    assert back.margin == 5.0
    assert load_scenario(FENCED).fence.spec() == spec
    assert fence_block(spec)["exclusions"][1] == {"circle": [60.0, -28.0, 8.0]}


def test_a_fence_that_differs_is_told_by_its_first_difference(fenced):
    spec = fenced.fence.spec()
    moved = spec._replace(polygons=(tuple((x, y + 0.3) for x, y in spec.polygons[0]),))
    assert fence_difference(spec, moved) == (
        "exclusion polygon 0 corner 0: 0.30 m apart (tolerance 0.1 m)"
    )
    assert fence_difference(spec, moved, tolerance_m=0.31) is None
    assert fence_difference(spec, spec._replace(circles=())) == (
        "the vehicle holds 0 exclusion circles, the scenario 1"
    )
    assert fence_difference(spec, spec._replace(inclusion=None)) == (
        "the vehicle's fence has no inclusion polygon, the scenario's has one"
    )
    wider = spec._replace(circles=((60.0, -28.0, 8.5),))
    assert "exclusion circle 0: 0.50 m apart" in fence_difference(spec, wider)


def test_the_lag_of_px4s_0_8_tracking_at_8_m_s_is_2_1_m():
    assert tracking_lag_m(8.0, 0.8, 0.95) == pytest.approx(0.25 * 8.0 / 0.95, rel=1e-12)
    assert tracking_lag_m(8.0, 1.0, 0.95) == 0.0


# --- the stub's fence protocol through MAVSDK ----------------------------------------------


def _free_port():
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _with_stub(scenario, body, options, misbehaviour=None, hold=False):
    """Run the stub in a thread and ``body(flight, system, vehicle)`` against it through
    MAVSDK with flight ``options``; returns what ``body`` returns."""
    pytest.importorskip("mavsdk")
    import threading

    from mavsdk.asyncio import ComponentType, Configuration, Mavsdk

    from hptrack.runtime.mavsdk_adapter import _Flight

    port = _free_port()
    vehicle = VehicleSim(scenario, f"udpout://127.0.0.1:{port}", None, misbehaviour=misbehaviour)
    if hold:
        vehicle.hold_fence(scenario.fence.spec())
    stop = threading.Event()
    thread = threading.Thread(target=vehicle.run, args=(60.0, stop))
    thread.start()

    async def main():
        config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
        async with Mavsdk(config) as mavsdk:
            await mavsdk.add_any_connection(f"udpin://127.0.0.1:{port}")
            system = await mavsdk.first_autopilot(timeout_s=10)
            flight = _Flight(
                None, options, lambda s: None, lambda m: None, asyncio.Event(), MissionLog()
            )
            return await body(flight, system, vehicle)

    try:
        return asyncio.run(main())
    finally:
        stop.set()
        thread.join(5.0)


def test_the_fence_uploads_reads_back_sets_gf_action_and_clears_through_mavsdk(fenced):
    from mavsdk.asyncio.plugins.geofence import GeofenceAsync
    from mavsdk.asyncio.plugins.param import ParamAsync

    from hptrack.runtime.mavsdk_adapter import FlightOptions, _zones, sync_fence

    async def body(flight, system, vehicle):
        flown = await sync_fence(flight, system, fenced.fence.spec())
        held = list(vehicle.fence)
        gf_action = await ParamAsync(system).get_param_int("GF_ACTION")
        await GeofenceAsync(system).clear_geofence()
        after_clear = _zones(await GeofenceAsync(system).download_geofence())
        return flown, held, gf_action, vehicle.fence, after_clear, flight.early

    flown, held, gf_action, cleared, downloaded, said = _with_stub(
        fenced, body, FlightOptions(fence_action=3)
    )
    spec = fenced.fence.spec()
    assert flown == spec  # the scenario's own fence is flown once the vehicle holds it
    # the stub holds it within a centimetre (MAVLink's 1e-7 degree)
    back = from_geodetic(held, ORIGIN, spec.margin)
    assert fence_difference(spec, back, tolerance_m=0.012) is None
    assert fence_difference(spec, back, tolerance_m=1e-4) is not None  # it went through MAVLink
    assert gf_action == 3 and cleared == [] and downloaded == []
    record = next(r for r in said if r["kind"] == "geofence")
    assert record["source"] == "scenario" and record["action"] == 3
    assert record["message"].startswith(
        "fence: the scenario's, uploaded and read back (within 0.1 m), an inclusion polygon, "
        "1 exclusion polygon, 1 exclusion circle; GF_ACTION 3 (return) on a breach"
    )


def test_a_vehicle_that_keeps_another_fence_is_refused_and_its_own_can_be_flown(fenced):
    from hptrack.runtime.mavsdk_adapter import FlightOptions, sync_fence

    async def body(flight, system, vehicle):
        try:
            await sync_fence(flight, system, fenced.fence.spec())
        except InputError as err:
            return str(err)
        return None

    message = _with_stub(fenced, body, FlightOptions(), Misbehaviour(fence_shift_m=0.5))
    assert message.startswith(
        "the vehicle's fence differs from the scenario's after the upload: inclusion corner 0: "
        "0.50 m apart (tolerance 0.1 m); nothing was flown"
    ), message

    async def own(flight, system, vehicle):
        return await sync_fence(flight, system, fenced.fence.spec())

    flown = _with_stub(
        fenced,
        own,
        FlightOptions(fence_from_vehicle=True),
        Misbehaviour(fence_shift_m=0.5),
        hold=True,
    )
    spec = fenced.fence.spec()
    moved = spec._replace(
        inclusion=tuple((x, y + 0.5) for x, y in spec.inclusion),
        polygons=(tuple((x, y + 0.5) for x, y in spec.polygons[0]),),
        circles=((60.0, -27.5, 8.0),),
    )
    assert fence_difference(moved, flown, tolerance_m=0.012) is None
    assert flown.margin == spec.margin


# --- breaches -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("action", "name", "mode", "armed"),
    [
        (0, "none", "offboard", True),
        (1, "warning", "offboard", True),
        (2, "hold", "hold", True),
        (3, "return", "rtl", True),
        (4, "terminate", "offboard", False),
        (5, "land", "land", True),
    ],
)
def test_a_breach_does_gf_action_once_where_the_vehicle_crosses_the_fence(
    fenced, action, name, mode, armed
):
    said = []
    vehicle = VehicleSim(
        fenced, detections_url=None, parameters={"GF_ACTION": action}, on_event=said.append
    )
    try:
        vehicle.hold_fence(fenced.fence.spec())
        clock = [0.0]
        vehicle._now = lambda: clock[0]
        vehicle.armed = True
        vehicle.position[2] = -10.0
        vehicle._set_mode("offboard")
        crossed = None
        for _ in range(300):  # 3 s east at y = 5 m into the no-fly square (x from 12 m)
            clock[0] += 0.01
            vehicle._target = np.array([5.0, 30.0, -10.0])
            vehicle._last_setpoint = clock[0]
            vehicle._fly(0.01)
            if crossed is None and vehicle.outside_fence():
                crossed = vehicle.position[1]
        assert vehicle.stats.fence_breaches[0][1] == name
        assert len(vehicle.stats.fence_breaches) == 1
        assert crossed is not None and 12.0 < crossed < 12.0 + 10.0 * 0.01  # one step in
        assert vehicle.mode == mode and vehicle.armed is armed
        assert any(f"geofence breached: GF_ACTION {action} ({name})" in s for s in said)
    finally:
        vehicle.close()


def test_no_fence_no_breach(fenced):
    vehicle = VehicleSim(fenced, detections_url=None)
    try:
        vehicle.position[:2] = [5.0, 16.0]  # inside the square, no fence held
        vehicle.armed = True
        vehicle.position[2] = -10.0
        assert not vehicle.outside_fence()
        vehicle.hold_fence(fenced.fence.spec())
        assert vehicle.outside_fence()
        vehicle.position[:2] = [-100.0, 0.0]  # 100 m south: outside the operating area
        assert vehicle.outside_fence()
        vehicle.position[:2] = [-28.0, 60.0]  # the circle's centre
        assert vehicle.outside_fence()
        vehicle.position[:2] = [-28.0, 68.5]  # 0.5 m outside the circle
        assert not vehicle.outside_fence()
    finally:
        vehicle.close()


# --- the controller keeps its setpoints inside --------------------------------------------


class _Into:
    """Flies at a fixed waypoint (inside the no-fly square)."""

    name = "stationary"
    settings = NoSettings()

    def current_plan(self):
        return CurrentPlan()

    def reset(self, mission, observation, rng):
        pass

    def act(self, observation):
        return np.array([16.0, 8.0])

    def episode_info(self):
        return {}


def test_every_reference_outside_the_free_space_is_projected_onto_it_and_logged(fenced):
    ctrl = MissionController(fenced, _Into(), runner=InlineRunner())
    fence = fenced.fence.spec().compiled()
    sent = []
    for i in range(60):
        t = 0.05 * i
        ctrl.odometry(t, [0.3 * i, 0.1 * i] if i < 20 else [6.0, 2.0])
        sent.append(ctrl.setpoint(t))
    inside = [point_free(fence, *s.reference) for s in sent]
    assert all(inside)
    projections = [r for r in ctrl.log.records if r["kind"] == "fence"]
    assert len(projections) == ctrl.fence_projections > 0
    for record in projections:
        reference, projected = np.array(record["reference"]), np.array(record["projected"])
        assert not point_free(fence, *reference) and point_free(fence, *projected)
    # a projected reference carries no feed-forward (it would push into the zone)
    projected = {tuple(r["projected"]) for r in projections}
    assert all(not np.any(s.velocity) for s in sent if tuple(s.reference) in projected)
    status = ctrl.status()["fence"]
    assert status["margin_m"] == 5.0 and status["projections"] == ctrl.fence_projections


def test_a_scenario_without_a_fence_sends_its_references_as_they_are(flight_scenario):
    ctrl = MissionController(flight_scenario, _Into(), runner=InlineRunner())
    for i in range(20):
        ctrl.odometry(0.05 * i, [0.0, 0.0])
        ctrl.setpoint(0.05 * i)
    assert ctrl.fence_projections == 0 and ctrl.status()["fence"] is None
    assert not [r for r in ctrl.log.records if r["kind"] == "fence"]


def test_the_margin_is_said_beside_the_lag_and_a_margin_below_it_warned_of(fenced):
    from hptrack.runtime.mavsdk_adapter import FlightOptions, say_fence_margin

    async def body(flight, system, vehicle):
        await say_fence_margin(flight, system, 8.0, 5.0)
        await say_fence_margin(flight, system, 8.0, 1.0)
        return [r["message"] for r in flight.early]

    said = _with_stub(fenced, body, FlightOptions())
    assert said == [
        "fence margin 5 m; tracking lag at 8 m/s 2.1 m (PX4 flies 0.8 of its velocity setpoint, "
        "MPC_XY_P 0.95 1/s)",
        "fence margin 1 m; tracking lag at 8 m/s 2.1 m (PX4 flies 0.8 of its velocity setpoint, "
        "MPC_XY_P 0.95 1/s); the margin is below the lag: the vehicle may fly up to 1.1 m past "
        "the fence",
    ]
