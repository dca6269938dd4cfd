"""Motion primitives and the step-level planner base (plan -> per-step waypoints)."""

import math

import numpy as np
import pytest

from hptrack.baselines.arvi import ArviPlanner, ArviSettings
from hptrack.baselines.astar import AStarSettings
from hptrack.baselines.controls import (
    HOVER,
    DecisionStats,
    PrimitivePlanner,
    PrimitiveSettings,
    step_directions,
)
from hptrack.interface import InputError
from hptrack.registry import make_planner


def test_control_set_is_hover_then_eight_headings_counter_clockwise_from_east():
    d = step_directions(8)
    s = math.sqrt(0.5)
    expected = [[0, 0], [1, 0], [s, s], [0, 1], [-s, s], [-1, 0], [-s, -s], [0, -1], [s, -s]]
    np.testing.assert_allclose(d, expected, atol=1e-15)
    assert HOVER == 0


class FixedPlan(PrimitivePlanner):
    """Returns [east, north, west] at every search and counts the searches."""

    name = "fixed"

    def search(self, observation):
        return np.array([1, 3, 5]), DecisionStats(observation.step, 0.0, 0, 1, False, 0.0)


def fly(planner, mission, observation, n_steps):
    """Apply the waypoints as the simulator does when they are one full step away."""
    position = np.zeros(2)
    planner.reset(mission, observation(position, 0), np.random.default_rng(0))
    path = [position]
    for k in range(n_steps):
        waypoint = planner.act(observation(position, k))
        assert np.hypot(*(waypoint - position)) <= mission.step_length + 1e-12
        position = waypoint
        path.append(position)
    return np.array(path)


@pytest.mark.parametrize(
    ("replan_period", "searches"), [(1, [0, 2, 4, 6]), (2, [0, 4]), (3, [0, 6])]
)
def test_plans_are_flown_primitive_by_primitive_and_replanned_on_schedule(
    make_mission, make_observation, replan_period, searches
):
    mission = make_mission(1)
    planner = FixedPlan(PrimitiveSettings(control_steps=2, replan_period=replan_period))

    def observation(position, k):
        return make_observation([[5000.0, 0.0, 0.0, 0.0]], agent=position, step=k)

    path = fly(planner, mission, observation, 8)
    assert [d.step for d in planner.decisions] == searches
    plans = {1: "EEEEEEEE", 2: "EENNEENN", 3: "EENNWWEE"}[replan_period]
    moves = {"E": (15.0, 0.0), "N": (0.0, 15.0), "W": (-15.0, 0.0)}
    np.testing.assert_allclose(np.diff(path, axis=0), [moves[m] for m in plans], atol=1e-12)
    assert all(d.planning_time_s >= 0.0 for d in planner.decisions)


def test_horizon_is_cut_to_the_primitives_left_in_the_budget(make_mission, make_observation):
    mission = make_mission(1, budget=100.0)  # 200 steps
    planner = ArviPlanner(ArviSettings(horizon=12))
    obs = make_observation([[0.0, 0.0, 0.0, 0.0]], step=0)
    planner.reset(mission, obs, np.random.default_rng(0))
    for step, expected in [(0, 12), (90, 11), (181, 2), (190, 1), (199, 1)]:
        later = make_observation([[0.0, 0.0, 0.0, 0.0]], step=step, budget=100.0)
        assert planner.horizon_primitives(later, 12) == expected
        assert len(planner.search(later)[0]) == expected


def test_options_from_the_command_line_are_parsed_by_field():
    settings = ArviSettings.from_options(
        "arvi",
        {"horizon": "8", "delta_schedule_m": "inf,100", "time_limit_s": "0.5", "cost": "sum"},
    )
    assert settings == ArviSettings(
        horizon=8, delta_schedule_m=(math.inf, 100.0), time_limit_s=0.5, cost="sum"
    )
    # the CLI reads "none" as None before validation (hptrack.cli.common.parse_value)
    assert ArviSettings.from_options("arvi", {"time_limit_s": None}).time_limit_s is None
    yaml_list = ArviSettings.from_options("arvi", {"delta_schedule_m": [math.inf, 100]})
    assert yaml_list.delta_schedule_m == (math.inf, 100.0)
    assert isinstance(yaml_list.delta_schedule_m[1], float)
    assert AStarSettings.from_options("astar", {"max_expansions": 50}).max_expansions == 50
    # the generic --time-limit flag sets ARVI's time_limit_s; ARVI has no notion of iterations
    effort = ArviSettings.effort_options(iterations=100, time_limit=1.5)
    assert effort == {"time_limit_s": 1.5}
    assert make_planner("arvi", effort).settings.time_limit_s == 1.5
    with pytest.raises(InputError, match="planner 'arvi': unknown option horizn"):
        ArviSettings.from_options("arvi", {"horizn": 3})
    with pytest.raises(ValueError, match="epsilon_schedule needs one value or one per delta"):
        ArviSettings(delta_schedule_m=(100.0, 50.0), epsilon_schedule=(1.0, 2.0, 3.0))


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"horizon": "abc"}, "option horizon must be an integer, got 'abc'"),
        ({"horizon": 0}, "option horizon must be >= 1, got 0"),
        ({"control_steps": 2.5}, "option control_steps"),
        ({"delta_schedule_m": "nan"}, "option delta_schedule_m"),
        ({"delta_schedule_m": "100,-1"}, "option delta_schedule_m"),
        ({"time_limit_s": 0}, "option time_limit_s must be > 0"),
        ({"epsilon_schedule": "1,2,3"}, "option epsilon_schedule needs one value or one per"),
    ],
)
def test_bad_options_are_refused_in_one_line_naming_planner_option_and_value(options, message):
    with pytest.raises(InputError, match=f"^planner 'arvi': {message}") as err:
        ArviSettings.from_options("arvi", options)
    assert "\n" not in str(err.value)


def test_settings_are_frozen_and_stored_with_the_episode_info():
    settings = ArviSettings(horizon=3)
    with pytest.raises(ValueError):
        settings.horizon = 4
    planner = ArviPlanner(settings)
    assert planner.settings is settings
    info = planner.episode_info()
    assert info["settings"] == settings.as_json()
    assert info["settings"]["delta_schedule_m"] == ["inf", 150.0, 100.0, 75.0, 50.0]
    assert info["decisions"] == 0
