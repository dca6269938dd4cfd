"""The search's improvements on problems with exact answers: the expected and max backups
(:mod:`hptrack.planning.tree`), the rollout policies of :mod:`hptrack.planning.subtask_rollout`
and the weighted root split of re-planning."""

import numpy as np
import pytest
from test_mcts import expectimax, six_targets, two_targets
from test_search_toys import GAMBLE, Bandit, Gamble, gamble_q_exact

from hptrack.models.beliefs import logdet_xy
from hptrack.models.motion import position_covariance_after
from hptrack.planning import SearchOptions, search, search_mdp
from hptrack.planning.backups import Expected, Max, Robust, back_max, backup_of
from hptrack.planning.search import _root_outcome
from hptrack.planning.subtask_mdp import FIND, MISS, intercept_of, is_available
from hptrack.planning.subtask_rollout import (
    MostUncertain,
    Nearest,
    Tour,
    UniformNoFollow,
    most_uncertain,
    nearest,
    tour,
    uniform_no_follow,
)
from hptrack.planning.tree import new_tree

MAX = SearchOptions(backup=Max())


@pytest.mark.parametrize("p", [0.3, 0.5, 0.9])
def test_expected_backup_weights_the_outcomes_by_their_known_probability(p):
    """One action, win 1 or lose 0: the sampled backup gives the fraction of wins drawn, the
    expected backup gives exactly ``p`` as soon as both outcomes were visited (the second visit
    takes the outcome not yet seen)."""
    env = Bandit(np.array([p]), np.array([1.0]), np.array([0.0]))
    root = (np.array([-1, 0], dtype=np.int64),)
    for sims in (3, 4, 50):
        result = search_mdp(
            env, root, 1, 2, np.zeros(1), SearchOptions(backup=Expected()), iterations=sims, seed=2
        )
        assert result.root.values[0] == pytest.approx(p, abs=1e-15)
    sampled = search_mdp(env, root, 1, 2, np.zeros(1), iterations=50, seed=2)
    assert sampled.root.values[0] != pytest.approx(p, abs=1e-3)


def test_max_backup_gives_the_exact_expectimax_values_of_the_gamble():
    """Deterministic rewards per outcome: once the tree is open to the end, the max backup's
    root values are the expectimax Q-values exactly, while the mean backups stay below them
    (they average in the worse actions tried below)."""
    exact = [gamble_q_exact(0, 0, a) for a in range(3)]
    root = (np.zeros(2, dtype=np.int64),)
    found = search_mdp(GAMBLE, root, 3, 4, np.zeros(1), MAX, iterations=100000, seed=5)
    np.testing.assert_allclose(found.root.values, exact, rtol=1e-12)
    for backup in ("sampled", "expected"):
        options = SearchOptions(backup=backup_of(backup))
        mean = search_mdp(GAMBLE, root, 3, 4, np.zeros(1), options, iterations=100000, seed=5)
        assert np.all(mean.root.values < np.array(exact) - 0.05)


def test_max_backup_matches_expectimax_on_the_subtask_mdp():
    exact = expectimax(two_targets())
    result = search(two_targets(), MAX, iterations=30000, seed=0)
    np.testing.assert_allclose(result.root.values, [exact[0], exact[1]], rtol=1e-9)
    after = search(two_targets(current_action=0), MAX, iterations=30000, seed=1)
    exact_after = expectimax(two_targets(), first=(0, FIND))
    after_find = after.after[FIND]
    np.testing.assert_allclose(
        after_find.values, [exact_after[a] for a in after_find.actions], rtol=1e-9
    )


def test_unknown_backup_and_root_split_are_refused():
    with pytest.raises(ValueError, match="backup must be one of"):
        backup_of("median")
    with pytest.raises(ValueError, match="max_weight must be in"):
        backup_of("max", 1.5)
    with pytest.raises(ValueError, match="root_split must be one of"):
        search(two_targets(), SearchOptions(root_split="odd"), iterations=10)


def _greedy_cases():
    """States of six targets at several steps, with and without a target just found, with
    their available actions and the greedy rules' scores computed here: the position log det
    on arrival at the belief mean (numpy) and the intercept steps."""
    problem = six_targets(3)
    env = problem.env()
    for step, last in ((0, -1), (300, 2), (900, 4)):
        state = problem.root_state()
        state[0][0], state[0][2] = step, last
        available = [a for a in range(6) if is_available(env, state, a)]
        steps = {a: intercept_of(env, state[1], a, step) for a in available if a != last}
        uncertainty = {
            a: logdet_xy(
                *position_covariance_after(
                    problem.covariances[a],
                    problem.mission.process_noise[a],
                    float(step + k),
                    0.5,
                    0.5,
                )
            )
            for a, k in steps.items()
        }
        assert len(steps) >= 3
        yield env, state, available, steps, uncertainty


@pytest.mark.parametrize("policy, kernel", [(MostUncertain, most_uncertain), (Nearest, nearest)])
def test_greedy_rollouts_pick_their_best_target_other_than_the_one_just_found(policy, kernel):
    """epsilon = 0: most uncertain, the available target whose position log det is largest
    on arrival; nearest, the one with the fewest intercept steps (the lower index on a tie);
    never the target just found while another is available. epsilon = 1: uniform over the
    available actions."""
    candidates = np.empty(6, dtype=np.int64)
    rng = np.array([7], dtype=np.uint64)
    for env, state, available, steps, uncertainty in _greedy_cases():
        expected = (
            max(uncertainty, key=uncertainty.get)
            if policy is MostUncertain
            else min(steps, key=steps.get)
        )
        assert kernel(policy(0.0), env, state, rng, candidates) == expected
        draws = {kernel(policy(1.0), env, state, rng, candidates) for _ in range(300)}
        assert draws == set(available)


def test_most_uncertain_rollout_follows_only_when_nothing_else_is_left():
    problem = two_targets()
    env = problem.env()
    state = problem.root_state()
    state[0][1] = 0b01  # target 1 missed: only target 0, just found, is left
    state[0][2] = 0
    out = most_uncertain(
        MostUncertain(0.0), env, state, np.array([1], dtype=np.uint64), np.empty(2, dtype=np.int64)
    )
    assert out == 0


def test_tour_rollout_dwells_while_the_velocity_is_uncertain_then_goes_to_the_nearest():
    """epsilon = 0. Target 0 just found with velocity variances 0.3 and 0.45 (m/s)^2: a dwell,
    drawn among the lengths available (both here, each drawn). Once its mean velocity variance
    is below ``settle_velocity_variance``, or without dwell actions: the nearest other target
    (target 1, the only other one). epsilon = 1: uniform over the available actions."""
    from hptrack.planning.subtask_mdp import SubtaskOptions

    problem = two_targets(budget=900.0, last_found=0)
    env = problem.env(SubtaskOptions(dwell=(5.0, 20.0)))
    state = problem.root_state()
    candidates = np.empty(4, dtype=np.int64)
    rng = np.array([3], dtype=np.uint64)
    draws = {tour(Tour(0.0), env, state, rng, candidates) for _ in range(200)}
    assert draws == {2, 3}
    assert tour(Tour(0.0, settle_velocity_variance=0.4), env, state, rng, candidates) == 1
    plain = problem.env()
    assert tour(Tour(0.0), plain, state, rng, candidates[:2]) == 1
    draws = {tour(Tour(1.0), env, state, rng, candidates) for _ in range(300)}
    assert draws == {0, 1, 2, 3}


def test_root_parallel_trees_merge_their_statistics():
    """Two trees of 1,500 simulations: visits add up action by action, values are the
    visit-weighted means of the trees' values, and the run is reproducible from its seed."""
    from hptrack.planning.search import seed_value
    from hptrack.planning.tree import merge_stats

    merged = search(six_targets(), iterations=1500, seed=4, threads=2)
    again = search(six_targets(), iterations=1500, seed=4, threads=2)
    np.testing.assert_array_equal(merged.root.visits, again.root.visits)
    assert merged.simulations == 3000
    seeds = np.random.SeedSequence(seed_value(4)).generate_state(2, np.uint64)
    trees = [search(six_targets(), iterations=1500, seed=int(s)) for s in seeds]
    visits = {a: 0 for a in merged.root.actions}
    weighted = {a: 0.0 for a in merged.root.actions}
    for t in trees:
        for a, n, v in zip(t.root.actions, t.root.visits, t.root.values, strict=True):
            visits[a] += n
            weighted[a] += n * v
    assert merged.root.visits.tolist() == [visits[a] for a in merged.root.actions]
    np.testing.assert_allclose(
        merged.root.values, [weighted[a] / visits[a] for a in merged.root.actions]
    )
    assert merged.best_action == merged.root.best
    assert merge_stats([None, None]) is None
    plan = search(six_targets(current_action=2), iterations=1000, seed=1, threads=2)
    assert plan.best_action == 2 and plan.after[FIND].visits.sum() > 0


def test_robust_backup_finds_the_gamble_optimum_with_values_between_mean_and_max():
    """A state worth its most visited action: on the gamble it picks the expectimax optimum,
    and its root values lie between the mean backup's (pessimistic) and the exact ones."""
    exact = np.array([gamble_q_exact(0, 0, a) for a in range(3)])
    root = (np.zeros(2, dtype=np.int64),)
    robust = search_mdp(
        GAMBLE, root, 3, 4, np.zeros(1), SearchOptions(backup=Robust()), iterations=100000, seed=5
    )
    mean = search_mdp(
        GAMBLE, root, 3, 4, np.zeros(1), SearchOptions(backup=Expected()), iterations=100000, seed=5
    )
    assert robust.best_action == int(np.argmax(exact))
    assert np.all(robust.root.values <= exact + 1e-9)
    assert np.all(robust.root.values >= mean.root.values - 1e-9)
    assert abs(robust.root.values[robust.best_action] - exact.max()) < 0.02


@pytest.mark.parametrize("weight", [0.0, 0.5, 1.0])
def test_mixmax_backup_mixes_the_best_action_and_the_mean_return(weight):
    """State 1 (below the root's only action) has two actions whose simulations returned -10
    and -20: it is worth ``lambda * (-10) + (1 - lambda) * (-15)``."""
    tree = new_tree(0, 8)
    tree.s_first[0], tree.s_count[0] = 0, 1
    tree.s_first[1], tree.s_count[1] = 1, 2
    tree.a_p[:3] = 1.0
    tree.a_child[0, 0] = 1
    path_state, path_outcome = np.array([0, 1]), np.array([FIND, FIND])
    for x, ret in ((1, -10.0), (2, -20.0)):
        back_max(Max(weight), tree, path_state, np.array([0, x]), path_outcome, 2, ret)
    assert tree.a_value[0] == weight * -10.0 + (1.0 - weight) * -15.0
    assert list(tree.a_value[1:3]) == [-10.0, -20.0]


def test_no_follow_rollout_draws_uniformly_among_the_targets_not_just_found():
    problem = six_targets()
    env = problem.env()
    state = problem.root_state()
    state[0][2] = 3  # target 3 was just found
    rng = np.array([7], dtype=np.uint64)
    draws = [
        uniform_no_follow(UniformNoFollow(), env, state, rng, np.empty(6, dtype=np.int64))
        for _ in range(3000)
    ]
    counts = np.bincount(draws, minlength=6)
    assert counts[3] == 0
    others = counts[[0, 1, 2, 4, 5]]
    assert np.all(np.abs(others - 600) < 4 * np.sqrt(600 * 0.8))  # binomial(3000, 1/5)
    state[0][1] = 0b001000  # only the followed target is left: it follows
    assert uniform_no_follow(UniformNoFollow(), env, state, rng, np.empty(6, dtype=np.int64)) == 3


def test_even_root_split_alternates_and_the_weighted_split_follows_the_probability():
    """Even: simulation ``k`` takes the find exactly when ``k`` is odd (the paper's rule).
    Weighted: after ``K`` simulations the find had ``floor(K f)`` of them, with
    ``f = p^(2/3) / (p^(2/3) + (1 - p)^(2/3))``."""
    two = np.array([0.9, 1.0 - 0.9])
    assert [_root_outcome(k, two, False) for k in range(10)] == [
        FIND if k % 2 == 1 else MISS for k in range(10)
    ]
    for p in (0.5, 0.9, 0.99):
        f = p ** (2 / 3) / (p ** (2 / 3) + (1 - p) ** (2 / 3))
        for total in (10, 101, 1000):
            outcomes = [_root_outcome(k, np.array([p, 1.0 - p]), True) for k in range(total)]
            assert outcomes.count(FIND) == int(np.floor(total * f))


def test_root_split_over_three_outcomes_gives_each_its_share_in_turn():
    """Three outcomes, one impossible: even, the two possible ones alternate and the impossible
    one gets none; weighted, after ``K`` simulations outcome 0 had ``floor(K f_0)`` and each
    count is within one of ``K f_o``, ``f_o`` proportional to ``p_o^(2/3)``."""
    p = np.array([0.6, 0.0, 0.4])
    assert [_root_outcome(k, p, False) for k in range(6)] == [2, 0, 2, 0, 2, 0]
    p = np.array([0.7, 0.2, 0.1])
    w = p ** (2 / 3)
    for total in (10, 101, 1000):
        counts = np.bincount([_root_outcome(k, p, True) for k in range(total)], minlength=3)
        assert counts[0] == int(np.floor(total * w[0] / w.sum()))
        assert np.all(np.abs(counts - total * w / w.sum()) <= 1.0)


def test_weighted_root_split_gives_the_likely_outcome_more_simulations():
    problem = six_targets(current_action=0)
    even = search(problem, MAX, iterations=4000, seed=1)
    weighted = search(problem, MAX._replace(root_split="weighted"), iterations=4000, seed=1)
    p = even.root.p[0, FIND]
    assert 0.5 < p < 1.0
    share = weighted.after[FIND].visits.sum() / sum(a.visits.sum() for a in weighted.after)
    even_share = even.after[FIND].visits.sum() / sum(a.visits.sum() for a in even.after)
    f = p ** (2 / 3) / (p ** (2 / 3) + (1 - p) ** (2 / 3))
    assert abs(even_share - 0.5) < 0.01 and abs(share - f) < 0.01


def test_common_rollouts_value_siblings_with_the_same_random_decisions():
    """A gamble whose every pull wins (rewards 1, 2, 4 over three pulls, value
    ``-(score - 5)^2``): the only randomness left is the rollout's choice of actions. After
    four simulations (the root's rollout, then one per action), each root action is valued by
    one rollout of the last two pulls. With common random numbers those rollouts choose the
    same pulls, so the three values are those of one common increment; with the single stream
    they are not, for most seeds."""
    sure = Gamble(np.ones(3), np.array([1, 2, 4]), 3, 5.0)
    rewards = np.array([1, 2, 4])
    increments = {int(a + b) for a in rewards for b in rewards}

    def one_increment(values):
        return any(np.allclose(values, -((rewards + inc - 5.0) ** 2)) for inc in increments)

    for common, expect in ((True, 20), (False, None)):
        hits = sum(
            one_increment(
                search_mdp(
                    sure,
                    (np.zeros(2, dtype=np.int64),),
                    3,
                    4,
                    np.zeros(1),
                    SearchOptions(common_rollouts=common),
                    iterations=4,
                    seed=seed,
                ).root.values
            )
            for seed in range(20)
        )
        assert hits == expect if expect else hits < 10
