"""The revisit-tour planner (``tour``): its order on toy geometries, its plan on a toy mission,
determinism, options and the CLI."""

import numpy as np
import pytest
import yaml

from hptrack.planning.tour import (
    TourPlanner,
    TourSettings,
    improved_tour,
    nearest_insertion,
    or_opt_move,
    tour_length,
    two_opt_move,
)
from hptrack.registry import make_planner
from hptrack.scenario import random_scenario
from hptrack.scenario.io import parse_scenario
from hptrack.sim.episode import run_episode
from hptrack.subtasks import read_subtasks


def distances(points):
    gaps = points[:, None, :] - points[None, :, :]
    return np.hypot(gaps[..., 0], gaps[..., 1])


def test_local_search_finds_the_polygon_from_any_order():
    """Twelve points on a circle, numbered at random: the shortest closed tour is the polygon
    (perimeter 24 sin(pi / 12) for a unit circle), and the tour visits them round the circle."""
    rng = np.random.default_rng(3)
    angles = rng.permutation(12) * (2 * np.pi / 12)
    cost = distances(np.column_stack([np.cos(angles), np.sin(angles)]))
    tour = improved_tour(cost)
    assert sorted(tour) == list(range(12)) and tour[0] == 0
    assert tour_length(cost, tour) == pytest.approx(24 * np.sin(np.pi / 12), rel=1e-12)
    steps = np.diff(np.round(angles[tour] / (2 * np.pi / 12)).astype(int) % 12) % 12
    assert set(steps) in ({1}, {11})


def test_two_opt_uncrosses_and_or_opt_moves_a_node_back_into_line():
    square = distances(np.array([[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]))
    crossed = np.array([0, 1, 2, 3])  # two diagonals: 2 + 2 sqrt(2)
    assert tour_length(square, crossed) == pytest.approx(2 + 2 * np.sqrt(2))
    assert two_opt_move(square, crossed)
    assert tour_length(square, crossed) == pytest.approx(4.0)
    assert not two_opt_move(square, crossed) and not or_opt_move(square, crossed)
    line = distances(np.column_stack([[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], np.zeros(6)]))
    detour = np.array([0, 3, 1, 2, 4, 5])  # node 3 out of place: 2 * 5 + 4
    assert tour_length(line, detour) == pytest.approx(14.0)
    assert or_opt_move(line, detour)  # the first improving move: 3 after 1, length 12
    assert tour_length(line, detour) == pytest.approx(12.0)
    assert or_opt_move(line, detour) and not or_opt_move(line, detour)
    assert tour_length(line, detour) == pytest.approx(10.0)
    assert tour_length(line, nearest_insertion(line)) == pytest.approx(10.0)


def toy_mission(far_x: float, budget: float = 200.0):
    """The agent at the origin, two still targets with small beliefs: t1 300 m east, t2 at
    ``far_x`` m on the x axis."""
    cov = "[[25, 0, 0, 0], [0, 25, 0, 0], [0, 0, 0.5, 0], [0, 0, 0, 0.5]]"
    return parse_scenario(
        yaml.safe_load(
            f"""
time_step: 0.5
budget: {budget}
seed: 4
agent: {{position: [0.0, 0.0], speed: 30.0, sensor_diameter: 100.0}}
targets:
  - {{id: t1, mean: [300.0, 0.0, 0.0, 0.0], covariance: {cov}, process_noise: 0.0001}}
  - {{id: t2, mean: [{far_x}, 0.0, 0.0, 0.0], covariance: {cov}, process_noise: 0.0001}}
"""
        )
    )


def test_two_targets_and_time_for_one_the_near_one_is_pursued_and_kept():
    """40 s of budget: t1 is met after about 8 s, t2 after 28 s, and neither can be reached from
    the other in the time left. The two priors are equal, so the best plan is known: find the
    near one and stay on it to the end (measured 32 s instead of 12 s)."""
    record = run_episode(toy_mission(-900.0, budget=40.0), make_planner("tour"))
    log = read_subtasks(record.info["subtasks"], record.target_ids)
    assert log[0].kind == "pursue" and log[0].target == 0 and log[0].outcome == "found"
    assert all(entry.target == 0 and entry.kind in ("dwell", "follow") for entry in log[1:])
    assert record.info["tours"][0]["order"][0] == 0
    assert record.detections.any(axis=0).tolist() == [True, False]


def test_two_targets_the_tour_alternates_between_them():
    """Both targets are found at once wherever they are pursued (p_find 1): the tour keeps both
    and alternates, dwelling on each after its find."""
    record = run_episode(toy_mission(-900.0), make_planner("tour"))
    log = read_subtasks(record.info["subtasks"], record.target_ids)
    pursuits = [entry.target for entry in log if entry.kind == "pursue"]
    assert len(pursuits) >= 3 and np.all(np.diff(pursuits) != 0)
    assert log[1].kind == "dwell" and log[1].target == log[0].target
    assert all(entry.outcome != "missed" for entry in log)


def test_min_find_of_one_lets_every_uncertain_target_go():
    """No pursuit of these broad priors is sure to find its target: with ``min_find=1`` the
    tour pursues nothing and the agent hovers, and U is the never-observed U."""
    scenario = random_scenario(3, seed=5, homogeneous=True)
    record = run_episode(scenario, TourPlanner(TourSettings(min_find=1.0)))
    assert [entry["kind"] for entry in record.info["subtasks"]] == ["hover"]
    assert not record.detections.any()


def test_the_planner_is_deterministic_and_plans_fast_enough():
    scenario = random_scenario(6, seed=11, homogeneous=True)
    first, second = (run_episode(scenario, make_planner("tour")) for _ in range(2))
    assert first.uncertainty == second.uncertainty
    assert first.info["subtasks"] == second.info["subtasks"]
    assert [d["order"] for d in first.info["tours"]] == [d["order"] for d in second.info["tours"]]
    log = read_subtasks(first.info["subtasks"], first.target_ids)
    assert {entry.kind for entry in log} >= {"pursue", "dwell"}


@pytest.mark.parametrize(
    ("option", "needle"),
    [
        ("min_find=1.5", "option min_find must be <= 1, got 1.5"),
        ("samples=0", "option samples must be >= 1, got 0"),
        ("dwell=0", "option dwell must be > 0, got 0"),
        ("settle_variance=-1", "option settle_variance must be > 0"),
        ("miss=forget", "option miss must be 'keep' or 'drop'"),
        ("horizon=3", "unknown option horizon"),
    ],
)
def test_bad_options_are_refused_in_one_line(cli, option, needle):
    cli("simulate", "--random", "--targets", "2", "--planner", "tour", "-o", option).refused(
        "planner 'tour'", needle
    )


def test_it_flies_through_simulate_and_is_listed(cli):
    result = cli("simulate", "--random", "--targets", "3", "--seed", "1", "--planner", "tour")
    assert result.code == 0, result.err
    assert "U" in result.out
    listed = cli("planners")
    assert listed.code == 0
    assert "tour" in listed.out and "min_find" in listed.out and "settle_variance" in listed.out


def test_a_detector_that_misses_leaves_the_tour_its_targets():
    """Under a detector with ``Pd = 0.7`` per pass (draws held over the pass), no target's
    chance of a find can reach ``min_find = 0.9``; the threshold is a share of one pass's
    chance of a detection, so the tour still pursues (it used to pursue nothing and score the
    never-observed U) and finds targets."""
    from hptrack.scenario.model import FootprintSensorSpec

    sensor = FootprintSensorSpec(detection_probability=0.7, detection_correlation_time=1000.0)
    scenario = random_scenario(4, seed=0, homogeneous=True, sensor=sensor)
    record = run_episode(scenario, make_planner("tour"), belief_stride=scenario.n_steps)
    pursued = [
        s for s in read_subtasks(record.info["subtasks"], scenario.target_ids) if s.kind == "pursue"
    ]
    assert len({s.target for s in pursued}) >= 2
    assert record.detections.any(axis=0).sum() >= 2
    assert record.uncertainty < scenario.never_observed_uncertainty() - 20.0
