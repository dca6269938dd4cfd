"""CBBA (`hptrack.planning.cbba`): a toy worked by hand, the sequential greedy assignment it
equals under diminishing marginal gains (fully connected, on a line, with dropped messages), no
conflicts, the committed task, the bundle's size, and the half-the-optimum bound."""

import itertools

import numpy as np
import pytest

from hptrack.planning.cbba import cbba


def additive(scores):
    """``S_i(p) = sum_j c_ij``: marginal scores that never change."""
    return lambda i, path: float(sum(scores[i, j] for j in path))


def discounted(weights, discount):
    """``S_i(p) = sum_n w_i,p_n discount^n``: the n-th task flown is worth less the later it
    comes; a task's marginal score only falls as the path grows (diminishing gains), and order
    matters."""
    return lambda i, path: float(sum(weights[i, j] * discount**n for n, j in enumerate(path)))


def coverage(chances, element_weights):
    """``S_i(p) = sum_e w_e (1 - prod_(j in p) (1 - q_ije))``: the expected weight of the
    elements the tasks of ``p`` see, each task ``j`` seeing element ``e`` with chance
    ``q_ije``: a submodular score (diminishing gains) that ignores the order."""
    return lambda i, path: float(
        element_weights @ (1.0 - np.prod(1.0 - chances[i][list(path)], axis=0))
    )


def sequential_greedy(n_agents, n_tasks, path_value, max_bundle):
    """The sequential greedy assignment: repeatedly give the pair (agent, task) of the highest
    marginal score (best insertion, the later of equal positions) until none is positive."""
    paths = [[] for _ in range(n_agents)]
    winners, bids = np.full(n_tasks, -1), np.zeros(n_tasks)
    while True:
        best = (0.0, None, None, None)
        for i in range(n_agents):
            if len(paths[i]) == max_bundle:
                continue
            base = path_value(i, tuple(paths[i]))
            for j in np.flatnonzero(winners < 0):
                for n in range(len(paths[i]) + 1):
                    trial = (*paths[i][:n], int(j), *paths[i][n:])
                    gain = path_value(i, trial) - base
                    if gain > best[0] or (gain == best[0] and best[1] == i and best[2] == j):
                        best = (gain, i, int(j), n)
        gain, i, j, n = best
        if i is None:
            return tuple(map(tuple, paths)), winners, bids
        paths[i].insert(n, j)
        winners[j], bids[j] = i, gain


def line_links(n_agents):
    """Neighbours on a line ``0 - 1 - ... - (m - 1)``."""
    links = np.zeros((n_agents, n_agents), dtype=bool)
    for i in range(n_agents - 1):
        links[i, i + 1] = links[i + 1, i] = True
    return links


def total(allocation, path_value):
    return sum(path_value(i, path) for i, path in enumerate(allocation.paths))


def assert_conflict_free(allocation, n_tasks):
    flown = [j for path in allocation.paths for j in path]
    assert len(flown) == len(set(flown))
    expected = np.full(n_tasks, -1)
    for i, path in enumerate(allocation.paths):
        expected[list(path)] = i
    np.testing.assert_array_equal(allocation.winners, expected)
    for path, bundle in zip(allocation.paths, allocation.bundles, strict=True):
        assert sorted(path) == sorted(bundle)


def random_instances(kind, count, seed, n_agents=3, n_tasks=7):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        if kind == "additive":
            yield additive(rng.uniform(0.0, 10.0, (n_agents, n_tasks)))
        elif kind == "discounted":
            yield discounted(rng.uniform(0.0, 10.0, (n_agents, n_tasks)), 0.8)
        else:
            chances = rng.random((n_agents, n_tasks, 8)) ** 3
            yield coverage(chances, rng.uniform(0.5, 2.0, 8))


def test_two_agents_three_tasks_worked_by_hand():
    """Scores ``[[5, 3, 1], [4, 4, 2]]``, two tasks per bundle. Round 1: agent 0 bids 5, 3 on
    tasks 0, 1 and agent 1 bids 4, 4 on the same (the lower task first on its tie); agent 0
    keeps 0 and loses 1 (4 > 3), agent 1 loses 0 (5 > 4) and so releases 1. Round 2: agent 0
    adds task 2 at 1, agent 1 tasks 1 and 2 at 4 and 2; agent 0 loses task 2 (2 > 1). Round 3
    changes nothing."""
    scores = np.array([[5.0, 3.0, 1.0], [4.0, 4.0, 2.0]])
    result = cbba(2, 3, additive(scores), max_bundle=2)
    assert result.paths == ((0,), (1, 2)) and result.bundles == ((0,), (1, 2))
    np.testing.assert_array_equal(result.winners, [0, 1, 1])
    np.testing.assert_array_equal(result.bids, [5.0, 4.0, 2.0])
    assert (result.rounds, result.converged) == (3, True)


def test_a_round_limit_stops_before_convergence():
    scores = np.array([[5.0, 3.0, 1.0], [4.0, 4.0, 2.0]])
    result = cbba(2, 3, additive(scores), max_bundle=2, max_rounds=1)
    assert (result.rounds, result.converged) == (1, False)
    assert result.paths == ((0,), ())  # after round 1's releases


@pytest.mark.parametrize("warp_bids", [True, False])
@pytest.mark.parametrize("kind", ["additive", "discounted", "coverage"])
def test_fully_connected_it_is_the_sequential_greedy_assignment(kind, warp_bids):
    """The paper's bids and the warped ones alike (warping changes nothing under diminishing
    gains)."""
    for path_value in random_instances(kind, 20, seed=1):
        result = cbba(3, 7, path_value, max_bundle=3, warp_bids=warp_bids)
        paths, winners, bids = sequential_greedy(3, 7, path_value, 3)
        assert result.converged
        assert result.paths == paths
        np.testing.assert_array_equal(result.winners, winners)
        np.testing.assert_allclose(result.bids, bids, rtol=1e-12)


@pytest.mark.parametrize("kind", ["additive", "discounted", "coverage"])
def test_on_a_line_it_converges_to_the_same_within_tasks_times_diameter_rounds(kind):
    n_agents, n_tasks = 5, 7
    for path_value in random_instances(kind, 10, seed=2, n_agents=n_agents, n_tasks=n_tasks):
        result = cbba(n_agents, n_tasks, path_value, 2, links=line_links(n_agents))
        assert result.converged
        assert result.paths == sequential_greedy(n_agents, n_tasks, path_value, 2)[0]
        # Theorem 1: min(n_tasks, L m) D rounds to agree, one more to see that nothing changes
        assert result.rounds <= min(n_tasks, 2 * n_agents) * (n_agents - 1) + 1


def test_dropped_messages_delay_the_same_allocation():
    """A link that carries nothing every other round, and only one direction on the others."""

    def links(round_index):
        if round_index % 2:
            return np.zeros((3, 3), dtype=bool)
        return np.tril(np.ones((3, 3), dtype=bool)) | (round_index % 4 == 0)

    for path_value in random_instances("discounted", 10, seed=3):
        full = cbba(3, 7, path_value, 3)
        slow = cbba(3, 7, path_value, 3, links=links)
        assert slow.converged and slow.rounds > full.rounds
        assert slow.paths == full.paths
        assert cbba(3, 7, path_value, 3, links=links).paths == slow.paths  # deterministic


@pytest.mark.parametrize("kind", ["additive", "discounted", "coverage"])
def test_no_task_is_flown_twice(kind):
    rng = np.random.default_rng(4)
    for path_value in random_instances(kind, 10, seed=5, n_agents=4, n_tasks=9):
        links = rng.random((4, 4)) < 0.6
        links |= links.T | line_links(4)  # connected
        result = cbba(4, 9, path_value, 3, links=links)
        assert result.converged
        assert_conflict_free(result, 9)


def test_the_bundle_never_exceeds_its_size():
    """Six tasks all worth 1: agent 0 wins the first ``L`` (ties go to the lower agent), agent
    1 the next ones, up to ``L``."""
    for max_bundle in (1, 2, 4):
        result = cbba(2, 6, additive(np.ones((2, 6))), max_bundle)
        second = min(max_bundle, 6 - max_bundle)
        assert result.bundles == (
            tuple(range(max_bundle)),
            tuple(range(max_bundle, max_bundle + second)),
        )


def test_equal_scores_go_to_the_lower_agent_and_the_lower_task():
    result = cbba(2, 3, additive(np.ones((2, 3))), max_bundle=1)
    assert result.paths == ((0,), (1,))
    np.testing.assert_array_equal(result.winners, [0, 1, -1])


def test_the_committed_task_stays_first_and_is_never_outbid():
    """Agent 1 values task 0 most of all and would win it; agent 0 flies it, so keeps it,
    first. Then agent 1 outbids agent 0 on task 1 (3 against 5 * 0.5 behind task 0), and agent
    0 wins task 2 (2 * 0.5 = 1 behind task 0, against 1 * 0.5 for agent 1 behind task 1)."""
    weights = np.array([[1.0, 5.0, 2.0], [9.0, 3.0, 1.0]])
    path_value = discounted(weights, 0.5)
    assert cbba(2, 3, path_value, 2).winners[0] == 1
    result = cbba(2, 3, path_value, 2, committed=[0, None])
    assert result.converged
    assert result.paths == ((0, 2), (1,)) and result.bundles == ((0, 2), (1,))
    np.testing.assert_array_equal(result.winners, [0, 1, 0])
    np.testing.assert_array_equal(result.bids, [1.0, 3.0, 1.0])  # task 0: its value alone


def test_nothing_is_inserted_before_the_committed_task():
    """Alone, agent 0 would fly task 1 (worth 5) before task 0 (worth 1)."""
    path_value = discounted(np.array([[1.0, 5.0]]), 0.5)
    assert cbba(1, 2, path_value, 2).paths == ((1, 0),)
    assert cbba(1, 2, path_value, 2, committed=[0]).paths == ((0, 1),)


def test_a_committed_task_counts_in_the_bundle():
    result = cbba(1, 3, additive(np.ones((1, 3))), max_bundle=1, committed=[2])
    assert result.paths == ((2,),)


def brute_force(n_agents, n_tasks, path_value, max_bundle):
    """The best total over every assignment of the tasks (or none) and every flying order."""
    best = 0.0
    for owners in itertools.product(range(-1, n_agents), repeat=n_tasks):
        groups = [[j for j in range(n_tasks) if owners[j] == i] for i in range(n_agents)]
        if any(len(g) > max_bundle for g in groups):
            continue
        value = sum(
            max(path_value(i, order) for order in itertools.permutations(g))
            for i, g in enumerate(groups)
        )
        best = max(best, value)
    return best


@pytest.mark.parametrize("kind", ["discounted", "coverage"])
def test_at_least_half_the_optimum_under_diminishing_gains(kind):
    ratios = []
    for path_value in random_instances(kind, 15, seed=6, n_agents=2, n_tasks=5):
        result = cbba(2, 5, path_value, 3)
        best = brute_force(2, 5, path_value, 3)
        ratios.append(total(result, path_value) / best)
    assert min(ratios) >= 0.5
    assert min(ratios) < 1.0  # the bound is not vacuous: greedy misses the optimum somewhere


def test_bad_arguments_are_refused():
    path_value = additive(np.ones((2, 3)))
    with pytest.raises(ValueError, match="committed"):
        cbba(2, 3, path_value, 2, committed=[1, 1])
    with pytest.raises(ValueError, match="committed"):
        cbba(2, 3, path_value, 2, committed=[3, None])
    with pytest.raises(ValueError, match="links"):
        cbba(2, 3, path_value, 2, links=np.ones((3, 3), dtype=bool))
    with pytest.raises(ValueError, match="max_bundle"):
        cbba(2, 3, path_value, 0)


def test_warped_bids_converge_where_rising_gains_make_the_paper_cycle():
    """``S_i(p) = sum w_ij + 3 (pairs in p)``, ``w = [[3, 1, 1], [1, 1, 4]]``: a task is worth
    more in a longer bundle. Agent 0 bids 3, 4, 7 on tasks 0, 1, 2 and agent 1 bids 4, 4, 7 on
    2, 0, 1: each loses its first task, releases its whole bundle, and so on for ever. Warped,
    agent 0 bids 3, 3, 3 and agent 1 4, 4, 4: agent 1 wins everything in one round."""
    weights = np.array([[3.0, 1.0, 1.0], [1.0, 1.0, 4.0]])

    def path_value(i, path):
        return float(sum(weights[i, j] for j in path) + 3.0 * len(path) * (len(path) - 1) / 2)

    assert not cbba(2, 3, path_value, 3, warp_bids=False, max_rounds=50).converged
    result = cbba(2, 3, path_value, 3)
    assert (result.converged, result.rounds) == (True, 2)
    assert result.paths == ((), (2, 0, 1))
    np.testing.assert_array_equal(result.bids, [4.0, 4.0, 4.0])
