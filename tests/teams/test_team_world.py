"""A team in the scenario and the simulator: ``agents:`` (a team of one is ``agent:``), every
UAV moving by its own speed and looking by its own sensor, the first UAV drawing first."""

import numpy as np
import pytest

from hptrack.interface import InputError
from hptrack.registry import make_planner
from hptrack.scenario.model import Scenario
from hptrack.scenario.random import random_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World


def team_of(scenario: Scenario, agents: list[dict], **fields) -> Scenario:
    data = scenario.model_dump()
    data.pop("agent")
    return Scenario.model_validate({**data, "agents": agents, **fields})


def test_agent_beside_agents_is_refused():
    data = random_scenario(2, 0).model_dump()
    data["agent"] = {"position": (5.0, 0.0)}
    with pytest.raises(ValueError, match="give agent .one UAV. or agents"):
        Scenario.model_validate({**data, "agents": [{"position": (0.0, 0.0)}]})


def test_a_team_of_one_is_the_one_agent():
    scenario = random_scenario(3, 4)
    one = team_of(scenario, [scenario.agent.model_dump()])
    a = run_episode(scenario, make_planner("greedy"))
    b = run_episode(one, make_planner("greedy"))
    assert np.array_equal(a.per_target_logdet, b.per_target_logdet)
    assert np.array_equal(a.agent_paths, b.agent_paths)


def test_an_idle_far_uav_changes_nothing_for_the_first():
    """A second UAV that never sees a target draws nothing: the first UAV's mission is the
    one-UAV mission, bit for bit (the first UAV draws first)."""
    scenario = random_scenario(3, 7)
    team = team_of(scenario, [{"position": (0.0, 0.0)}, {"position": (9e6, 9e6)}])
    alone, world = World(scenario), World(team)
    rng = np.random.default_rng(1)
    for _ in range(300):
        waypoint = rng.uniform(-500, 500, size=2)
        alone.step(*waypoint)
        world.step_team(np.array([waypoint, [9e6, 9e6]]))
    assert np.array_equal(alone.means, world.means)
    assert np.array_equal(alone.covariances, world.covariances)
    assert world.uncertainty == alone.uncertainty


def test_each_uav_moves_by_its_own_speed_and_sees_by_its_own_footprint():
    scenario = random_scenario(1, 0).model_copy(
        update={
            "targets": [
                random_scenario(1, 0)
                .targets[0]
                .model_copy(
                    update={"mean": (400.0, 0.0, 0.0, 0.0), "truth": (400.0, 0.0, 0.0, 0.0)}
                )
            ]
        }
    )
    team = team_of(
        scenario,
        [
            {"position": (0.0, 0.0)},
            {"position": (400.0, 70.0), "speed": 100.0, "sensor_diameter": 80.0},
        ],
    )
    world = World(team)
    assert not world.seen[0]  # 70 m away, beyond the second UAV's 40 m radius
    world.step_team(np.array([[100.0, 0.0], [400.0, 0.0]]))
    assert np.allclose(world.agents, [[15.0, 0.0], [400.0, 20.0]])  # 30 and 100 m/s, 0.5 s
    assert world.seen[0]  # now 20 m: inside the second UAV's footprint only
    mission = team.mission_spec()
    assert mission.n_vehicles == 2
    assert mission.vehicle_mission(1).agent_speed == 100.0
    assert mission.vehicle_mission(1).sensor_diameter == 80.0
    assert mission.vehicle_mission(0).agent_speed == 30.0


def test_a_uav_slower_than_a_target_is_named():
    scenario = random_scenario(2, 0)
    speed = float(np.hypot(*scenario.targets[0].mean[2:]))
    with pytest.raises(ValueError, match=r"agents\.1\.speed"):
        team_of(scenario, [{"position": (0.0, 0.0)}, {"speed": speed / 2}])


def test_one_uav_planners_refuse_a_team_in_one_line():
    team = random_scenario(3, 0, team=2)
    for name in ("mcts", "greedy", "clairvoyant", "arvi", "astar", "tour", "stationary"):
        with pytest.raises(InputError, match="flies one vehicle.*team-mcts") as err:
            run_episode(team, make_planner(name))
        assert "\n" not in str(err.value)


def test_random_team_has_the_same_targets():
    one, team = random_scenario(5, 3), random_scenario(5, 3, team=3)
    assert one.targets == team.targets
    assert team.starts().shape == (3, 2)
