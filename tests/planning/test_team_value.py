"""The value of a UAV's path of pursuits (`hptrack.planning.team_value`): the formula by hand
from the estimator's outputs, the budget, unreachable targets, and how far the marginal gains
diminish."""

import math

import numpy as np
import pytest

from hptrack.coverage.estimator import estimate_coverage
from hptrack.coverage.intercept import plan_intercept
from hptrack.interface import MissionSpec
from hptrack.planning.team_value import team_path_value
from hptrack.scenario import random_scenario

PRIOR = np.diag([400.0, 400.0, 0.25, 0.25])
Q = 1e-3


def spec(budget=120.0, n_targets=2, **fields):
    return MissionSpec(
        budget=budget,
        process_noise=np.full(n_targets, Q),
        target_ids=tuple(f"t{i}" for i in range(n_targets)),
        **fields,
    )


def logdet(cov):
    return math.log(np.linalg.det(cov[:2, :2]))


def updated(cov, noise):
    """The textbook position update ``P - P H' (H P H' + R)^-1 H P``."""
    h = np.eye(2, 4)
    gain = cov @ h.T @ np.linalg.inv(h @ cov @ h.T + noise)
    return cov - gain @ h @ cov


def pursuit_by_hand(mission, position, step, mean, cov):
    """One pursuit from ``position`` at ``step``, from the Python faces of the intercept, the
    motion and the estimator: ``(credit, end step, end position)``."""
    tau, n_steps = mission.time_step, mission.n_steps
    now = mean.copy()
    now[:2] += mean[2:] * step * tau  # constant velocity
    n = plan_intercept(mission.record, position, now).steps
    predict = mission.motion.predict
    start = predict(mean[None], cov[None], Q, (step + n) * tau)[1][0]
    est = estimate_coverage(start, Q, mission, (n_steps - step - n) * tau)
    find = max(1, n + math.floor(est.expected_steps + 0.5))
    miss = max(1, n + est.cutoff_steps)
    found = predict(mean[None], cov[None], Q, (step + find) * tau)[1][0]
    found = updated(found, mission.measurement_noise)
    found_end = predict(mean[None], found[None], Q, (n_steps - step - find) * tau)[1][0]
    unseen_end = predict(mean[None], cov[None], Q, n_steps * tau)[1][0]
    credit = est.p_find * (logdet(unseen_end) - logdet(found_end))
    end = step + max(1, math.floor(est.p_find * find + (1 - est.p_find) * miss + 0.5))
    return credit, end, mean[:2] + mean[2:] * end * tau


def test_two_pursuits_are_worth_the_formula_from_the_estimators_outputs():
    """A target 600 m east, then one that drifts north-west from (600, 400) m."""
    mission = spec(measurement_noise=np.eye(2))
    means = np.array([[600.0, 0.0, 0.0, 0.0], [600.0, 400.0, -1.0, 2.0]])
    covs = np.stack([PRIOR, PRIOR])
    value = team_path_value([mission], np.zeros((1, 2)), means, covs, mission.budget)
    first, end, position = pursuit_by_hand(mission, np.zeros(2), 0, means[0], PRIOR)
    second, _, _ = pursuit_by_hand(mission, position, end, means[1], PRIOR)
    assert 0.0 < first and 0.0 < second
    assert value(0, (0,)) == pytest.approx(first, rel=1e-9)
    assert value(0, (0, 1)) == pytest.approx(first + second, rel=1e-9)
    assert value(0, ()) == 0.0


def test_a_coverage_limit_shortens_the_bids_pursuits():
    """The auction's bids see the members' coverage limit: a 1 s spiral finds less than one
    run to ``t_cutoff``; a limit beyond every cutoff changes nothing."""
    mission = spec(measurement_noise=np.eye(2))
    means = np.array([[600.0, 0.0, 0.0, 0.0], [600.0, 400.0, -1.0, 2.0]])
    covs = np.stack([PRIOR, PRIOR])

    def value(limit: float) -> float:
        path_value = team_path_value(
            [mission], np.zeros((1, 2)), means, covs, mission.budget, coverage_limit=limit
        )
        return path_value(0, (0, 1))

    assert 0.0 < value(1.0) < value(0.0) == value(1e5)


def test_each_uav_flies_with_its_own_position_speed_and_sensor():
    slow = spec(agent_speed=15.0)
    fast = spec(agent_speed=30.0)
    means = np.array([[600.0, 0.0, 0.0, 0.0], [600.0, 400.0, -1.0, 2.0]])
    covs = np.stack([PRIOR, PRIOR])
    positions = np.array([[0.0, 0.0], [600.0, 300.0]])
    team = team_path_value([slow, fast], positions, means, covs, 120.0)
    for agent, mission in enumerate((slow, fast)):
        alone = team_path_value([mission], positions[agent : agent + 1], means, covs, 120.0)
        for path in ((0,), (1,), (0, 1), (1, 0)):
            assert team(agent, path) == alone(0, path)
    assert team(0, (1,)) != team(1, (1,))


def test_a_target_out_of_reach_is_worth_nothing_and_skipped():
    """Target 1 runs at 40 m/s from a 30 m/s UAV; target 2 is 10 km away with 120 s left."""
    mission = spec(n_targets=3)
    means = np.array([[600.0, 0.0, 0.0, 0.0], [300.0, 0.0, 40.0, 0.0], [1e4, 0.0, 0.0, 0.0]])
    value = team_path_value([mission], np.zeros((1, 2)), means, np.stack([PRIOR] * 3), 120.0)
    assert value(0, (1,)) == 0.0 and value(0, (2,)) == 0.0
    assert value(0, (1, 0, 2)) == value(0, (0,)) > 0.0


def test_the_value_over_the_budget_rises_then_fades():
    """A target 600 m east (sd 50 m): zero until the budget outlasts the intercept (to the
    mean, 600 m at 30 m/s: 20 s); rising while the budget cuts the coverage short; then falling:
    the score is U at the budget's end, and a target found long before it has grown back by
    then."""
    means, prior = np.array([[600.0, 0.0, 0.0, 0.0]]), np.diag([2500.0, 2500.0, 1.0, 1.0])
    values = []
    budgets = [19.5, 20.0, 20.5, 21.0, 22.0, 25.0, 30.0, 40.0, 60.0, 120.0, 300.0, 900.0]
    for budget in budgets:
        mission = spec(budget, n_targets=1)
        value = team_path_value([mission], np.zeros((1, 2)), means, prior[None], budget)
        values.append(value(0, (0,)))
    assert values[:2] == [0.0, 0.0]
    peak = int(np.argmax(values))
    assert budgets[peak] == 25.0
    assert np.all(np.diff(values[1 : peak + 1]) > 0) and np.all(np.diff(values[peak:]) < 0)


def random_team(seed, n_targets=10, n_agents=2):
    scenario = random_scenario(n_targets, seed=seed, homogeneous=True)
    obs = scenario.initial_observation()
    rng = np.random.default_rng(seed)
    positions = obs.agent_position + rng.uniform(-300.0, 300.0, (n_agents, 2))
    mission = scenario.mission_spec()
    return team_path_value(
        [mission] * n_agents, positions, obs.means, obs.covariances, obs.remaining_budget
    ), rng


def test_appending_a_pursuit_never_lowers_the_value():
    for seed in range(3):
        value, rng = random_team(seed)
        for _ in range(20):
            path = tuple(int(j) for j in rng.permutation(10)[: rng.integers(1, 8)])
            assert value(0, path) >= value(0, path[:-1])


def marginal(value, path, task):
    base = value(0, path)
    return max(value(0, (*path[:n], task, *path[n:])) - base for n in range(len(path) + 1))


def test_the_marginal_gains_do_not_always_diminish():
    """A pursuit flown later is found closer to the budget's end, where a find counts more: on
    these scenarios a target's best marginal score often rises once another pursuit is put in
    the path (``docs/teams.md`` has the share), so CBBA's guarantee does not hold for these
    scores."""
    rises = falls = 0
    for seed in range(3):
        value, rng = random_team(seed)
        for _ in range(10):
            order = [int(j) for j in rng.permutation(10)]
            path, added, others = tuple(order[:3]), order[3], order[4:]
            longer = max(
                ((*path[:n], added, *path[n:]) for n in range(len(path) + 1)),
                key=lambda p: value(0, p),
            )
            for task in others:
                before, after = marginal(value, path, task), marginal(value, longer, task)
                rises += after > before
                falls += after <= before
    assert rises > 0 and falls > 0


def test_bad_shapes_are_refused():
    mission = spec()
    means, covs = np.zeros((2, 4)), np.stack([PRIOR, PRIOR])
    with pytest.raises(ValueError, match="agent_positions"):
        team_path_value([mission, mission], np.zeros((1, 2)), means, covs, 60.0)
    with pytest.raises(ValueError, match="means"):
        team_path_value([mission], np.zeros((1, 2)), means[:1], covs, 60.0)
    value = team_path_value([mission], np.zeros((1, 2)), means, covs, 60.0)
    with pytest.raises(ValueError, match="path"):
        value(0, (0, 0))
    with pytest.raises(ValueError, match="agent"):
        value(1, (0,))
