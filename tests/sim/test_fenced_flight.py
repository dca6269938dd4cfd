"""A fenced mission in the simulator: a no-fly circle across the straight flight from the start
to a target, and every planner's flown path keeps out of it by the margin at every step; the
scenario's ``fence:`` block validated in one line; the record carries the fence for the
figures."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.models.vehicle import FencedHolonomicVehicle, HolonomicVehicle
from hptrack.registry import make_planner
from hptrack.scenario import parse_scenario, random_scenario
from hptrack.sim.episode import run_episode
from hptrack.viz.mission import mission_figure

MARGIN = 10.0
QUICK = {
    "mcts": {"iterations": 60},
    "arvi": {"max_nodes_per_level": 200},
    "astar": {"max_expansions": 200},
}


def fenced(n_targets: int, seed: int, budget: float = 240.0) -> tuple:
    """A random scenario with a no-fly circle centred halfway to target 0, a third of the way
    long in radius; ``(scenario, circle)``."""
    data = random_scenario(n_targets, seed=seed).model_dump(mode="json")
    start = np.array(data["agent"]["position"])
    goal = np.array(data["targets"][0]["mean"][:2])
    centre = 0.5 * (start + goal)
    radius = math.dist(start, goal) / 3
    circle = [float(centre[0]), float(centre[1]), radius]
    data["budget"] = budget
    data["fence"] = {"exclusions": [{"circle": circle}], "margin": MARGIN}
    return parse_scenario(data), circle


@pytest.mark.parametrize(
    "planner", ["greedy", "clairvoyant", "mcts", "arvi", "astar", "coverage", "tour"]
)
def test_every_planner_keeps_out_of_the_zone(planner):
    scenario, (cx, cy, radius) = fenced(3, seed=4)
    options = dict(QUICK.get(planner, {}))
    if planner == "coverage":
        options["target"] = scenario.targets[0].id
    record = run_episode(scenario, make_planner(planner, options), seed=0)
    path = record.agent_path
    gaps = np.hypot(path[:, 0] - cx, path[:, 1] - cy)
    assert gaps.min() >= radius + MARGIN - 1e-6, gaps.min()
    straight = np.hypot(*(scenario.means()[0, :2] - path[0]))
    assert straight > 2 * radius  # the zone does lie across the straight flight


def test_a_fenced_mission_flies_a_fenced_vehicle_and_draws_the_fence():
    scenario, _ = fenced(2, seed=1, budget=60.0)
    assert isinstance(scenario.mission_spec().record.vehicle, FencedHolonomicVehicle)
    free = random_scenario(2, seed=1)
    assert isinstance(free.mission_spec().record.vehicle, HolonomicVehicle)
    record = run_episode(scenario, make_planner("greedy"), seed=0)
    assert record.fence == scenario.fence.spec()
    labels = [h.get_label() for h in mission_figure(record).legends[0].legend_handles]
    assert "no-fly zone" in labels and f"margin ({MARGIN:g} m)" in labels


def _with_fence(fence: dict, **agent) -> dict:
    data = random_scenario(2, seed=0).model_dump(mode="json")
    data["agent"] = {**data["agent"], **agent}
    data["fence"] = fence
    return data


@pytest.mark.parametrize(
    ("fence", "agent", "needles"),
    [
        ({"exclusions": [{"circle": [0.0, 0.0, 50.0]}]}, {}, ("agent.position", "no-fly")),
        (
            {"exclusions": [{"polygon": [[0, 0], [10, 10], [10, 0], [0, 10]]}]},
            {"position": [500.0, 500.0]},
            ("fence: exclusion 0: not a simple polygon",),
        ),
        (
            {"inclusion": {"polygon": [[-10, -10], [10, -10], [10, 10], [-10, 10]]}},
            {},
            ("targets.0.mean", "out of the UAV's sight"),
        ),
        ({"exclusions": [{"circle": [0.0, 0.0, -5.0]}]}, {}, ("fence.exclusions.0",)),
        ({"margin": -1.0}, {}, ("fence.margin",)),
    ],
)
def test_a_bad_fence_is_one_line(cli, tmp_path, fence, agent, needles):
    import yaml

    path = tmp_path / "fenced.yaml"
    path.write_text(yaml.safe_dump(_with_fence(fence, **agent)))
    cli("scenario", "check", path).refused(*needles)


def test_a_random_fenced_scenario_is_written_and_read_back(cli, tmp_path):
    from hptrack.scenario import load_scenario

    path = tmp_path / "fenced.yaml"
    result = cli("scenario", "random", "--targets", 4, "--seed", 2, "--no-fly", "-o", path)
    assert result.code == 0, result.err
    scenario = load_scenario(path)
    assert scenario.fence is not None and 1 <= len(scenario.fence.exclusions) <= 3
    plain = tmp_path / "plain.yaml"
    assert cli("scenario", "random", "--targets", 4, "--seed", 2, "-o", plain).code == 0
    assert load_scenario(plain).targets == scenario.targets
