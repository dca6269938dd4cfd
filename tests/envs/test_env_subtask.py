"""SubtaskTracking-v0: one coverage sub-task per action, follow, feasibility, info."""

import numpy as np
import pytest

from hptrack.coverage.subtask import CoverageSubtask
from hptrack.envs import SubtaskTrackingEnv
from hptrack.scenario import random_scenario


def test_a_coverage_subtask_runs_inside_one_step():
    env = SubtaskTrackingEnv(n_targets=3)
    _, info = env.reset(options={"scenario": random_scenario(3, seed=1, budget=300.0)})
    u0 = info["U"]
    plan = CoverageSubtask.from_observation(env.world.observation(), 0, env.world.mission)
    _, reward, terminated, truncated, info = env.step(0)
    sub = info["subtask"]
    assert not terminated and not truncated
    assert sub["outcome"] == "found" and info["detected"][0]
    assert sub["kind"] == "pursue" and sub["target"] == 0 and sub["start_step"] == 0
    assert sub["steps"] == env.world.step_index == sub["end_step"]
    assert sub["steps"] <= plan.total_steps
    assert sub["duration"] == pytest.approx(0.5 * sub["steps"])
    assert sub["t_cutoff"] == plan.cutoff_time and sub["p_find"] == plan.p_find
    assert reward == pytest.approx(-(info["U"] - u0) / 3, abs=1e-12)
    assert info["last_found"] == 0


def test_choosing_the_target_just_found_follows_it_to_the_end():
    env = SubtaskTrackingEnv(n_targets=3)
    env.reset(options={"scenario": random_scenario(3, seed=1, budget=300.0)})
    _, _, _, _, info = env.step(0)
    assert info["subtask"]["outcome"] == "found"
    start = env.world.step_index
    _, _, _, truncated, info = env.step(0)
    sub = info["subtask"]
    assert truncated and sub["outcome"] == "followed"
    assert sub["end_step"] == 600 and sub["steps"] == 600 - start
    assert not info["action_mask"].any()
    # followed at its predicted position: measured (almost) every step, its uncertainty small
    assert info["per_target_logdet"][0] < 6.0


def test_a_target_found_earlier_but_not_just_now_gets_a_new_coverage():
    env = SubtaskTrackingEnv(n_targets=3)
    env.reset(options={"scenario": random_scenario(3, seed=1, budget=300.0)})
    env.step(0)
    _, _, _, _, info = env.step(1)
    assert info["subtask"]["outcome"] == "found" and info["last_found"] == 1
    _, _, _, _, info = env.step(0)
    assert info["subtask"]["outcome"] in ("found", "missed")


def test_infeasible_actions_hover_one_step():
    env = SubtaskTrackingEnv(n_targets=2, max_targets=4)
    _, info = env.reset(options={"scenario": random_scenario(2, seed=3, budget=60.0)})
    np.testing.assert_array_equal(info["action_mask"][2:], False)
    start = env.world.agent.copy()
    _, _, _, _, info = env.step(3)  # a padding slot
    assert info["subtask"]["outcome"] == "infeasible" and info["subtask"]["steps"] == 1
    np.testing.assert_array_equal(env.world.agent, start)


def test_a_target_out_of_reach_of_the_remaining_budget_is_infeasible():
    env = SubtaskTrackingEnv(n_targets=4)
    env.reset(options={"scenario": random_scenario(4, seed=2, budget=20.0)})
    w = env.world
    distance = np.hypot(*(w.means[:, :2] - w.agent).T)
    mask = env.action_masks()
    # at 30 m/s the agent covers at most ~600 m (+ the 50 m footprint) in 20 s
    assert not mask[distance > 700.0].any()
    far = int(np.argmax(distance))
    assert distance[far] > 700.0
    _, _, _, _, info = env.step(far)
    assert info["subtask"]["outcome"] == "infeasible"


def test_missed_and_budget_outcomes():
    scenario = random_scenario(3, seed=5, budget=240.0)
    data = scenario.model_dump()
    t = data["targets"][1]
    t["truth"] = (t["mean"][0] + 1500.0, t["mean"][1] - 1500.0, 0.0, 0.0)
    env = SubtaskTrackingEnv(n_targets=3)
    env.reset(options={"scenario": type(scenario).model_validate(data)})
    plan = CoverageSubtask.from_observation(env.world.observation(), 1, env.world.mission)
    _, _, _, truncated, info = env.step(1)
    assert info["subtask"]["outcome"] == "missed" and not truncated
    assert info["subtask"]["steps"] == plan.total_steps
    outcomes = []
    while not truncated:  # the lost target again, until the budget cuts a coverage short
        _, _, _, truncated, info = env.step(1)
        outcomes.append(info["subtask"]["outcome"])
    assert outcomes == ["missed", "budget"]
    assert info["subtask"]["budget_limited"] and info["subtask"]["end_step"] == 480
