import numpy as np
import pytest

from hptrack.baselines.coverage import CoveragePlanner, CoverageSettings
from hptrack.coverage.estimator import estimate_coverage
from hptrack.coverage.subtask import CoverageSubtask
from hptrack.experiments.coverage_validation import ValidationConfig, case_rows, draw_case
from hptrack.interface import InputError, MissionSpec, Observation
from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode

MISSION = MissionSpec(
    time_step=0.5,
    budget=900.0,
    agent_speed=30.0,
    sensor_diameter=100.0,
    measurement_noise=10.0 * np.eye(2),
    process_noise_form="continuous",
    process_noise=np.array([3e-4, 2e-4]),
    target_ids=("a", "b"),
)
MEAN = np.array([700.0, -400.0, 2.0, 1.0])
COV = np.diag([1500.0, 900.0, 0.4, 0.3])
COV[0, 1] = COV[1, 0] = 400.0


def observation(step, agent, detected=(False, False), budget_used=0.0):
    return Observation(
        step,
        step * 0.5,
        900.0 - step * 0.5 - budget_used,
        np.asarray(agent),
        np.stack([MEAN, MEAN]),
        np.stack([COV, COV]),
        np.array(detected),
    )


def test_plan_flies_intercept_then_spiral_from_the_belief_centre():
    task = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, target_index=1)
    n = task.intercept.steps
    path = task.planned_positions()
    assert path.shape == (n + task.estimate.cutoff_steps + 1, 2)
    np.testing.assert_array_equal(path[0], np.zeros(2))
    np.testing.assert_allclose(path[n], MEAN[:2] + MEAN[2:] * n * 0.5)  # belief centre
    steps = np.hypot(*np.diff(path, axis=0).T)
    assert np.all(steps <= 15.0 * (1 + 1e-9))
    np.testing.assert_allclose(steps[n:], 15.0, rtol=1e-6)
    assert task.intercept_time == n * 0.5
    assert 0.0 < task.p_find < 1.0 and 0.0 < task.expected_time < task.cutoff_time
    assert task.end_step == n + task.estimate.cutoff_steps
    # the covariance the estimate starts from is the prior propagated n steps
    _, covs = MISSION.motion.predict(MEAN[None], COV[None], 3e-4, n * 0.5)
    np.testing.assert_allclose(task.start_covariance, covs[0])


def test_waypoints_follow_the_observation_steps_and_extend_past_the_cutoff():
    task = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, start_step=40)
    path = task.planned_positions(task.total_steps + 50)
    for j in (0, 5, task.intercept.steps, task.total_steps + 20):
        np.testing.assert_array_equal(task.next_waypoint(observation(40 + j, path[j])), path[j + 1])


def test_done_on_detection_of_the_pursued_target_cutoff_or_budget():
    task = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, target_index=1)
    assert not task.done(observation(3, np.zeros(2), detected=(True, False)))
    assert task.done(observation(3, np.zeros(2), detected=(False, True)))
    assert not task.done(observation(task.end_step - 1, np.zeros(2)))
    assert task.done(observation(task.end_step, np.zeros(2)))
    assert task.done(observation(3, np.zeros(2), budget_used=900.0 - 1.5))


def test_short_budget_cuts_the_plan():
    task = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 40.0)
    assert task.estimate.budget_limited
    assert task.total_steps == 80 == task.intercept.steps + task.estimate.cutoff_steps
    assert task.planned_positions().shape == (81, 2)  # by default up to the budget's end
    never = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 5.0)
    assert never.p_find == 0.0 and never.total_steps == 10


def test_without_a_budget_the_plan_runs_to_the_cutoff():
    unbounded = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, None)
    short = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 40.0)
    n = unbounded.intercept.steps
    assert n == short.intercept.steps
    expected = estimate_coverage(unbounded.start_covariance, 3e-4, MISSION)
    assert not unbounded.estimate.budget_limited
    assert unbounded.estimate.cutoff_steps == expected.cutoff_steps > 80 - n
    assert unbounded.p_find == expected.p_find > short.p_find
    assert unbounded.total_steps == n + expected.cutoff_steps
    np.testing.assert_array_equal(unbounded.planned_positions()[:81], short.planned_positions())


def test_mean_inside_the_footprint_spirals_from_the_agent_at_once():
    agent = MEAN[:2] + np.array([20.0, -30.0])
    task = CoverageSubtask(agent, MEAN, COV, 3e-4, MISSION, 900.0)
    assert task.intercept.steps == 0
    np.testing.assert_array_equal(task.planned_positions(1)[0], agent)
    np.testing.assert_allclose(np.hypot(*(task.waypoint(1) - agent)), 15.0)


def test_bad_inputs():
    with pytest.raises(ValueError, match="target_index"):
        CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, target_index=2)
    with pytest.raises(ValueError, match="not below the agent speed"):
        CoverageSubtask(np.zeros(2), [0.0, 900.0, 40.0, 0.0], COV, 3e-4, MISSION, 900.0)
    with pytest.raises(ValueError, match="mean"):
        CoverageSubtask(np.zeros(2), [0.0, np.nan, 1.0, 0.0], COV, 3e-4, MISSION, 900.0)
    with pytest.raises(InputError, match="option target 'zz' is not a target of the scenario"):
        CoveragePlanner(CoverageSettings(target="zz")).reset(
            MISSION, observation(0, np.zeros(2)), None
        )
    with pytest.raises(InputError, match="planner 'coverage': option target is required"):
        make_planner("coverage", {})


def test_coverage_planner_finds_and_then_follows_its_target():
    scenario = random_scenario(2, seed=4).model_copy(update={"budget": 150.0})
    record = run_episode(scenario, make_planner("coverage", {"target": "t2"}), seed=11)
    assert record.info["settings"] == {"target": "t2"}
    subtasks = record.info["subtasks"]
    assert subtasks[0]["outcome"] == "found"
    first = subtasks[0]["end_step"]
    assert record.detections[first, 1]
    # after finding it the agent stays on the target: measured at most steps from then on
    assert record.detections[first:, 1].mean() > 0.9


@pytest.mark.parametrize("case", [0, 1, 2])
def test_estimate_agrees_with_2000_simulated_trajectories(case):
    config = ValidationConfig(cases=3, runs=2000, seed=2024)
    for row in case_rows(draw_case(case, 2024), config)[0]:
        assert abs(row["est_p_find"] - row["emp_p_find"]) <= 0.1, row


def test_a_coverage_limit_ends_the_spiral_early_with_its_estimate_truncated_there():
    """A limit of half the coverage's ``t_cutoff``: the spiral ends there (the same path up to
    it), with the paper's estimate of a coverage truncated there as at the budget's end; a
    budget that ends first still binds, and a limit beyond ``t_cutoff`` changes nothing."""
    full = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, target_index=1)
    n, cutoff = full.intercept.steps, full.estimate.cutoff_steps
    limit = cutoff // 2
    short = CoverageSubtask(
        np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, target_index=1, coverage_steps=limit
    )
    assert (short.estimate.cutoff_steps, short.end_step) == (limit, n + limit)
    truncated = estimate_coverage(short.start_covariance, 3e-4, MISSION, limit * 0.5)
    assert short.p_find == truncated.p_find < full.p_find
    assert short.expected_time == truncated.expected_time < full.expected_time
    assert short.sharp_estimate.p_find < full.sharp_estimate.p_find
    np.testing.assert_array_equal(
        short.planned_positions(), full.planned_positions()[: n + limit + 1]
    )
    budget = (n + 10) * 0.5
    late = CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, budget, coverage_steps=limit)
    assert late.end_step == n + 10
    beyond = CoverageSubtask(
        np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, target_index=1, coverage_steps=cutoff + 5
    )
    assert (beyond.end_step, beyond.p_find, beyond.expected_time) == (
        full.end_step,
        full.p_find,
        full.expected_time,
    )
    with pytest.raises(ValueError, match="coverage_steps must be at least 1, got 0"):
        CoverageSubtask(np.zeros(2), MEAN, COV, 3e-4, MISSION, 900.0, coverage_steps=0)
