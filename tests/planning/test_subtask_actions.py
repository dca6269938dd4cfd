"""Typed sub-task actions: the one action table, the one feasibility rule shared by the search,
the planner and the sub-task environment, the one flight, and m vehicles at the interfaces."""

import numpy as np
import pytest

from hptrack.interface import InputError, MissionSpec, Observation, vehicle_waypoints
from hptrack.planning.subtask_flight import SubtaskFlight, feasible
from hptrack.planning.subtask_mdp import PlanningProblem, SubtaskOptions, is_available
from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.subtasks import HOVER, ActionTable, SubtaskAction

PRIOR = np.diag([900.0, 900.0, 0.5, 0.5])


def test_the_table_numbers_targets_then_dwells_and_maps_back():
    table = ActionTable(3, (4, 8))
    assert table.size == 5
    assert table.action(0, None) == SubtaskAction("pursue", 0)
    assert table.action(2, 2) == SubtaskAction("follow", 2)
    assert table.action(3, 1) == SubtaskAction("dwell", 1, 4)
    assert table.action(4, 1) == SubtaskAction("dwell", 1, 8)
    assert table.action(None, 1) is None
    for index in range(5):
        assert table.index(table.action(index, 1)) == index
    with pytest.raises(ValueError, match="action index 5 is not in a table of 5"):
        table.action(5)
    with pytest.raises(ValueError, match="no dwell of 6 steps"):
        table.index(SubtaskAction("dwell", 1, 6))
    with pytest.raises(ValueError, match="a hover has no action index"):
        table.index(HOVER)
    with pytest.raises(ValueError, match="sub-task kind must be one of"):
        SubtaskAction("orbit", 0)


def _observation(agent, means, remaining):
    n = len(means)
    return Observation(
        0,
        0.0,
        remaining,
        np.asarray(agent, dtype=float),
        np.asarray(means, dtype=float),
        np.repeat(PRIOR[None], n, axis=0),
        np.zeros(n, dtype=bool),
    )


def test_the_planner_and_the_search_agree_on_what_can_be_flown():
    """`feasible` on an observation (the planner's and the environment's check) is the search's
    `is_available` at the root, for every action: targets near and far, out of the action list,
    the target just found, dwells short and longer than the budget left."""
    n, seen = 5, set()
    options = SubtaskOptions(dwell=(2.0, 60.0))
    spec = MissionSpec(process_noise=np.full(n, 3e-4), target_ids=tuple("abcde"))
    table = ActionTable(n, (4, 120))
    for seed in range(12):
        rng = np.random.default_rng(seed)
        means = np.column_stack([rng.uniform(-3000, 3000, (n, 2)), rng.uniform(-8, 8, (n, 2))])
        remaining = float(rng.choice([3.0, 40.0, 150.0, 900.0]))
        available = rng.random(n) < 0.7
        last = int(np.flatnonzero(available)[0]) if available.any() and seed % 2 else None
        observation = _observation(rng.uniform(-500, 500, 2), means, remaining)
        problem = PlanningProblem.from_observation(
            spec.record, observation, available=available, last_found=last
        )
        env, state = problem.env(options), problem.root_state()
        for a in range(table.size):
            flag = feasible(table, a, spec, observation, available, last)
            assert flag == bool(is_available(env, state, a)), (seed, a)
            seen.add((table.action(a, last).kind, flag))
    # a follow can always be flown while the budget lasts
    assert seen == {(k, f) for k in ("pursue", "dwell") for f in (True, False)} | {("follow", True)}


def test_a_target_faster_than_the_agent_cannot_be_pursued_even_when_it_is_over_it():
    """A coverage sub-task needs a target slower than the agent, also when the belief mean is
    already in the footprint (the intercept is then 0 steps): the rule refuses it."""
    spec = MissionSpec(process_noise=np.full(2, 3e-4), target_ids=("slow", "fast"))
    observation = _observation([0.0, 0.0], [[10.0, 0.0, 2.0, 0.0], [20.0, 0.0, 31.0, 0.0]], 900.0)
    table, every = ActionTable(2), np.ones(2, dtype=bool)
    assert feasible(table, 0, spec, observation, every, None)
    assert not feasible(table, 1, spec, observation, every, None)
    assert feasible(table, 1, spec, observation, every, 1)  # followed once found


def test_a_dwell_flies_its_length_at_the_targets_predicted_position():
    spec = MissionSpec(process_noise=np.full(1, 3e-4), target_ids=("a",))
    mean = [100.0, 50.0, 4.0, -2.0]
    flight = SubtaskFlight(SubtaskAction("dwell", 0, 6), _observation([0, 0], [mean], 900.0), spec)
    assert flight.record.kind == "dwell" and flight.record.parameter == 6
    assert flight.end_step == 6
    later = Observation(5, 2.5, 897.5, np.zeros(2), np.array([mean]), PRIOR[None], np.zeros(1))
    assert not flight.done(later)
    np.testing.assert_array_equal(flight.waypoint(later), [102.0, 49.0])  # p + v tau
    ended = Observation(6, 3.0, 897.0, np.zeros(2), np.array([mean]), PRIOR[None], np.zeros(1))
    assert flight.done(ended) and not flight.found(ended)
    hover = SubtaskFlight(HOVER, ended, spec)
    np.testing.assert_array_equal(hover.waypoint(ended), [0.0, 0.0])


def test_observations_and_answers_carry_m_vehicles():
    one = _observation([3.0, 4.0], [[0.0, 0.0, 0.0, 0.0]], 10.0)
    assert one.agent_positions.shape == (1, 2) and one.n_vehicles == 1
    np.testing.assert_array_equal(one.agent_position, [3.0, 4.0])
    keyword = Observation(
        0,
        0.0,
        10.0,
        agent_position=np.array([3.0, 4.0]),
        means=np.zeros((1, 4)),
        covariances=PRIOR[None],
        detected=np.zeros(1, dtype=bool),
    )
    np.testing.assert_array_equal(keyword.agent_positions, one.agent_positions)
    two = Observation(0, 0.0, 10.0, np.array([[0.0, 1.0], [2.0, 3.0]]), *[np.zeros(1)] * 3)
    assert two.n_vehicles == 2 and two.agent_position.tolist() == [0.0, 1.0]
    assert vehicle_waypoints([1.0, 2.0], 1, "p").tolist() == [[1.0, 2.0]]
    assert vehicle_waypoints([[1.0, 2.0], [3.0, 4.0]], 2, "p").shape == (2, 2)
    with pytest.raises(ValueError, match="planner 'p' returned an invalid waypoint"):
        vehicle_waypoints([1.0, 2.0], 2, "p")
    with pytest.raises(ValueError, match="n_vehicles must be a whole number >= 1, got 0"):
        MissionSpec(n_vehicles=0)


@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("mcts", {"iterations": 50}),
        ("stationary", {}),
        ("greedy", {}),
        ("coverage", {"target": "t1"}),
        ("clairvoyant", {}),
        ("arvi", {}),
        ("astar", {}),
    ],
)
def test_every_planner_of_one_vehicle_refuses_two_in_one_line(name, options):
    scenario = random_scenario(2, seed=0)
    spec = scenario.mission_spec()
    two = MissionSpec(
        spec.time_step,
        spec.budget,
        spec.agent_speed,
        spec.sensor_diameter,
        spec.measurement_noise,
        spec.process_noise_form,
        spec.process_noise,
        spec.target_ids,
        n_vehicles=2,
    )
    planner = make_planner(name, options)
    with pytest.raises(
        InputError,
        match=rf"^planner '{name}' flies one vehicle; .*n_vehicles is 2 \(a team flies with team-",
    ):
        planner.reset(two, scenario.initial_observation(), np.random.default_rng(0))
