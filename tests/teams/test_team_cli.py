"""A team from the command line: simulate and benchmark fly it with the team planners; a
planner of one UAV, a flight without one connection per UAV and a bad team size are refused in
one line, exit 2."""

import json

from hptrack.scenario import load_scenario


def test_simulate_flies_a_random_team_and_writes_its_figure(cli, tmp_path):
    out = cli(
        "simulate", "--random", "--targets", "3", "--team", "2", "--seed", "1",
        "--planner", "team-greedy", "--plot", str(tmp_path / "team.png"),
        "--json", str(tmp_path / "team.json"),
    )  # fmt: skip
    assert out.code == 0, out.err
    assert (tmp_path / "team.png").stat().st_size > 0
    assert json.loads((tmp_path / "team.json").read_text())["planner"] == "team-greedy"


def test_a_planner_of_one_uav_and_a_bad_team_size_are_refused(cli):
    cli("simulate", "--random", "--targets", "3", "--team", "2", "--seed", "1").refused(
        "planner 'mcts' flies one vehicle", "team-mcts"
    )
    cli("simulate", "--random", "--targets", "3", "--team", "0").refused("--team", "0")
    cli("benchmark", "--planners", "team-mcts,greedy", "--targets", "3", "--team", "2").refused(
        "planner 'greedy' flies one UAV"
    )


def test_scenario_random_writes_a_team_that_flight_wants_one_connection_per_uav_for(cli, tmp_path):
    path = tmp_path / "team.yaml"
    assert cli("scenario", "random", "--targets", "3", "--team", "3", "-o", str(path)).code == 0
    assert load_scenario(path).n_vehicles == 3
    cli("fly", str(path), "--connection", "udpin://0.0.0.0:14540").refused(
        "--connection given 1 times; the scenario flies 3 UAVs"
    )


def test_a_team_planners_option_keeps_its_hyphenated_name(cli, tmp_path):
    out = cli(
        "simulate", "--random", "--targets", "2", "--team", "2", "--seed", "1",
        "--planner", "team-greedy", "-o", "team-greedy.share-period=30",
        "--json", str(tmp_path / "team.json"),
    )  # fmt: skip
    assert out.code == 0, out.err
    settings = json.loads((tmp_path / "team.json").read_text())["info"]["settings"]
    assert settings["share_period"] == 30.0
