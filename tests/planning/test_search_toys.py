"""The tree search (paper Algorithm 1) apart from the sub-task MDP, on toy MDPs whose answers are
known exactly: a one-action problem (the running-mean backup), a two-armed bandit (exact visit
counts from the textbook UCB1 rule and the published splitmix64 stream), a three-step gamble
solved by expectimax, and a dice game whose actions have three chance outcomes."""

import math
import os
import subprocess
import sys
from functools import cache
from pathlib import Path
from typing import NamedTuple

import numba
import numpy as np
import pytest

from hptrack.planning import MdpKernels, register_mdp, search_mdp
from hptrack.planning.backups import Max
from hptrack.planning.search import DEFAULT_EXPLORATION, SearchOptions

MASK64 = 2**64 - 1


class Stream:
    """splitmix64 (Steele, Lea, Flood 2014) with the search's seeding: an independent model of
    the search's random draws."""

    def __init__(self, seed: int) -> None:
        self.state = int(np.random.SeedSequence(seed).generate_state(1, np.uint64)[0])

    def uniform(self) -> float:
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK64
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK64
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK64
        z ^= z >> 31
        return (z >> 11) * 2.0**-53


# --- a bandit: one pull of one of the arms, win (p) or lose ---------------------------------
class Bandit(NamedTuple):
    p: np.ndarray
    win: np.ndarray
    lose: np.ndarray


@numba.njit
def bandit_copy(env, src, dst):
    dst[0][0] = src[0][0]
    dst[0][1] = src[0][1]


@numba.njit
def bandit_available(env, state, a):
    return state[0][0] < 0


@numba.njit
def bandit_expand(env, state, a, p, payload, work):
    p[0], p[1] = env.p[a], 1.0 - env.p[a]
    payload[0] = payload[1] = 0


@numba.njit
def bandit_apply(env, state, a, outcome, payload, work):
    state[0][0] = a
    state[0][1] = 1 if outcome == 0 else 0


@numba.njit
def bandit_value(env, state):
    a = state[0][0]
    return env.win[a] if state[0][1] == 1 else env.lose[a]


register_mdp(
    Bandit, MdpKernels(bandit_copy, bandit_available, bandit_expand, bandit_apply, bandit_value)
)


def bandit_search(p, win, lose, iterations, seed):
    env = Bandit(np.array(p, float), np.array(win, float), np.array(lose, float))
    root = (np.array([-1, 0], dtype=np.int64),)
    return search_mdp(env, root, len(p), 2, np.zeros(1), iterations=iterations, seed=seed)


def test_running_mean_after_one_two_and_three_simulations():
    """One action, win 1 or lose 0 with p = 0.5. The first simulation expands the root and rolls
    out (no action statistic yet); each later one backs its return up into the action's running
    mean: V = r_2, then (r_2 + r_3) / 2, then (r_2 + r_3 + r_4) / 3."""
    seed = 11
    stream = Stream(seed)
    stream.uniform()  # simulation 1: the rollout's choice of the only action
    stream.uniform()  # ... and its outcome
    returns = [1.0 if stream.uniform() < 0.5 else 0.0 for _ in range(3)]
    assert 0.0 < sum(returns) < 3.0  # the seed gives both outcomes, so the mean is informative
    for sims, expected in (
        (1, None),
        (2, returns[0]),
        (3, np.mean(returns[:2])),
        (4, np.mean(returns)),
    ):
        result = bandit_search([0.5], [1.0], [0.0], sims, seed)
        if expected is None:
            assert result.root.actions.size == 0  # the root is a leaf: no action slots yet
        else:
            assert result.root.visits.tolist() == [sims - 1]
            assert result.root.values[0] == pytest.approx(expected, rel=1e-12)


def reference_ucb1(p, win, lose, iterations, seed, c=DEFAULT_EXPLORATION):
    """Algorithm 1 on a one-pull bandit, by the book: the first simulation rolls out with a
    uniformly random arm; then unvisited arms first, else UCB1 on values normalised by the
    range of returns seen; running-mean backups."""
    stream = Stream(seed)
    arms = len(p)
    visits, values = [0] * arms, [0.0] * arms
    arm = int(stream.uniform() * arms)
    ret = win[arm] if stream.uniform() < p[arm] else lose[arm]
    low = high = ret
    for n in range(iterations - 1):
        unvisited = [a for a in range(arms) if visits[a] == 0]
        if unvisited:
            arm = unvisited[0]
        else:
            scale = 1.0 / (high - low) if high > low else 0.0
            scores = [
                (values[a] - low) * scale + c * math.sqrt(math.log(n) / visits[a])
                for a in range(arms)
            ]
            arm = int(np.argmax(scores))
        ret = win[arm] if stream.uniform() < p[arm] else lose[arm]
        visits[arm] += 1
        values[arm] += (ret - values[arm]) / visits[arm]
        low, high = min(low, ret), max(high, ret)
    return visits, values


@pytest.mark.parametrize("seed", [0, 3])
def test_exact_visit_counts_on_a_two_armed_bandit(seed):
    p, win, lose = [0.3, 0.7], [1.0, 1.0], [0.0, 0.0]
    visits, values = reference_ucb1(p, win, lose, 300, seed)
    result = bandit_search(p, win, lose, 300, seed)
    assert result.root.visits.tolist() == visits
    np.testing.assert_allclose(result.root.values, values, rtol=1e-12)
    assert visits[1] > visits[0]  # the better arm gets most of the simulations
    assert result.best_action == 1


# --- a three-step gamble: each step, pursue one of three bets ---------------------------------
class Gamble(NamedTuple):
    p: np.ndarray
    reward: np.ndarray
    steps: int
    goal: float


@numba.njit
def gamble_copy(env, src, dst):
    dst[0][0] = src[0][0]
    dst[0][1] = src[0][1]


@numba.njit
def gamble_available(env, state, a):
    return state[0][0] < env.steps


@numba.njit
def gamble_expand(env, state, a, p, payload, work):
    p[0], p[1] = env.p[a], 1.0 - env.p[a]
    payload[0], payload[1] = env.reward[a], 0


@numba.njit
def gamble_apply(env, state, a, outcome, payload, work):
    state[0][0] += 1
    state[0][1] += payload


@numba.njit
def gamble_value(env, state):
    return -((state[0][1] - env.goal) ** 2)


register_mdp(
    Gamble, MdpKernels(gamble_copy, gamble_available, gamble_expand, gamble_apply, gamble_value)
)

GAMBLE = Gamble(np.array([0.9, 0.5, 0.25]), np.array([1, 2, 4]), 3, 5.0)


@cache
def gamble_value_exact(t: int, score: int) -> float:
    """Expectimax: the optimal expected value of a state."""
    if t == GAMBLE.steps:
        return -((score - GAMBLE.goal) ** 2)
    return max(gamble_q_exact(t, score, a) for a in range(3))


def gamble_q_exact(t: int, score: int, a: int) -> float:
    p, r = GAMBLE.p[a], int(GAMBLE.reward[a])
    return p * gamble_value_exact(t + 1, score + r) + (1 - p) * gamble_value_exact(t + 1, score)


def test_search_finds_the_expectimax_optimum_and_its_values():
    exact = [gamble_q_exact(0, 0, a) for a in range(3)]
    optimum = int(np.argmax(exact))
    assert sorted(exact)[-1] - sorted(exact)[-2] > 0.3  # a clear optimum
    errors = []
    for sims in (1000, 10000, 100000):
        result = search_mdp(
            GAMBLE, (np.zeros(2, dtype=np.int64),), 3, 4, np.zeros(1), iterations=sims, seed=5
        )
        assert result.best_action == optimum
        most = int(np.argmax(result.root.visits))
        assert result.root.actions[most] == optimum
        errors.append(abs(result.root.values[most] - exact[optimum]))
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.15  # -5.65 against the exact -5.56 after 100,000 simulations


def test_a_toy_search_leaves_the_disk_cache_usable_by_another_process():
    """A process that searched a toy MDP (as this module does) must not leave in the kernels'
    disk cache anything that a process without the toy cannot load."""
    here = Path(__file__).parent
    toy = (
        "import test_search_toys as t; "
        "t.bandit_search(np.array([0.5, 0.5]), np.zeros(2), np.ones(2), 50, 0)"
    )
    subprocess.run(
        [sys.executable, "-c", f"import numpy as np; {toy}"],
        check=True,
        env={
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(here), os.environ.get("PYTHONPATH", "")]),
        },
        cwd=here,
    )
    plan = (
        "from hptrack.registry import make_planner; "
        "from hptrack.scenario.random import random_scenario; "
        "from hptrack.sim.episode import run_episode; "
        "run_episode(random_scenario(2, seed=0, homogeneous=True), "
        "make_planner('mcts', {'iterations': 200}))"
    )
    subprocess.run([sys.executable, "-c", plan], check=True, cwd=here.parent.parent)


def test_a_bandit_of_300_arms_keeps_every_action_index():
    """300 sure arms (``p = 1``), arm 217 pays 1, the others 0: after the root's rollout, UCB1
    tries each arm once (the first unvisited slot first), so 301 simulations give every arm one
    visit valued exactly, and the best is 217, an index past ``int8``."""
    n = 300
    win = np.zeros(n)
    win[217] = 1.0
    result = bandit_search(np.ones(n), win, np.zeros(n), n + 1, 0)
    assert result.root.actions.tolist() == list(range(n))
    assert result.root.visits.tolist() == [1] * n
    np.testing.assert_array_equal(result.root.values, win)
    assert result.best_action == 217
    more = bandit_search(np.ones(n), win, np.zeros(n), 2000, 0)
    assert more.best_action == 217 and int(np.argmax(more.root.visits)) == 217


def test_an_mdp_declaring_more_actions_than_the_tree_holds_is_refused():
    from hptrack.planning import MAX_ACTIONS

    env = Bandit(np.ones(1), np.ones(1), np.zeros(1))
    root = (np.array([-1, 0], dtype=np.int64),)
    with pytest.raises(ValueError, match=f"declares {MAX_ACTIONS + 1} actions; the search takes"):
        search_mdp(env, root, MAX_ACTIONS + 1, 2, np.zeros(1), iterations=1)


# --- dice: two throws, each of one of three dice with three faces (an impossible one) ---------
class Dice(NamedTuple):
    """The gamble's state ``[throws, score]`` and kernels, but each die has three faces."""

    p: np.ndarray  # (dice, faces): each face's probability
    reward: np.ndarray  # (dice, faces): each face's points
    steps: int
    goal: float


@numba.njit
def dice_expand(env, state, a, p, payload, work):
    for o in range(env.p.shape[1]):
        p[o] = env.p[a, o]
        payload[o] = env.reward[a, o]


register_mdp(
    Dice,
    MdpKernels(
        gamble_copy,
        gamble_available,
        dice_expand,
        gamble_apply,
        gamble_value,
        n_outcomes=lambda env: env.p.shape[1],
    ),
)

DICE = Dice(
    np.array([[0.5, 0.3, 0.2], [0.1, 0.8, 0.1], [0.6, 0.0, 0.4]]),
    np.array([[0, 1, 3], [0, 2, 4], [0, 1, 5]]),
    2,
    5.0,
)


@cache
def dice_value_exact(throws: int, score: int) -> float:
    """Expectimax over three outcomes: the optimal expected value of a state."""
    if throws == DICE.steps:
        return -((score - DICE.goal) ** 2)
    return max(dice_q_exact(throws, score, a) for a in range(3))


def dice_q_exact(throws: int, score: int, a: int) -> float:
    return sum(
        DICE.p[a, o] * dice_value_exact(throws + 1, score + int(DICE.reward[a, o]))
        for o in range(3)
        if DICE.p[a, o] > 0.0
    )


MAX = SearchOptions(backup=Max())


def dice_search(iterations, seed, fixed=-1):
    root = (np.zeros(2, dtype=np.int64),)
    return search_mdp(
        DICE, root, 3, 3, np.zeros(1), MAX, iterations=iterations, seed=seed, fixed=fixed
    )


def test_three_outcomes_reach_the_expectimax_values_exactly():
    """With the max backup the search over 3 x 3 outcomes per throw ends with the exact
    expectimax values of every root action once the tree holds the whole game."""
    exact = [dice_q_exact(0, 0, a) for a in range(3)]
    assert sorted(exact)[-1] - sorted(exact)[-2] > 0.3  # a clear optimum
    result = dice_search(5000, 3)
    assert result.root.p.shape == (3, 3)
    np.testing.assert_array_equal(result.root.p, DICE.p)
    np.testing.assert_array_equal(result.root.payload, DICE.reward)
    np.testing.assert_allclose(result.root.values, exact, rtol=1e-12)
    assert result.best_action == int(np.argmax(exact))


def test_replanning_with_three_outcomes_plans_after_each_and_shares_the_root_evenly():
    """The current action fixed: one plan per outcome, each the exact best next throw, and the
    simulations after the first shared evenly among the three outcomes."""
    sims = 3001
    result = dice_search(sims, 4, fixed=0)
    assert len(result.after) == 3
    for o in range(3):
        exact = [dice_q_exact(1, int(DICE.reward[0, o]), a) for a in range(3)]
        np.testing.assert_allclose(result.after[o].values, exact, rtol=1e-12)
        assert result.best_after(o) == int(np.argmax(exact))
    shares = [result.after[o].visits.sum() for o in range(3)]
    assert max(shares) - min(shares) <= 1 and sum(shares) >= sims - 4


def test_an_impossible_outcome_is_never_drawn_nor_planned():
    """Die 2 never shows its middle face: after fixing it, that outcome's child is never
    reached, so no plan exists for it."""
    result = dice_search(600, 5, fixed=2)
    assert result.after[1] is None and result.best_after(1) is None
    assert result.after[0].visits.sum() > 0 and result.after[2].visits.sum() > 0


def test_outcome_draws_over_three_faces_follow_the_stream():
    """One throw of one die: after the root's rollout, each simulation draws a face from the
    tree's stream (face ``o`` when ``u`` falls in its share of ``[0, 1)``, in order) and the
    paper's backup keeps the running mean of the returns, exactly."""
    one = Dice(DICE.p[:1], DICE.reward[:1], 1, 5.0)
    seed, sims = 9, 40
    stream = Stream(seed)
    stream.uniform()  # the rollout's choice of the only action
    stream.uniform()  # ... and its face
    cumulative = np.cumsum(one.p[0])
    returns = []
    for _ in range(sims - 1):
        face = min(int(np.searchsorted(cumulative, stream.uniform(), side="right")), 2)
        returns.append(-((one.reward[0, face] - one.goal) ** 2))
    result = search_mdp(
        one, (np.zeros(2, dtype=np.int64),), 1, 2, np.zeros(1), iterations=sims, seed=seed
    )
    assert result.root.visits.tolist() == [sims - 1]
    assert result.root.values[0] == pytest.approx(np.mean(returns), rel=1e-12)
    assert len(set(returns)) == 3  # the seed shows every face
