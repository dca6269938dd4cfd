import json

import yaml
from typer.testing import CliRunner

from hptrack.cli.app import app
from hptrack.sim.record import EpisodeRecord

runner = CliRunner()


def test_simulate_random_writes_json_plot_and_record(tmp_path):
    result = runner.invoke(app, ["simulate", "--random", "--targets", "2", "--seed", "3",
                                 "--planner", "greedy", "--json", str(tmp_path / "m.json"),
                                 "--plot", str(tmp_path / "m.png"),
                                 "--record", str(tmp_path / "m.npz")])
    assert result.exit_code == 0, result.output
    assert "U" in result.output and "t2" in result.output
    summary = json.loads((tmp_path / "m.json").read_text())
    assert {"U", "per_target_logdet", "detections", "planner", "seed"} <= set(summary)
    assert summary["planner"] == "greedy" and summary["seed"] == 3
    assert (tmp_path / "m.png").read_bytes()[:4] == b"\x89PNG"
    record = EpisodeRecord.load(tmp_path / "m.npz")
    assert record.uncertainty == summary["U"]


def test_scenario_random_then_check_then_simulate(tmp_path):
    path = tmp_path / "s.yaml"
    result = runner.invoke(app, ["scenario", "random", "--targets", "3", "--seed", "5",
                                 "--homogeneous", "-o", str(path)])
    assert result.exit_code == 0, result.output
    assert len(yaml.safe_load(path.read_text())["targets"]) == 3
    assert runner.invoke(app, ["scenario", "check", str(path)]).exit_code == 0
    result = runner.invoke(app, ["simulate", str(path), "--planner", "stationary",
                                 "--json", str(tmp_path / "o.json")])
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "o.json").read_text())["seed"] == 5


def test_bad_scenario_exits_non_zero_with_one_line(tmp_path):
    path = tmp_path / "bad.yaml"
    data = {"targets": [{"id": "a", "mean": [0, 0, 40, 0], "process_noise": 1e-4,
                         "covariance": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]}
    path.write_text(yaml.safe_dump(data))
    result = runner.invoke(app, ["simulate", str(path)])
    assert result.exit_code == 2
    assert "Traceback" not in result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "targets.0.mean" in lines[0] and "40 m/s" in lines[0]


def test_unknown_planner_and_missing_input_are_clean_errors():
    result = runner.invoke(app, ["simulate", "--random", "--planner", "nope"])
    assert result.exit_code == 2 and "unknown planner 'nope'" in result.output
    result = runner.invoke(app, ["simulate"])
    assert result.exit_code == 2 and "--random" in result.output


def test_planner_options_are_checked_by_name_and_type():
    result = runner.invoke(app, ["simulate", "--random", "--planner", "greedy",
                                 "--iterations", "5"])
    assert result.exit_code == 2 and "planner 'greedy' takes no option iterations" in result.output
    result = runner.invoke(app, ["simulate", "--random", "--planner", "mcts", "-o", "explore=2"])
    assert result.exit_code == 2 and "'exploration'" in result.output
    result = runner.invoke(app, ["simulate", "--random", "--planner", "arvi", "-o",
                                 "horizon=abc"])
    assert result.exit_code == 2 and "ArviParams.horizon" in result.output
    assert "'abc'" in result.output
