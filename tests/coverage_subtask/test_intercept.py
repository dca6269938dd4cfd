"""Planning the intercept flight of a coverage sub-task (paper Sec. IV-C)."""

import math

import numpy as np
import pytest

from hptrack.coverage.intercept import intercept_path, intercept_waypoint, plan_intercept
from hptrack.interface import MissionSpec
from hptrack.models.mission import intercept_steps_to

RECORD = MissionSpec().record
"""The paper's constants: tau 0.5 s, v_a 30 m/s, w 100 m."""


def state(position, velocity):
    return np.array([*position, *velocity], dtype=float)


def test_wrapper_names_the_speeds():
    with pytest.raises(ValueError, match=r"speed 30\.5 m/s is not below the agent speed 30 m/s"):
        plan_intercept(RECORD, np.zeros(2), state([500.0, 0.0], [30.5, 0.0]))


@pytest.mark.parametrize(
    ("agent", "mean"),
    [
        (np.array([np.nan, 0.0]), state([800.0, 0.0], [1.0, 1.0])),
        (np.zeros(3), state([800.0, 0.0], [1.0, 1.0])),
        (np.zeros(2), np.array([800.0, 0.0, 1.0])),
        (np.zeros(2), state([800.0, 0.0], [math.inf, 1.0])),
    ],
)
def test_bad_inputs_are_rejected(agent, mean):
    with pytest.raises(ValueError):
        plan_intercept(RECORD, agent, mean)


def test_whole_steps_round_up_but_not_an_exact_multiple():
    exact = plan_intercept(RECORD, np.zeros(2), state([150.0, 0.0], [0.0, 0.0]))
    assert exact.time == pytest.approx(5.0) and exact.steps == 10
    late = plan_intercept(RECORD, np.zeros(2), state([151.0, 0.0], [0.0, 0.0]))
    assert late.steps == 11 and late.duration == 5.5


def test_mean_inside_the_footprint_starts_coverage_at_once():
    agent = np.array([10.0, -20.0])
    plan = plan_intercept(RECORD, agent, state(agent + [30.0, 39.0], [2.0, 2.0]))
    assert plan.steps == 0 and plan.time == 0.0
    np.testing.assert_array_equal(plan.start, agent)


@pytest.mark.parametrize("seed", range(5))
def test_path_flies_straight_at_full_speed_and_meets_the_mean(seed):
    rng = np.random.default_rng(seed)
    agent, mean = rng.uniform(-1000, 1000, 2), rng.uniform(-1000, 1000, 2)
    velocity = rng.uniform(-3, 3, 2)
    plan = plan_intercept(RECORD, agent, state(mean, velocity))
    assert plan.steps == intercept_steps_to(RECORD, *agent, state(mean, velocity))
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
    plan = plan_intercept(RECORD, agent, state([700.0, 400.0], [1.5, -2.0]))
    whole = intercept_path(agent, plan, 15.0)
    chosen = np.array([0, 3, plan.steps - 1, plan.steps, plan.steps + 40])
    got = intercept_path(agent, plan, 15.0, chosen)
    np.testing.assert_array_equal(got[:4], whole[chosen[:4]])
    np.testing.assert_array_equal(got[4], plan.start)  # after arrival it stays at the start
    for j in chosen:
        np.testing.assert_array_equal(
            intercept_waypoint(agent, plan, 15.0, int(j)), got[list(chosen).index(j)]
        )
    at_once = plan_intercept(RECORD, agent, state(agent + [10.0, 0.0], [0.0, 0.0]))
    np.testing.assert_array_equal(intercept_path(agent, at_once, 15.0, np.arange(3)), [agent] * 3)
