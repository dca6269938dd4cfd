"""The revisit tour inside the search (``rollout="tour_plan"``, ``fortify``): the tour as a
rollout policy flies as the tour planner scores it, the fortified rule, the tree's return sums,
and the invariant of rollout over a base policy on toy missions solved exactly."""

import math

import numpy as np
import pytest

from hptrack.interface import InputError
from hptrack.models.mission import mission_record
from hptrack.planning.backups import Max
from hptrack.planning.fortified import fortified_choice
from hptrack.planning.hierarchical import MctsSettings
from hptrack.planning.search import SearchOptions
from hptrack.planning.subtask_mdp import (
    FIND,
    MISS,
    PlanningProblem,
    SubtaskOptions,
    apply_outcome,
    copy_state,
    expand_action,
    is_available,
    n_actions,
    new_work,
    terminal_value,
)
from hptrack.planning.subtask_search import search
from hptrack.planning.tour import (
    TourRollout,
    TourSettings,
    cyclic_order,
    fly_tour,
    plan_tour,
    tour_choice,
    tour_score,
)
from hptrack.planning.tree import ActionStats
from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode


def stats(values, visits, sums, squares):
    k = len(values)
    return ActionStats(
        np.arange(k),
        np.array(visits),
        np.array(values, dtype=float),
        np.full((k, 2), 0.5),
        np.zeros((k, 2), dtype=np.int64),
        np.array(sums, dtype=float),
        np.array(squares, dtype=float),
    )


def test_standard_errors_are_those_of_the_mean_return():
    """Returns 1, 2, 3 through action 0 (sample variance 1) and 5, 5 through action 1; action
    2 seen once."""
    s = stats([2.0, 5.0, 0.0], [3, 2, 1], [6.0, 10.0, 0.0], [14.0, 50.0, 0.0])
    assert s.standard_errors()[0] == pytest.approx(math.sqrt(1 / 3), rel=1e-12)
    assert s.standard_errors()[1] == 0.0
    assert s.standard_errors()[2] == math.inf


def test_the_fortified_rule_keeps_the_base_unless_the_search_beats_it_by_its_error():
    # action 1 is best by 1.0; the difference's standard error is hypot(0.5, 0.5) = 0.707
    s = stats([0.0, 1.0], [4, 4], [0.0, 4.0], [4 * 0.75, 4 * 1.75])
    assert s.standard_errors() == pytest.approx([0.5, 0.5])
    assert fortified_choice(s, 0) == 1
    wide = stats([0.0, 1.0], [4, 4], [0.0, 4.0], [4 * 3.0, 4 * 4.0])  # errors 1, 1: 1.41
    assert fortified_choice(wide, 0) == 0
    assert fortified_choice(wide, 1) == 1
    assert fortified_choice(wide, 5) == 1  # a base the search never tried: the search's best
    assert fortified_choice(wide, -1) == 1
    assert fortified_choice(None, 3) == 3 and fortified_choice(None, -1) is None


def random_problem(n, seed, budget=300.0, available=None):
    scenario = random_scenario(n, seed=seed, homogeneous=True)
    mission = scenario.mission_spec()
    return mission, PlanningProblem(
        mission.record,
        np.asarray(scenario.agent.position, dtype=float),
        np.array([t.mean for t in scenario.targets], dtype=float),
        np.array([t.covariance for t in scenario.targets], dtype=float),
        budget,
        available=available,
    )


@pytest.mark.parametrize("dwell", [0.0, 10.0])
def test_the_tour_rollout_flies_the_tour_as_the_tour_planner_scores_it(dwell):
    """With ``min_find = 0`` (no target let go), stepping `tour_choice` through the MDP with
    the same outcome draws gives `fly_tour`'s return and first action, bit for bit."""
    for seed in range(3):
        mission, problem = random_problem(6, seed)
        env = problem.env(SubtaskOptions(dwell=dwell, miss="keep"))
        root = problem.root_state()
        order = cyclic_order(
            problem.means[:, :2],
            problem.agent_position,
            np.arange(6),
            None,
            mission.agent_speed,
        )
        draws = np.random.default_rng(seed).random(problem.n_steps + 1)
        work = new_work()
        flown = tuple(np.array(a, copy=True) for a in root)
        gone = np.zeros(6, dtype=bool)
        value, first = fly_tour(env, flown, order, 0, 0.05, 0.0, draws, gone, work)
        state = tuple(np.array(a, copy=True) for a in root)
        actions, drawn = [], 0
        while (a := tour_choice(env, state, order, 0.05, 0.0)) >= 0:
            actions.append(a)
            p, find_steps, miss_steps = expand_action(env, state, a, work)
            if a == state[0][2] or a >= 6:  # follow or dwell: no outcome drawn
                apply_outcome(env, state, a, FIND, find_steps, work)
                continue
            found = draws[drawn] < p
            drawn += 1
            apply_outcome(
                env, state, a, FIND if found else MISS, find_steps if found else miss_steps, work
            )
        assert actions[0] == first
        assert terminal_value(env, state) == value
        if dwell:
            assert 6 in actions  # the tour dwelt


def exact_tour_value(env, state, tour, work):
    """The tour's expected ``-U`` from ``state``, every outcome enumerated."""
    a = tour_choice(env, state, tour.order, tour.settle, tour.min_find)
    if a < 0:
        return terminal_value(env, state)
    return exact_q(env, state, a, work, lambda child: exact_tour_value(env, child, tour, work))


def exact_optimum(env, state, actions, work):
    """The MDP's optimal expected ``-U`` from ``state`` (expectimax)."""
    values = [
        exact_q(env, state, a, work, lambda c: exact_optimum(env, c, actions, work))
        for a in range(actions)
        if is_available(env, state, a)
    ]
    return max(values) if values else terminal_value(env, state)


def exact_q(env, state, a, work, value_of):
    """``sum_o p_o value_of(state after a, o)``."""
    p, find_steps, miss_steps = expand_action(env, state, a, work)
    total = 0.0
    for outcome, prob, steps in ((FIND, p, find_steps), (MISS, 1.0 - p, miss_steps)):
        if prob <= 0.0:
            continue
        child = tuple(np.array(x, copy=True) for x in state)
        copy_state(env, state, child)
        apply_outcome(env, child, a, outcome, steps, work)
        total += prob * value_of(child)
    return total


def toy_problem(seed):
    """Three targets 150 to 400 m from the agent, 45 s of budget: every history is a few
    sub-tasks long, so the MDP is solved exactly by enumeration."""
    rng = np.random.default_rng(seed)
    mission = mission_record(0.5, 30.0, 30.0, 100.0, 10.0 * np.eye(2), np.full(3, 3e-4))
    angle = rng.uniform(0, 2 * np.pi, 3)
    radius = rng.uniform(150.0, 400.0, 3)
    means = np.column_stack(
        [radius * np.cos(angle), radius * np.sin(angle), rng.normal(0, 1, 3), rng.normal(0, 1, 3)]
    )
    cov = np.stack([np.diag([rng.uniform(200, 3000)] * 2 + [0.3, 0.3]) for _ in range(3)])
    return PlanningProblem(mission, np.zeros(2), means, cov, 45.0)


@pytest.mark.parametrize("seed", range(4))
def test_the_fortified_search_is_never_worse_than_its_tour_in_the_mdp(seed):
    """Rollout's invariant on toys solved exactly: the action the fortified search takes,
    followed by the best continuation, is worth at least the tour's own plan; the tree opened
    to the end values the root at the MDP's optimum; the tour planner's Monte Carlo score is
    the tour's exact value within three standard errors."""
    problem = toy_problem(seed)
    subtask = SubtaskOptions()
    env = problem.env(subtask)
    root = problem.root_state()
    work = new_work()
    order = cyclic_order(problem.means[:, :2], problem.agent_position, np.arange(3), None, 30.0)
    settings = TourSettings(min_find=0.0)
    draws = np.random.default_rng(seed).random((settings.samples, problem.n_steps + 1))
    plan = plan_tour(env, root, order, settings, draws, work)
    tour = TourRollout(plan.order, plan.settle, settings.min_find)
    v_tour = exact_tour_value(env, root, tour, work)
    options = SearchOptions(backup=Max(), rollout=tour)
    result = search(problem, options, subtask, iterations=20_000, seed=seed)
    choice = fortified_choice(result.root, plan.first)
    assert choice is not None
    q = exact_q(
        env, root, choice, work, lambda c: exact_optimum(env, c, n_actions(3, subtask), work)
    )
    assert q >= v_tour - 1e-9
    optimum = exact_optimum(env, root, n_actions(3, subtask), work)
    assert result.root.values.max() == pytest.approx(optimum, rel=1e-12)
    many = np.random.default_rng(seed + 10).random((4000, problem.n_steps + 1))
    scratch = tuple(np.array(a, copy=True) for a in root)
    returns = []
    for row in many:
        copy_state(env, root, scratch)
        returns.append(
            fly_tour(env, scratch, tour.order, 0, tour.settle, 0.0, row, np.zeros(3, bool), work)[0]
        )
    mean, se = np.mean(returns), np.std(returns) / math.sqrt(len(returns))
    assert abs(mean - v_tour) < 3 * se + 1e-12
    scored, _ = tour_score(
        env, root, scratch, tour.order, 0, tour.settle, 0.0, many, np.zeros(3, bool), work
    )
    assert scored == pytest.approx(mean, rel=1e-12)


def test_the_return_sums_are_the_sampled_backups_means():
    """With the paper's backup, an action's value is the running mean of its returns: the
    tree's return sums over the visits give it."""
    _, problem = random_problem(4, 0)
    result = search(problem, SearchOptions(), iterations=3000, seed=1)
    root = result.root
    assert root.visits.sum() == 2999  # the first simulation rolls out from the root itself
    assert root.return_sum / root.visits == pytest.approx(root.values, rel=1e-9)
    assert np.all(root.standard_errors() > 0)


def test_fortify_needs_the_tour_rollout():
    with pytest.raises(
        InputError,
        match="planner 'mcts': option fortify=true applies only to rollout=tour_plan, "
        "got rollout=uniform",
    ):
        MctsSettings.from_options("mcts", {"fortify": True, "rollout": "uniform"})
    assert MctsSettings.from_options("mcts", {"fortify": True}).rollout == "tour_plan"


def test_a_mission_with_the_tour_inside_the_search_is_deterministic_and_logs_the_tour():
    scenario = random_scenario(5, seed=2, homogeneous=True, budget=240.0)
    options = {"iterations": 300, "rollout": "tour_plan", "fortify": True, "dwell": 10}
    first = run_episode(scenario, make_planner("mcts", options))
    again = run_episode(scenario, make_planner("mcts", options))
    assert first.uncertainty == again.uncertainty
    searches = first.info["searches"]
    assert searches and all("tour_actions" in s for s in searches)
    assert all(len(s["tour_actions"]) in (1, 2) for s in searches)
    plain = run_episode(scenario, make_planner("mcts", {"iterations": 300}))
    assert all("tour_actions" not in s for s in plain.info["searches"])
