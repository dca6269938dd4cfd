"""The sub-task MDP's action list beyond one ``int64`` word (63 targets per word): the layout,
a miss and a pass on a target of the second word, a search on 100 targets, the cap."""

import math

import numpy as np
import pytest
import yaml

from hptrack.models.mission import MAX_TARGETS, mission_record
from hptrack.planning.subtask_mdp import (
    FIND,
    I_LAST,
    I_MASK,
    MISS,
    PlanningProblem,
    SubtaskOptions,
    add_to_list,
    apply_outcome,
    drop_from_list,
    expand_action,
    in_list,
    int_size,
    int_state,
    is_available,
    new_work,
)
from hptrack.planning.subtask_search import search

TAU, SPEED, W = 0.5, 30.0, 100.0
R = np.array([[10.0, 1.5], [1.5, 12.0]])
FULL_WORD = 2**63 - 1


def prior(var_x=1500.0, var_y=900.0, rho=0.4):
    cov = np.diag([var_x, var_y, 0.3, 0.45])
    cov[0, 1] = cov[1, 0] = rho * math.sqrt(var_x * var_y)
    return cov


def problem_of(means, covs, budget=900.0, **kw):
    n = len(means)
    record = mission_record(TAU, budget, SPEED, W, R, np.full(n, 3e-4))
    return PlanningProblem(
        record, np.zeros(2), np.asarray(means, float), np.asarray(covs, float), budget, **kw
    )


def listed(si, n):
    return [bool(in_list(si, a)) for a in range(n)]


def test_up_to_63_targets_the_list_is_one_word_as_before():
    available = np.array([False, True, True, False, True])
    assert int_state(7, available, 2).tolist() == [7, 0b10110, 2]
    assert int_state(0, np.ones(63, dtype=bool), -1).tolist() == [0, FULL_WORD, -1]
    assert [int_size(n) for n in (1, 62, 63, 64, 126, 127, MAX_TARGETS)] == [3, 3, 3, 4, 4, 5, 7]


def test_targets_beyond_the_first_word_sit_in_the_words_after_last():
    """Target ``a`` is bit ``a % 63`` of word ``a // 63``; word 0 at ``si[1]``, the others
    after ``si[2]`` (the last found)."""
    available = np.zeros(130, dtype=bool)
    available[[0, 62, 63, 125, 126, 129]] = True
    si = int_state(3, available, 126)
    assert si.tolist() == [3, 1 | 1 << 62, 126, 1 | 1 << 62, 1 | 1 << 3]
    assert listed(si, 130) == available.tolist()
    drop_from_list(si, 125)
    add_to_list(si, 64)
    drop_from_list(si, 64)  # and out again
    add_to_list(si, 127)
    assert si.tolist() == [3, 1 | 1 << 62, 126, 1, 1 | 1 << 1 | 1 << 3]


def test_a_miss_of_target_70_drops_exactly_that_target_or_keeps_it():
    """80 targets on a ring of 900 m; a miss of target 70 (word 1, bit 7) takes it, and only
    it, out of the list with ``miss="drop"``; ``"keep"`` leaves the list as it was."""
    n = 80
    angles = 2 * math.pi * np.arange(n) / n
    means = np.column_stack([900 * np.cos(angles), 900 * np.sin(angles), np.zeros((n, 2))])
    problem = problem_of(means, [prior()] * n)
    work = new_work()
    for miss in ("drop", "keep"):
        state = problem.root_state()
        si = state[0]
        assert si.tolist() == [0, FULL_WORD, -1, 2**17 - 1]
        env = problem.env(SubtaskOptions(miss=miss))
        p, _, miss_steps = expand_action(env, state, 70, work)
        assert 0.0 < p < 1.0
        apply_outcome(env, state, 70, MISS, miss_steps, work)
        want = [a != 70 or miss == "keep" for a in range(n)]
        assert listed(si, n) == want
        assert si[I_MASK] == FULL_WORD and si[I_LAST] == -1
        assert si[3] == (2**17 - 1 if miss == "keep" else (2**17 - 1) & ~(1 << 7))
        assert is_available(env, state, 70) == (miss == "keep")


def test_a_pass_puts_target_70_back_in_the_list():
    """``passes="credit"``: the flight to target 0, 900 m east, crosses target 70's small belief
    450 m east, missed before: it is measured at the closest approach and back in the list. The
    other targets, 3 km north and beyond, are not crossed."""
    n = 71
    small = prior(100.0, 100.0, 0.0)
    means = np.zeros((n, 4))
    means[0, 0] = 900.0
    means[1:70, 0] = np.linspace(-1000.0, 1000.0, 69)
    means[1:70, 1] = 3000.0
    means[70, 0] = 450.0
    available = np.ones(n, dtype=bool)
    available[70] = False
    problem = problem_of(means, [prior()] * 70 + [small], available=available)
    state = problem.root_state()
    si, step = state[0], state[3]
    assert not in_list(si, 70)
    env, work = problem.env(SubtaskOptions(passes="credit")), new_work()
    _, find_steps, _ = expand_action(env, state, 0, work)
    apply_outcome(env, state, 0, FIND, find_steps, work)
    assert listed(si, n) == [True] * n
    assert step[70] == math.floor(find_steps / 2 + 0.5) and not step[1:70].any()


def test_a_search_on_100_targets_returns_an_available_action():
    """Targets 63..79 (the second word) missed: the root never offers them, and the plan is an
    available target."""
    rng = np.random.default_rng(0)
    n = 100
    means = np.column_stack([rng.uniform(-1000, 1000, (n, 2)), rng.uniform(-3, 3, (n, 2))])
    available = np.ones(n, dtype=bool)
    available[63:80] = False
    problem = problem_of(means, [prior()] * n, available=available)
    result = search(problem, iterations=300, seed=0)
    root_actions = set(result.root.actions.tolist())
    assert result.simulations == 300 and len(root_actions) > 63
    assert root_actions.isdisjoint(range(63, 80))
    assert result.best_action in root_actions
    assert is_available(problem.env(), problem.root_state(), result.best_action)


def test_more_than_the_cap_is_refused():
    n = MAX_TARGETS + 1
    assert MAX_TARGETS == 256
    with pytest.raises(ValueError, match="at most 256 targets, got 257"):
        mission_record(TAU, 900.0, SPEED, W, R, np.full(n, 3e-4))
    problem = problem_of(np.zeros((MAX_TARGETS, 4)), [prior()] * MAX_TARGETS)
    assert listed(problem.root_state()[0], MAX_TARGETS) == [True] * MAX_TARGETS


def test_the_cli_refuses_more_targets_than_the_cap(cli):
    result = cli("simulate", "--random", "--targets", MAX_TARGETS + 1, "--seed", 0)
    result.refused("--targets must be between 1 and 256, got 257")


def test_the_cli_simulates_80_targets_with_the_search(cli, tmp_path):
    """``hptrack simulate`` of 80 random targets (seed 0) with the default search at 200
    simulations per decision, on a 60 s budget."""
    path = tmp_path / "s.yaml"
    assert cli("scenario", "random", "--targets", 80, "--seed", 0, "-o", path).code == 0
    data = yaml.safe_load(path.read_text())
    path.write_text(yaml.safe_dump(data | {"budget": 60.0}))
    result = cli("simulate", path, "--seed", 0, "-o", "mcts.iterations=200")
    assert result.code == 0, result.err
    assert "t80" in result.out and "U" in result.out
