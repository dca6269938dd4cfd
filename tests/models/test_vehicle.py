"""The holonomic vehicle's closed-form intercept (paper Sec. IV-C) and its move."""

import math

import numba
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.interface import MissionSpec
from hptrack.models.mission import intercept_flight, intercept_steps, intercept_steps_to
from hptrack.models.vehicle import (
    HolonomicVehicle,
    intercept_time,
    move_towards,
    reach_times,
    vehicle_intercept_time,
    vehicle_move,
)

RECORD = MissionSpec().record
"""The paper's constants: tau 0.5 s, v_a 30 m/s, w 100 m."""

coord = st.floats(-2000.0, 2000.0)
vel = st.floats(-20.0, 20.0)


@settings(max_examples=300, deadline=None)
@given(coord, coord, coord, coord, vel, vel)
def test_closed_form_is_the_smallest_catching_time(ax, ay, mx, my, vx, vy):
    speed = 30.0
    t = intercept_time(ax, ay, mx, my, vx, vy, speed)
    assert t >= 0.0
    gap = math.hypot(mx + vx * t - ax, my + vy * t - ay)
    assert gap == pytest.approx(speed * t, rel=1e-9, abs=1e-9)
    # Before t the mean is still out of reach (|d + v s| - v_a s decreases in s).
    for s in np.linspace(0.0, t, 20)[:-1]:
        assert math.hypot(mx + vx * s - ax, my + vy * s - ay) > speed * s - 1e-9


def test_static_target_and_agent_on_mean():
    assert intercept_time(0.0, 0.0, 300.0, 400.0, 0.0, 0.0, 25.0) == pytest.approx(20.0)
    assert intercept_time(5.0, 5.0, 5.0, 5.0, 3.0, -1.0, 30.0) == 0.0


def test_head_on_and_receding_targets():
    # Target 600 m ahead coming at 10 m/s: closing speed 40 m/s; receding: 20 m/s.
    assert intercept_time(0.0, 0.0, 600.0, 0.0, -10.0, 0.0, 30.0) == pytest.approx(15.0)
    assert intercept_time(0.0, 0.0, 600.0, 0.0, 10.0, 0.0, 30.0) == pytest.approx(30.0)


def test_kernel_flags_a_target_not_slower_than_the_agent():
    assert math.isinf(intercept_time(0.0, 0.0, 100.0, 0.0, 30.0, 0.0, 30.0))
    assert intercept_steps(RECORD, 0.0, 0.0, 500.0, 0.0, 0.0, 31.0) == -1
    assert intercept_flight(RECORD, 0.0, 0.0, 500.0, 0.0, 0.0, 31.0) == (math.inf, -1)


def test_whole_steps_round_up_except_an_exact_multiple():
    # 150 m to a static mean at 30 m/s: 5 s, exactly 10 steps of 0.5 s; 151 m: 11 steps
    assert intercept_flight(RECORD, 0.0, 0.0, 150.0, 0.0, 0.0, 0.0) == (pytest.approx(5.0), 10)
    assert intercept_steps(RECORD, 0.0, 0.0, 151.0, 0.0, 0.0, 0.0) == 11


def test_a_mean_the_sensor_measures_is_reached_at_once():
    # 50 m is on the footprint's edge (w/2); from 50.01 m the flight goes to the mean itself:
    # 50.01 m at 30 m/s, 1.667 s, 4 steps of 0.5 s
    assert intercept_flight(RECORD, 0.0, 0.0, 30.0, 40.0, 29.0, 0.0) == (0.0, 0)
    assert intercept_steps(RECORD, 0.0, 0.0, 50.01, 0.0, 0.0, 0.0) == 4
    mean = np.array([30.0, 39.0, 2.0, 2.0])
    assert intercept_steps_to(RECORD, 0.0, 0.0, mean) == 0


@numba.njit
def _dispatched(vehicle, agent, waypoint, ax, ay, x, y, vx, vy):
    vehicle_move(vehicle, agent, waypoint)
    return vehicle_intercept_time(vehicle, ax, ay, x, y, vx, vy)


def test_the_registered_kernels_are_the_holonomic_point():
    vehicle = HolonomicVehicle(30.0, 15.0)
    agent = np.zeros(2)
    t = _dispatched(vehicle, agent, np.array([300.0, 400.0]), 0.0, 0.0, 600.0, 0.0, -10.0, 0.0)
    assert t == intercept_time(0.0, 0.0, 600.0, 0.0, -10.0, 0.0, 30.0) == pytest.approx(15.0)
    np.testing.assert_allclose(agent, [9.0, 12.0], rtol=1e-15)  # 15 m towards (300, 400)
    np.testing.assert_array_equal(move_towards([0.0, 0.0], [3.0, 4.0], 15.0), [3.0, 4.0])


@pytest.mark.parametrize(
    ("state", "expected"),
    [
        ((300.0, 0.0, 0.0, 0.0), 250.0 / 30.0),  # static: fly to the footprint's edge
        ((300.0, 0.0, 10.0, 0.0), 250.0 / 20.0),  # running away at 10 m/s
        ((300.0, 0.0, -10.0, 0.0), 250.0 / 40.0),  # coming closer
        ((0.0, 40.0, 0.0, 0.0), 0.0),  # already inside the footprint
        ((300.0, 0.0, 40.0, 0.0), math.inf),  # faster than the agent
    ],
)
def test_reach_times_are_the_earliest_arrivals_at_the_footprints_edge(state, expected):
    states = np.array([state])
    t = reach_times(RECORD.vehicle, np.zeros(2), states[:, :2], states[:, 2:], 50.0)[0]
    assert t == pytest.approx(expected, rel=1e-12)
