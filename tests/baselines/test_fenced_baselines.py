"""The baselines with a fence: ARVI and A* take as candidates only the primitives the vehicle may
fly straight, so their plans are the best of the sequences that keep out (exhaustive search on a
toy fence whose open-space plan crosses the zone) and are flown as planned; greedy's way to a
mean is the shortest free flight."""

from __future__ import annotations

import itertools
from dataclasses import replace

import numpy as np
import pytest

from hptrack.baselines.arvi import ArviPlanner, ArviSettings
from hptrack.baselines.astar import AStarPlanner, AStarSettings
from hptrack.baselines.greedy import GreedyPlanner
from hptrack.baselines.information import expand, mean_positions
from hptrack.models.beliefs import position_logdet
from hptrack.models.fence import FenceSpec, fenced_distance, segment_free
from hptrack.registry import make_planner
from hptrack.scenario import Scenario, TargetSpec
from hptrack.sim.episode import run_episode

EAST, HOVER = 1, 0
SQUARE = ((130.0, -40.0), (230.0, -40.0), (230.0, 40.0), (130.0, 40.0))
"""A no-fly square on the x axis: the first eastward primitive (150 m) ends inside it."""
MARGIN = 5.0
FENCE = FenceSpec(polygons=(SQUARE,), margin=MARGIN)
TARGET = [450.0, 0.0, 0.0, 0.0]
HORIZON = 3


def _planner(kind, mission, obs):
    if kind == "arvi":  # delta 0: exact value iteration
        planner = ArviPlanner(
            ArviSettings(horizon=HORIZON, delta_schedule_m=(0.0,), max_nodes_per_level=10**6)
        )
    else:
        planner = AStarPlanner(AStarSettings(horizon=HORIZON, max_expansions=10**6))
    planner.reset(mission, obs, np.random.default_rng(0))
    return planner


def _exhaustive(planner, obs):
    """The difference cost of each of the 9^H sequences (lexicographic order) in open space,
    and whether each primitive of it stays out of the fence."""
    k = planner.settings.control_steps
    means = mean_positions(obs.means, planner.mission.motion, HORIZON * k)
    pos, covs = obs.agent_position[None], obs.covariances[None]
    total, previous = np.zeros(1), np.array([position_logdet(obs.covariances).sum()])
    for level in range(HORIZON):
        pos, covs, unc = expand(
            planner.mission, planner.step_displacements, means[level * k : (level + 1) * k + 1],
            pos, covs,
        )  # fmt: skip
        total = np.repeat(total, 9) + unc - np.repeat(previous, 9)
        previous = unc
    fence = FENCE.compiled()
    free = []
    for sequence in itertools.product(range(9), repeat=HORIZON):
        here, ok = obs.agent_position, True
        for c in sequence:
            there = here + k * planner.step_displacements[c]
            ok &= c == HOVER or segment_free(fence, *here, *there)
            here = there
        free.append(ok)
    return total, np.array(free)


@pytest.mark.parametrize("kind", ["arvi", "astar"])
def test_the_fenced_plan_is_the_best_that_keeps_out(kind, make_mission, make_observation):
    mission, obs = make_mission(1), make_observation([TARGET])
    fenced = replace(mission, fence=FENCE)
    open_plan, _ = _planner(kind, mission, obs).search(obs)
    np.testing.assert_array_equal(open_plan, [EAST] * HORIZON)  # straight through the square
    costs, free = _exhaustive(_planner(kind, mission, obs), obs)
    assert not free[int(np.argmin(costs))]
    plan, stats = _planner(kind, fenced, obs).search(obs)
    best = int(np.argmin(np.where(free, costs, np.inf)))
    np.testing.assert_array_equal(plan, np.unravel_index(best, (9,) * HORIZON))
    assert stats.predicted_cost == costs[best]  # scored as in open space: it is flown so


def test_the_open_space_children_are_unchanged_and_the_blocked_one_is_not_a_candidate(
    make_mission, make_observation
):
    mission, obs = make_mission(1), make_observation([TARGET])
    displacements = _planner("arvi", mission, obs).step_displacements
    means = mean_positions(obs.means, mission.motion, 10)
    args = (displacements, means, obs.agent_position[None], obs.covariances[None])
    _, open_covs, open_unc = expand(mission, *args)
    _, covs, unc = expand(replace(mission, fence=FENCE), *args)
    blocked = np.isinf(unc)
    np.testing.assert_array_equal(np.flatnonzero(blocked), [EAST])
    np.testing.assert_array_equal(unc[~blocked], open_unc[~blocked])
    np.testing.assert_array_equal(covs[~blocked], open_covs[~blocked])
    np.testing.assert_array_equal(covs[EAST], obs.covariances)  # the node's


STATIC_PRIOR = ((900.0, 100.0, 0.0, 0.0), (100.0, 800.0, 0.0, 0.0), (0.0, 0.0, 0.3, 0.0),
                (0.0, 0.0, 0.0, 0.3))  # fmt: skip


@pytest.mark.parametrize("planner", ["arvi", "astar"])
def test_a_fenced_episode_is_flown_as_planned_and_never_inside(planner):
    """0 steps inside the square grown by the margin, and every step one of the planner's own
    (a heading at full speed or hover): the vehicle never had to turn the planner away."""
    target = TargetSpec(
        id="t", mean=tuple(TARGET), covariance=STATIC_PRIOR, process_noise=0.0, truth=tuple(TARGET)
    )
    scenario = Scenario(
        seed=1,
        targets=[target],
        budget=60.0,
        fence={"exclusions": [{"polygon": [list(c) for c in SQUARE]}], "margin": MARGIN},
    )
    record = run_episode(scenario, make_planner(planner), seed=0)
    path = record.agent_path
    (x0, y0), (x1, y1) = np.min(SQUARE, axis=0) - MARGIN, np.max(SQUARE, axis=0) + MARGIN
    inside = (path[:, 0] > x0) & (path[:, 0] < x1) & (path[:, 1] > y0) & (path[:, 1] < y1)
    assert not inside.any()
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    np.testing.assert_allclose(steps[steps > 1e-9], 15.0, rtol=1e-9)
    assert record.detections[:, 0].any()  # it gets round to the target


def test_greedy_reaches_by_the_shortest_free_flight(make_mission, make_observation):
    mission, obs = make_mission(1), make_observation([TARGET])
    fenced = replace(mission, fence=FENCE)
    planner = GreedyPlanner()
    planner.reset(fenced, obs, np.random.default_rng(0))
    length = fenced_distance(FENCE.compiled(), obs.agent_position, TARGET[:2])
    assert length > 450.0 + 1.0  # around the square
    assert planner._reach_times(obs)[0] == length / mission.agent_speed
