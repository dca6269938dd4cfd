"""ARVI: hand-checkable plans, alternation between near targets, and the pruning rule."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.baselines.arvi import ArviPlanner, ArviSettings, prune
from hptrack.baselines.information import expand, mean_positions
from hptrack.models.beliefs import position_logdet
from hptrack.scenario import Scenario, TargetSpec
from hptrack.sim.episode import run_episode

EAST, HOVER = 1, 0
STATIC_PRIOR = (
    (900.0, 100.0, 0.0, 0.0),
    (100.0, 800.0, 0.0, 0.0),
    (0.0, 0.0, 0.3, 0.0),
    (0.0, 0.0, 0.0, 0.3),
)


def planner_for(mission, obs, **settings):
    planner = ArviPlanner(ArviSettings(**settings))
    planner.reset(mission, obs, np.random.default_rng(0))
    return planner


def static_scenario(xs, budget):
    """Targets whose truth sits still at their mean (q = 0), on the x axis."""
    targets = [
        TargetSpec(
            id=f"t{i}",
            mean=(x, 0.0, 0.0, 0.0),
            covariance=STATIC_PRIOR,
            process_noise=0.0,
            truth=(x, 0.0, 0.0, 0.0),
        )
        for i, x in enumerate(xs)
    ]
    return Scenario(seed=1, targets=targets, budget=budget)


def test_flies_straight_to_a_reachable_target_and_stays_on_it(make_mission, make_observation):
    # Four eastward primitives (600 m) put the agent on the target; hovering there keeps it
    # measured at every sub-step, which no other control does.
    mission, obs = make_mission(1), make_observation([[600.0, 0.0, 0.0, 0.0]])
    plan, stats = planner_for(mission, obs).search(obs)
    np.testing.assert_array_equal(plan, [EAST] * 4 + [HOVER] * 8)
    assert stats.passes == 5 and not stats.capped
    record = run_episode(static_scenario([600.0], budget=60.0), ArviPlanner())
    # 15 m per step: the target is within 50 m from step ceil(550 / 15) = 37 on.
    assert np.flatnonzero(record.detections[:, 0])[0] == 37
    assert record.detections[37:, 0].all()
    assert record.info["decisions"] == 12  # 120 steps, one search per 10-step primitive
    assert record.info["settings"]["delta_schedule_m"] == ["inf", 150.0, 100.0, 75.0, 50.0]


def test_hovers_when_nothing_is_reachable(make_mission, make_observation):
    mission, obs = make_mission(1), make_observation([[3000.0, 0.0, 0.0, 0.0]])
    plan, stats = planner_for(mission, obs).search(obs)
    np.testing.assert_array_equal(plan, [HOVER] * 12)
    _, predicted = mission.motion.predict(
        obs.means, obs.covariances, mission.process_noise, 120 * mission.time_step
    )
    growth = position_logdet(predicted) - position_logdet(obs.covariances)
    assert stats.predicted_cost == pytest.approx(growth.sum(), rel=1e-12)


def test_alternates_between_two_near_targets():
    # The seed paper (Sec. V-B) saw ARVI with the difference cost move back and forth between
    # targets in small environments.
    record = run_episode(static_scenario([-300.0, 300.0], budget=300.0), ArviPlanner())
    order = [
        i for k in range(record.detections.shape[0]) for i in np.flatnonzero(record.detections[k])
    ]
    visits = [i for i, _ in itertools.groupby(order)]
    assert len(visits) >= 6
    assert visits[:6] in ([0, 1, 0, 1, 0, 1], [1, 0, 1, 0, 1, 0])
    assert record.detections.sum(axis=0).min() >= 30


def test_anytime_search_returns_the_best_pass_and_exact_vi_is_exhaustive(
    make_mission, make_observation
):
    means = [[100.0, 60.0, -2.0, 1.0], [-150.0, 100.0, 1.0, -1.0]]
    mission, obs = make_mission(2), make_observation(means)
    planner = planner_for(mission, obs, horizon=3)
    mp = mean_positions(obs.means, mission.motion, 30)
    passes = [planner.run_pass(obs, mp, 3, d, e) for d, e in planner.settings.passes()]
    assert len({p.cost for p in passes}) > 1
    plan, stats = planner.search(obs)
    assert stats.predicted_cost == min(p.cost for p in passes)
    exact = planner.run_pass(obs, mp, 3, 0.0, 0.0)
    # Exhaustive: all 9^3 sequences.
    pos, covs = obs.agent_position[None], obs.covariances[None]
    for level in range(3):
        pos, covs, unc = expand(
            planner.mission,
            planner.step_displacements,
            mp[level * 10 : (level + 1) * 10 + 1],
            pos,
            covs,
        )
    costs = unc - position_logdet(obs.covariances).sum()
    best = int(np.argmin(costs))
    assert exact.cost == pytest.approx(costs[best], abs=1e-9)
    np.testing.assert_array_equal(exact.plan, [best // 81, best // 9 % 9, best % 9])
    assert exact.nodes_expanded == 1 + 9 + 81
    assert stats.predicted_cost >= exact.cost - 1e-12


def test_time_limit_stops_after_the_first_pass_and_default_is_deterministic(
    make_mission, make_observation
):
    means = [[400.0, 300.0, -2.0, 1.0], [-500.0, 150.0, 1.0, 0.0]]
    mission, obs = make_mission(2), make_observation(means)
    # a limit of 0 is refused; 1 ns is spent before the first pass ends
    _, stats = planner_for(mission, obs, time_limit_s=1e-9).search(obs)
    assert stats.passes == 1
    a = planner_for(mission, obs).search(obs)
    b = planner_for(mission, obs).search(obs)
    np.testing.assert_array_equal(a[0], b[0])
    assert a[1].predicted_cost == b[1].predicted_cost


def test_original_sum_cost_also_steers_to_the_target(make_mission, make_observation):
    mission, obs = make_mission(1), make_observation([[600.0, 0.0, 0.0, 0.0]])
    plan, _ = planner_for(mission, obs, cost="sum").search(obs)
    np.testing.assert_array_equal(plan, [EAST] * 4 + [HOVER] * 8)


# --- pruning -------------------------------------------------------------------------------


def test_pruning_keeps_the_cheapest_node_even_when_it_comes_last():
    positions = np.array([[0.0, 0.0], [30.0, 0.0], [200.0, 0.0], [210.0, 0.0]])
    costs = np.array([2.0, 1.0, 3.0, 0.5])
    kept, capped = prune(positions, costs, None, 50.0, math.inf, 10)
    np.testing.assert_array_equal(kept, [3, 1])
    assert not capped
    kept, capped = prune(positions, costs, None, 50.0, math.inf, 1)
    np.testing.assert_array_equal(kept, [3])
    assert capped
    np.testing.assert_array_equal(prune(positions, costs, None, math.inf, math.inf, 10)[0], [3])
    np.testing.assert_array_equal(prune(positions, costs, None, 0.0, math.inf, 10)[0], [3, 1, 0, 2])


def test_epsilon_redundancy_is_checked_on_whole_blocks():
    # Same position; node 0 is cheaper. Its covariance exceeds node 1's by D = [[1, 2], [2, 1]]
    # on the position block (eigenvalues 3 and -1): node 1 is redundant iff D <= epsilon I,
    # i.e. epsilon >= 3, although the diagonal alone would allow epsilon >= 1.
    base = np.diag([20.0, 20.0, 1.0, 1.0])
    worse = base.copy()
    worse[:2, :2] += [[1.0, 2.0], [2.0, 1.0]]
    covs = np.stack([worse, base])[:, None]
    positions = np.zeros((2, 2))
    costs = np.array([0.0, 1.0])
    for epsilon, expected in [(0.0, [0, 1]), (2.0, [0, 1]), (2.999, [0, 1]), (3.001, [0])]:
        np.testing.assert_array_equal(prune(positions, costs, covs, 10.0, epsilon, 10)[0], expected)
    with pytest.raises(ValueError, match="finite epsilon needs the covariances"):
        prune(positions, costs, None, 10.0, 1.0, 10)


def redundant(positions, covs, j, k, delta, epsilon):
    if np.hypot(*(positions[k] - positions[j])) >= delta:
        return False
    if math.isinf(epsilon):
        return True
    return all(
        np.linalg.eigvalsh(covs[j, i] + epsilon * np.eye(4) - covs[k, i]).min() >= -1e-9
        for i in range(covs.shape[1])
    )


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    delta=st.sampled_from([0.0, 20.0, 75.0, math.inf]),
    epsilon=st.sampled_from([0.0, 5.0, 50.0, math.inf]),
)
def test_pruning_matches_the_greedy_rule_and_never_drops_the_best(seed, delta, epsilon):
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 60))
    positions = rng.uniform(0.0, 200.0, (m, 2))
    costs = np.round(rng.normal(size=m), 1)  # ties happen
    a = rng.normal(size=(m, 2, 4, 4))
    covs = a @ a.transpose(0, 1, 3, 2) * 10.0 + np.eye(4)
    kept, capped = prune(positions, costs, covs, delta, epsilon, m)
    assert not capped
    order = np.argsort(costs, kind="stable")
    assert kept[0] == order[0]
    expected = []
    for j in order:
        if not any(redundant(positions, covs, j, k, delta, epsilon) for k in expected):
            expected.append(j)
    np.testing.assert_array_equal(kept, expected)
