"""The public API: every name of ``hptrack.__all__`` resolves, ``import hptrack`` stays cheap,
``plan`` returns the planner's own first decision, ``benchmark`` the episodes' own U."""

import subprocess
import sys

import numpy as np
import pytest

import hptrack
from hptrack.interface import InputError
from hptrack.scenario import AgentSpec, Scenario, TargetSpec, random_scenario
from hptrack.sim.episode import run_episode

PRIOR = [[400, 0, 0, 0], [0, 400, 0, 0], [0, 0, 0.25, 0], [0, 0, 0, 0.25]]


def one_target(position=(600.0, 0.0)) -> Scenario:
    target = TargetSpec(id="only", mean=(*position, 0.0, 0.0), covariance=PRIOR, process_noise=1e-4)
    return Scenario(budget=120.0, agent=AgentSpec(), targets=[target])


def test_every_public_name_resolves_and_is_listed():
    assert hptrack.__all__ == sorted(hptrack._EXPORTS)
    for name in hptrack.__all__:
        assert getattr(hptrack, name) is not None
    assert set(hptrack.__all__) <= set(dir(hptrack))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        hptrack.nope  # noqa: B018


def test_import_hptrack_loads_no_numerics():
    code = "import sys, hptrack; print(sorted(m for m in ('numpy', 'numba') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_version_is_the_distribution_version():
    from importlib import metadata

    assert hptrack.__version__ == metadata.version("hptrack")


def test_initial_observation_is_the_prior_at_time_zero():
    scenario = random_scenario(3, seed=5)
    obs = scenario.initial_observation()
    assert (obs.step, obs.time, obs.remaining_budget) == (0, 0.0, scenario.budget)
    np.testing.assert_array_equal(obs.agent_position, scenario.agent.position)
    np.testing.assert_array_equal(obs.means, scenario.means())
    np.testing.assert_array_equal(obs.covariances, scenario.covariances())
    assert not obs.detected.any() and obs.detected.shape == (3,)
    assert not obs.means.flags.writeable


def test_plan_pursues_the_only_target_and_heads_straight_for_it():
    decision = hptrack.plan(one_target(), "mcts", iterations=200)
    assert decision.target == "only"
    assert 0.0 < decision.subtask["p_find"] <= 1.0
    # the intercept of a target 600 m east that stands still: due east, one step of 15 m
    np.testing.assert_allclose(decision.waypoint, [15.0, 0.0], atol=1e-9)
    assert decision.info["searches"][0]["simulations"] >= 200


def test_plan_from_beliefs_equals_plan_from_the_scenario():
    scenario = random_scenario(4, seed=2)
    a = hptrack.plan(scenario, "mcts", iterations=500, seed=7)
    b = hptrack.plan(
        scenario.mission_spec(), "mcts", scenario.initial_observation(), iterations=500, seed=7
    )
    assert a.target == b.target
    np.testing.assert_array_equal(a.waypoint, b.waypoint)


def test_plan_with_a_planner_without_subtasks():
    decision = hptrack.plan(one_target(), "stationary")
    assert decision.target is None and decision.subtask is None
    np.testing.assert_array_equal(decision.waypoint, [0.0, 0.0])


def test_plan_refuses_bad_input():
    scenario = one_target()
    with pytest.raises(TypeError, match="needs the current observation"):
        hptrack.plan(scenario.mission_spec(), "greedy")
    with pytest.raises(InputError, match="exploration"):
        hptrack.plan(scenario, "mcts", exploration=-1)
    with pytest.raises(TypeError, match="planner given by name"):
        hptrack.plan(scenario, hptrack.make_planner("greedy"), iterations=3)


def test_benchmark_summarises_the_episodes_it_flies():
    summary = hptrack.benchmark(["greedy", "stationary"], [2], scenarios=2, first_seed=4)
    for name in ("greedy", "stationary"):
        u = [
            run_episode(
                random_scenario(2, seed=s, homogeneous=True), hptrack.make_planner(name)
            ).uncertainty
            for s in (4, 5)
        ]
        cell = summary[name][2]
        assert cell["episodes"] == 2
        assert cell["mean"] == pytest.approx(np.mean(u), rel=1e-12)


def test_benchmark_refuses_options_for_other_planners():
    with pytest.raises(InputError, match="not benchmarked: mcts"):
        hptrack.benchmark(["greedy"], [2], 1, options={"mcts": {"iterations": 10}})
