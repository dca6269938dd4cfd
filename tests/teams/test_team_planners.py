"""Team planners: the UAVs never claim the same target on the perfect link; a limited link
lets them; the references read the truth; a benchmark refuses a planner of one UAV."""

import numpy as np
import pytest

from hptrack.interface import InputError
from hptrack.registry import check_team, make_planner
from hptrack.scenario.random import random_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World


def claims_over(scenario, planner, steps):
    world = World(scenario)
    planner.reset(world.mission, world.observation(), np.random.default_rng(0))
    claims = [planner.claims()]
    for _ in range(steps):
        if hasattr(planner, "see_truth"):
            planner.see_truth(world.truth.copy())
        world.step_team(planner.act(world.observation()))
        claims.append(planner.claims())
    return np.array(claims)


def distinct(claims):
    held = claims[claims >= 0]
    return len(held) == len(set(held.tolist()))


@pytest.mark.parametrize(
    ("name", "options"),
    [
        ("team-greedy", {}),
        ("team-clairvoyant", {}),
        ("team-mcts", {"iterations": 200}),
        ("team-cbba", {"iterations": 200}),
    ],
)
def test_no_two_uavs_claim_one_target_on_the_perfect_link(name, options):
    scenario = random_scenario(5, 2, homogeneous=True, team=3, budget=300.0)
    claims = claims_over(scenario, make_planner(name, options), 600)
    assert all(distinct(row) for row in claims)
    assert (claims[1:] >= 0).all(axis=0).any()  # some UAV holds a target all along


def test_a_lossy_link_lets_two_uavs_chase_one_target():
    scenario = random_scenario(2, 0, homogeneous=True, team=2, budget=100.0)
    claims = claims_over(
        scenario, make_planner("team-greedy", {"share_period": 1000.0}), 200
    )  # no share in the mission: each UAV chases the most uncertain target alone
    assert not all(distinct(row) for row in claims)


def test_a_team_beats_its_one_uav_on_a_spread_mission():
    one = random_scenario(6, 5, homogeneous=True)
    team = random_scenario(6, 5, homogeneous=True, team=2)
    alone = run_episode(one, make_planner("greedy")).uncertainty
    together = run_episode(team, make_planner("team-greedy")).uncertainty
    assert together < alone - 10.0


def test_a_benchmark_refuses_a_planner_of_one_uav_for_a_team():
    with pytest.raises(InputError, match="planner 'mcts' flies one UAV; a team of 2"):
        check_team(["team-mcts", "mcts"], 2)
    check_team(["mcts"], 1)


def test_the_one_uav_env_refuses_a_team_in_one_line():
    from hptrack.envs.tracking import TrackingEnv

    env = TrackingEnv(n_targets=3)
    with pytest.raises(InputError, match="flies 2 UAVs; this env flies one .TeamTracking-v0"):
        env.reset(options={"scenario": random_scenario(3, 0, team=2)})


def test_cbba_reallocates_on_its_period_and_keeps_pursuits():
    scenario = random_scenario(6, 1, homogeneous=True, team=2, budget=120.0)
    record = run_episode(
        scenario, make_planner("team-cbba", {"iterations": 100, "reallocate_period": 30.0})
    )
    auctions = record.info["auctions"]
    assert [a["step"] for a in auctions] == [0, 60, 120, 180]
    assert all(a["converged"] for a in auctions)
    for a in auctions:  # conflict-free bundles, each UAV's current target first in its own
        held = [t for path in a["paths"] for t in path]
        assert len(held) == len(set(held))
        for target, path in zip(a["committed"], a["paths"], strict=True):
            assert target is None or path[0] == target
    assert any(t is not None for a in auctions[1:] for t in a["committed"])


def test_a_uav_follows_the_target_it_found_though_another_claims_it():
    """Over a lossy link two UAVs may find one target; each may still follow or dwell on it."""
    for seed in (0, 8, 9):  # scenarios where both UAVs found one target
        scenario = random_scenario(4, seed, homogeneous=True, team=2, budget=300.0)
        planner = make_planner(
            "team-mcts", {"iterations": 100, "share_period": 20.0, "drop_rate": 0.5}
        )
        record = run_episode(scenario, planner)
        assert record.info["link"]["lost"] > 0


@pytest.mark.parametrize("name", ["team-mcts", "team-cbba"])
def test_a_teams_searches_keep_their_preset_whatever_the_single_uav_default(name, monkeypatch):
    """Every UAV's search in a team defaults to `TEAM_PRESET` (the preset the team tables were
    measured with), not to the one-UAV default; a named preset still wins."""
    from hptrack.planning import hierarchical
    from hptrack.registry import planner_settings
    from hptrack.teams.sequential import TEAM_PRESET

    monkeypatch.setattr(hierarchical, "DEFAULT_PRESET", "revisit")
    assert hierarchical.MctsSettings().rollout == "tour_plan"
    team = planner_settings(name, {})
    assert (team.preset, team.rollout, team.iterations) == (TEAM_PRESET, "uniform", 100_000)
    assert (
        team.member_settings().canonical()
        == hierarchical.MctsSettings(preset=TEAM_PRESET).canonical()
    )
    named = planner_settings(name, {"preset": "revisit"})
    assert (named.rollout, named.iterations) == ("tour_plan", 20_000)
    member = named.member_settings()
    assert hierarchical.MctsSettings.from_canonical(member.canonical()).preset == "revisit"
