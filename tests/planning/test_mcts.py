"""The tree search (paper Algorithm 1) on the sub-task MDP, on small problems whose answer is
known (the search on toy MDPs with exact answers: ``test_search_toys.py``)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from hptrack.models.mission import mission_record
from hptrack.planning import PlanningProblem, search
from hptrack.planning.search import SearchOptions, run_simulations
from hptrack.planning.subtask_mdp import (
    FIND,
    MISS,
    SubtaskOptions,
    apply_outcome,
    expand_action,
    new_work,
)
from hptrack.planning.subtask_optimum import action_values
from hptrack.planning.tree import grow_tree, new_tree

TAU = 0.5


def prior(var_x=1500.0, var_y=1000.0, rho=0.3):
    cov = np.diag([var_x, var_y, 0.3, 0.4])
    cov[0, 1] = cov[1, 0] = rho * math.sqrt(var_x * var_y)
    return cov


def two_targets(budget=400.0, **kw):
    """Target 0 near the agent, target 1 5 km away on the other side: pursuing the near one
    first wins (found after a short flight, then the long trip) by more than 3 in E[U]."""
    means = np.array([[300.0, 0.0, 0.0, 0.5], [-5000.0, 0.0, 0.0, -0.5]])
    mission = mission_record(TAU, 900.0, 30.0, 100.0, 10.0 * np.eye(2), np.array([3e-4, 2e-4]))
    covs = np.array([prior(), prior(900.0, 2000.0, -0.5)])
    return PlanningProblem(mission, np.zeros(2), means, covs, budget, **kw)


def six_targets(seed=0, **kw):
    rng = np.random.default_rng(seed)
    means = np.hstack([rng.uniform(-1000, 1000, (6, 2)), rng.uniform(-3, 3, (6, 2))])
    covs = np.array([prior(*rng.uniform(500, 2000, 2), rng.uniform(-0.8, 0.8)) for _ in range(6)])
    q = rng.uniform(1e-4, 5e-4, 6)
    mission = mission_record(TAU, 900.0, 30.0, 100.0, 10.0 * np.eye(2), q)
    return PlanningProblem(mission, np.zeros(2), means, covs, 900.0, **kw)


def expectimax(problem, first=None):
    """Exact values ``-E[U]`` of the root's actions under the optimal policy (small MDPs), or
    with ``first = (action, outcome)`` of the actions after that first sub-task."""
    env = problem.env()
    state = problem.root_state()
    if first is not None:
        work = new_work()
        _, find_steps, miss_steps = expand_action(env, state, first[0], work)
        payload = find_steps if first[1] == FIND else miss_steps
        apply_outcome(env, state, first[0], first[1], payload, work)
    return action_values(env, state)


def test_ucb_picks_the_clearly_better_order():
    exact = expectimax(two_targets())
    assert exact[0] > exact[1] + 3.0
    result = search(two_targets(), iterations=3000, seed=0)
    assert result.best_action == 0
    assert result.root.actions.tolist() == [0, 1]
    assert result.root.visits.sum() == result.simulations - 1  # the first one rolls out
    assert result.root.visits[0] > result.root.visits[1]


def test_replanning_returns_one_action_per_outcome():
    result = search(two_targets(current_action=0), iterations=3000, seed=1)
    assert result.best_action == 0
    assert result.root.actions.tolist() == [0]
    assert result.root.visits.tolist() == [result.simulations - 1]
    # after finding target 0 both targets remain (0 again = follow it to the end); after a
    # miss only target 1 is left
    after_find, after_miss = result.after
    assert after_find.actions.tolist() == [0, 1]
    assert after_miss.actions.tolist() == [1]
    assert result.best_after(FIND) in (0, 1)
    assert result.best_after(MISS) == 1
    assert after_find.visits.sum() + after_miss.visits.sum() <= result.simulations
    exact = expectimax(two_targets(), first=(0, FIND))
    assert result.best_after(FIND) == max(exact, key=exact.get)


def test_replanning_with_six_targets():
    result = search(replace(six_targets(3), current_action=2), iterations=5000, seed=2)
    for stats in result.after:
        assert stats.visits.sum() > 0
        visited = stats.visits > 0
        assert stats.best == stats.actions[visited][np.argmax(stats.values[visited])]
    assert 2 in result.after[FIND].actions
    assert 2 not in result.after[MISS].actions


def test_same_seed_and_iterations_give_the_same_plan():
    a = search(six_targets(), iterations=1500, seed=7)
    b = search(six_targets(), iterations=1500, seed=7)
    c = search(six_targets(), iterations=1500, seed=8)
    assert a.best_action == b.best_action
    for name in ("actions", "visits", "values", "p", "payload"):
        np.testing.assert_array_equal(getattr(a.root, name), getattr(b.root, name))
    assert (a.state_nodes, a.action_nodes) == (b.state_nodes, b.action_nodes)
    assert not np.array_equal(a.root.visits, c.root.visits)
    gen = search(six_targets(), iterations=200, seed=np.random.default_rng(4))
    assert (
        gen.root.visits.tolist()
        == search(six_targets(), iterations=200, seed=np.random.default_rng(4)).root.visits.tolist()
    )


def test_tree_is_independent_of_chunking_and_initial_capacity():
    problem = six_targets(1)
    root = problem.root_state()

    def run(chunks, capacity):
        tree = new_tree(12345, capacity)
        env = problem.env()
        state = tuple(a.copy() for a in root)
        for n in chunks:
            while n:
                n -= run_simulations(
                    tree,
                    env,
                    root,
                    state,
                    new_work(),
                    SearchOptions(),
                    6,
                    problem.n_steps + 2,
                    -1,
                    n,
                )
                if n:
                    tree = grow_tree(tree, 6)
        return tree

    one = run([900], 1024)
    many = run([1, 7, 92, 300, 500], 2)
    assert many.s_first.shape[0] < one.s_first.shape[0] * 4
    for x, y in zip(one, many, strict=True):
        n = min(x.shape[0], y.shape[0]) if x.ndim else None
        np.testing.assert_array_equal(x[:n], y[:n])


def test_time_limit_and_iteration_limit():
    timed = search(six_targets(), time_limit=0.3, seed=0)
    assert timed.stopped_by == "time_limit"
    assert timed.elapsed >= 0.3 and timed.simulations > 0
    both = search(six_targets(), iterations=50, time_limit=60.0, seed=0)
    assert (both.stopped_by, both.simulations) == ("iterations", 50)
    with pytest.raises(ValueError, match="iterations, time_limit"):
        search(six_targets())
    with pytest.raises(ValueError, match="cannot be carried out"):
        search(two_targets(budget=10.0, current_action=1), iterations=10)


def test_no_available_action_gives_no_plan():
    result = search(two_targets(budget=5.0), iterations=20, seed=0)
    assert result.best_action is None
    assert result.root.actions.size == 0
    assert result.state_nodes == 1


def test_values_are_minus_uncertainty_at_the_end():
    """With one target left and one action, every simulation ends in the follow or the miss
    branch; the root's value is the p_find-weighted mean of their -U."""
    problem = two_targets(available=[True, False])
    result = search(problem, iterations=400, seed=3)
    exact = expectimax(problem)
    assert result.root.actions.tolist() == [0]
    assert result.root.values[0] == pytest.approx(exact[0], abs=0.5)


def test_replanning_under_false_finds_plans_only_what_the_world_reports():
    """With false finds modelled the current action has three outcomes, but the world reports
    a false find as a find: the root's simulations go to the find and the miss only, evenly,
    and no plan is made after the false find."""
    problem = two_targets(current_action=0)
    problem = replace(problem, mission=problem.mission._replace(false_alarm_density=1e-6))
    result = search(problem, subtask=SubtaskOptions(false_finds="model"), iterations=3000, seed=1)
    assert len(result.after) == 3 and result.after[2] is None
    after_find, after_miss = result.after[:2]
    assert after_find.actions.tolist() == [0, 1] and after_miss.actions.tolist() == [1]
    # the first simulation rolls out; the rest alternate between the two outcomes
    assert abs(int(after_find.visits.sum()) - int(after_miss.visits.sum())) <= 2
    first = search(replace(problem, current_action=None), iterations=3000, seed=1)
    modelled = search(
        replace(problem, current_action=None),
        subtask=SubtaskOptions(false_finds="model"),
        iterations=3000,
        seed=1,
    )
    assert first.root.values.tolist() != modelled.root.values.tolist()  # the outcome counts
