import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.coverage.intercept import (
    intercept_path,
    intercept_steps,
    intercept_time,
    intercept_waypoint,
    plan_intercept,
)

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
    assert intercept_steps(0.0, 0.0, 500.0, 0.0, 0.0, 31.0, 30.0, 0.5, 50.0) == -1


def test_wrapper_names_the_speeds():
    with pytest.raises(ValueError, match=r"speed 30\.5 m/s is not below the agent speed 30 m/s"):
        plan_intercept(np.zeros(2), np.array([500.0, 0.0]), np.array([30.5, 0.0]), 30.0, 0.5, 100.0)


@pytest.mark.parametrize(
    "bad",
    [
        dict(agent_position=np.array([np.nan, 0.0])),
        dict(mean_velocity=np.array([1.0, 2.0, 3.0])),
        dict(speed=0.0),
        dict(time_step=-0.5),
        dict(sensor_diameter=math.inf),
    ],
)
def test_bad_inputs_are_rejected(bad):
    args = dict(
        agent_position=np.zeros(2),
        mean_position=np.array([800.0, 0.0]),
        mean_velocity=np.array([1.0, 1.0]),
        speed=30.0,
        time_step=0.5,
        sensor_diameter=100.0,
    )
    args.update(bad)
    with pytest.raises(ValueError):
        plan_intercept(**args)


def test_whole_steps_round_up_but_not_an_exact_multiple():
    exact = plan_intercept(np.zeros(2), np.array([150.0, 0.0]), np.zeros(2), 30.0, 0.5, 100.0)
    assert exact.time == pytest.approx(5.0) and exact.steps == 10
    late = plan_intercept(np.zeros(2), np.array([151.0, 0.0]), np.zeros(2), 30.0, 0.5, 100.0)
    assert late.steps == 11 and late.duration == 5.5


def test_mean_inside_the_footprint_starts_coverage_at_once():
    agent = np.array([10.0, -20.0])
    plan = plan_intercept(agent, agent + [30.0, 39.0], np.array([2.0, 2.0]), 30.0, 0.5, 100.0)
    assert plan.steps == 0 and plan.time == 0.0
    np.testing.assert_array_equal(plan.start, agent)
    assert intercept_steps(*agent, *(agent + [30.0, 39.0]), 2.0, 2.0, 30.0, 0.5, 50.0) == 0


@pytest.mark.parametrize("seed", range(5))
def test_path_flies_straight_at_full_speed_and_meets_the_mean(seed):
    rng = np.random.default_rng(seed)
    agent, mean = rng.uniform(-1000, 1000, 2), rng.uniform(-1000, 1000, 2)
    velocity = rng.uniform(-3, 3, 2)
    plan = plan_intercept(agent, mean, velocity, 30.0, 0.5, 100.0)
    assert plan.steps == intercept_steps(*agent, *mean, *velocity, 30.0, 0.5, 50.0)
    np.testing.assert_allclose(plan.start, mean + velocity * plan.steps * 0.5)
    path = intercept_path(agent, plan, 15.0)
    assert path.shape == (plan.steps + 1, 2)
    np.testing.assert_array_equal(path[0], agent)
    np.testing.assert_array_equal(path[-1], plan.start)
    steps = np.hypot(*np.diff(path, axis=0).T)
    assert np.all(steps <= 15.0 * (1 + 1e-12))
    np.testing.assert_allclose(steps[:-1], 15.0, rtol=1e-12)


def test_path_at_chosen_steps_and_single_waypoints_match_the_whole_path():
    agent = np.array([-200.0, 50.0])
    plan = plan_intercept(agent, np.array([700.0, 400.0]), np.array([1.5, -2.0]), 30.0, 0.5, 100.0)
    whole = intercept_path(agent, plan, 15.0)
    chosen = np.array([0, 3, plan.steps - 1, plan.steps, plan.steps + 40])
    got = intercept_path(agent, plan, 15.0, chosen)
    np.testing.assert_array_equal(got[:4], whole[chosen[:4]])
    np.testing.assert_array_equal(got[4], plan.start)  # after arrival it stays at the start
    for j in chosen:
        np.testing.assert_array_equal(
            intercept_waypoint(agent, plan, 15.0, int(j)), got[list(chosen).index(j)]
        )
    at_once = plan_intercept(agent, agent + [10.0, 0.0], np.zeros(2), 30.0, 0.5, 100.0)
    np.testing.assert_array_equal(intercept_path(agent, at_once, 15.0, np.arange(3)), [agent] * 3)
