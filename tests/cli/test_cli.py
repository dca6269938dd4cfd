"""The command line: the main job end to end, and bad input refused with one line naming what
is wrong (exit code 2), never a traceback; a bug shows its traceback (exit code 1)."""

import json
import re

import numpy as np
import pytest
import yaml

from hptrack import __version__
from hptrack.sim.record import EpisodeRecord

COV = [[900, 100, 0, 0], [100, 800, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.4]]


def scenario_file(tmp_path, name="s.yaml", budget=60.0, **changes):
    data = {
        "budget": budget,
        "seed": 1,
        "targets": [
            {"id": "a", "mean": [200.0, 0.0, 1.0, 0.0], "covariance": COV, "process_noise": 3e-4},
            {
                "id": "b",
                "mean": [-200.0, 100.0, 0.0, 1.0],
                "covariance": COV,
                "process_noise": 2e-4,
            },
        ],
    }
    data.update(changes)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def test_simulate_random_writes_json_plot_and_record(cli, tmp_path):
    result = cli(
        "simulate",
        "--random",
        "--targets",
        2,
        "--seed",
        3,
        "--planner",
        "greedy",
        "--json",
        tmp_path / "m.json",
        "--plot",
        tmp_path / "m.png",
        "--record",
        tmp_path / "m.npz",
    )
    assert result.code == 0, result.err
    assert "U" in result.out and "t2" in result.out
    summary = json.loads((tmp_path / "m.json").read_text())
    assert {"U", "per_target_logdet", "detections", "planner", "seed"} <= set(summary)
    assert summary["planner"] == "greedy" and summary["seed"] == 3
    assert summary["seed_drawn"] is False
    assert summary["info"]["settings"] == {}
    assert (tmp_path / "m.png").read_bytes()[:4] == b"\x89PNG"
    record = EpisodeRecord.load(tmp_path / "m.npz")
    assert record.uncertainty == summary["U"]
    assert np.isfinite(summary["U"])


def test_scenario_random_then_check_then_simulate(cli, tmp_path):
    path = tmp_path / "s.yaml"
    result = cli("scenario", "random", "--targets", 3, "--seed", 5, "--homogeneous", "-o", path)
    assert result.code == 0, result.err
    assert len(yaml.safe_load(path.read_text())["targets"]) == 3
    assert cli("scenario", "check", path).code == 0
    result = cli("simulate", path, "--planner", "stationary", "--json", tmp_path / "o.json")
    assert result.code == 0, result.err
    assert json.loads((tmp_path / "o.json").read_text())["seed"] == 5


def test_random_without_seed_draws_prints_and_stores_it(cli, tmp_path):
    seeds = []
    for name in ("a.json", "b.json"):
        result = cli(
            "simulate",
            "--random",
            "--targets",
            2,
            "--planner",
            "stationary",
            "--json",
            tmp_path / name,
        )
        assert result.code == 0, result.err
        summary = json.loads((tmp_path / name).read_text())
        assert summary["seed_drawn"] is True
        assert f"seed {summary['seed']} (drawn; pass --seed {summary['seed']}" in result.out
        seeds.append(summary["seed"])
    assert seeds[0] != seeds[1]
    again = cli(
        "simulate",
        "--random",
        "--targets",
        2,
        "--planner",
        "stationary",
        "--seed",
        seeds[0],
        "--json",
        tmp_path / "c.json",
    )
    assert again.code == 0
    assert (
        json.loads((tmp_path / "c.json").read_text())["U"]
        == json.loads((tmp_path / "a.json").read_text())["U"]
    )


def test_version(cli):
    result = cli("--version")
    assert result.code == 0 and result.out.strip() == f"hptrack {__version__}"


def test_target_ids_are_printed_literally(cli, tmp_path):
    path = scenario_file(
        tmp_path,
        targets=[
            {"id": "[/x] [bold]t", "mean": [0, 0, 0, 0], "covariance": COV, "process_noise": 1e-4}
        ],
    )
    result = cli("simulate", path, "--planner", "stationary", "--json", tmp_path / "o.json")
    assert result.code == 0, result.err
    assert "[/x] [bold]t" in result.out
    assert "[/x] [bold]t" in json.loads((tmp_path / "o.json").read_text())["per_target_logdet"]


def test_simulate_and_benchmark_default_to_the_heterogeneous_setting(cli):
    for command in ("simulate", "benchmark"):
        text = " ".join(re.sub("[│╭╮╰╯─]", " ", cli(command, "--help").out).split())
        assert "default heterogeneous" in text


def test_the_command_list_gives_each_summary_as_one_paragraph(cli):
    """``hptrack --help``: a command's summary is its docstring's first paragraph with the
    docstring's line breaks removed (so a line is never cut off mid-sentence)."""
    from hptrack.cli.app import app

    for info in app.registered_commands:
        assert info.short_help and "\n" not in info.short_help, info.name
    lines = cli("--help").out.splitlines()
    text = " ".join(re.sub("[│╭╮╰╯─]", " ", cli("--help").out).split())
    assert "MAPE of P_find and E[T_find] per delay, for the paper's estimator" in text
    assert not any(line.rstrip(" │").endswith("per delay,") for line in lines)


def one_line_refusal(result, *needles):
    assert result.code == 2, (result.code, result.out, result.err)
    assert "Traceback" not in result.err + result.out
    assert len(result.error_lines) == 1, result.err
    for needle in needles:
        assert needle in result.error_lines[0], (needle, result.error_lines[0])


def test_bad_scenario_exits_with_one_line(cli, tmp_path):
    path = scenario_file(
        tmp_path,
        targets=[{"id": "a", "mean": [0, 0, 40, 0], "process_noise": 1e-4, "covariance": COV}],
    )
    one_line_refusal(cli("simulate", path), "targets.0.mean", "40 m/s")


@pytest.mark.parametrize(
    "args, needles",
    [
        (["-o", "iterations=abc"], ["planner 'mcts'", "option iterations", "'abc'"]),
        (["-o", "exploration=nan"], ["planner 'mcts'", "option exploration", "finite", "nan"]),
        (["-o", "exploration=-1"], ["planner 'mcts': option exploration must be > 0, got -1"]),
        (["-o", "explore=2"], ["planner 'mcts'", "unknown option explore", "exploration"]),
        (["-o", "arvi.horizon=3"], ["planner 'arvi' is not running"]),
        (["--planner", "arvi", "-o", "horizon=abc"], ["planner 'arvi'", "option horizon", "'abc'"]),
        (["--planner", "nope"], ["unknown planner 'nope'"]),
        (["--planner", "coverage"], ["planner 'coverage'", "option target is required"]),
        (["--planner", "coverage", "-o", "target=zz"], ["option target 'zz'", "targets are"]),
        (["--seed", "-1"], ["--seed", "-1"]),
        (["--seed", "abc"], ["--seed", "abc"]),
        (["--iterations", "0"], ["--iterations", "0"]),
        (["--time-limit", "nan"], ["--time-limit", "nan"]),
        (["--belief-stride", "0"], ["--belief-stride", "0"]),
    ],
)
def test_bad_simulate_options_are_one_line_refusals(cli, args, needles):
    one_line_refusal(cli("simulate", "--random", "--targets", 2, *args), *needles)


def test_effort_flags_only_set_planners_that_have_them(cli, tmp_path):
    """``--iterations`` sets the tree search and A*'s expansion cap; greedy has no such notion
    and its record claims none."""
    result = cli(
        "simulate",
        "--random",
        "--targets",
        2,
        "--seed",
        1,
        "--planner",
        "greedy",
        "--iterations",
        5,
        "--json",
        tmp_path / "g.json",
    )
    assert result.code == 0, result.err
    assert json.loads((tmp_path / "g.json").read_text())["info"]["settings"] == {}
    assert result.error_lines == [
        "warning: planner 'greedy' has no iterations effort: --iterations 5 is ignored for it"
    ]


def test_missing_input_is_refused(cli):
    one_line_refusal(cli("simulate"), "--random")


@pytest.mark.parametrize(
    "content, needles",
    [
        (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR", ["s.yaml", "not a UTF-8 text file"]),
        (b"targets: [\n", ["s.yaml", "malformed YAML"]),
        (b"budget: 60\nbudget: 90\ntargets: []\n", ["s.yaml", "duplicated key 'budget'"]),
        ("caf\xe9: 1\n".encode("latin-1"), ["s.yaml", "not a UTF-8 text file"]),
        (b"seed: 1\x00\n", ["s.yaml", "binary"]),
    ],
)
def test_unreadable_scenario_files_name_the_file(cli, tmp_path, content, needles):
    path = tmp_path / "s.yaml"
    path.write_bytes(content)
    for command in (["scenario", "check", path], ["simulate", path]):
        one_line_refusal(cli(*command), *needles)


def test_missing_scenario_file_names_it(cli, tmp_path):
    one_line_refusal(cli("scenario", "check", tmp_path / "none.yaml"), "none.yaml", "cannot read")


@pytest.mark.parametrize(
    "changes, needles",
    [
        (dict(budget=True), ["budget", "boolean"]),
        (dict(budget=900.3), ["budget", "900.3", "whole number of time steps"]),
        (dict(budget=1e7), ["budget", "20,000,000 steps", "at most"]),
        (dict(agent={"position": [1e12, 0.0]}), ["agent.position.0", "1e+12"]),
        (
            dict(
                targets=[
                    {"id": "a", "mean": [1e12, 0, 0, 0], "covariance": COV, "process_noise": 1e-4}
                ]
            ),
            ["targets.0.mean.0", "1e+12"],
        ),
        (
            dict(
                targets=[
                    {
                        "id": "a",
                        "mean": [0, 0, 0, 0],
                        "process_noise": 1e-4,
                        "covariance": [
                            [1e300, 0, 0, 0],
                            [0, 1e300, 0, 0],
                            [0, 0, 1, 0],
                            [0, 0, 0, 1],
                        ],
                    }
                ]
            ),
            ["targets.0", "covariance"],
        ),
        (
            dict(
                targets=[
                    {
                        "id": "a",
                        "mean": [0, 0, 0, 0],
                        "process_noise": 1e-4,
                        "covariance": [
                            [1e160, 0, 0, 0],
                            [0, 1e160, 0, 0],
                            [0, 0, 1, 0],
                            [0, 0, 0, 1],
                        ],
                    }
                ]
            ),
            ["targets.0.covariance", "too large"],
        ),
        (
            dict(
                budget=900.0,
                targets=[
                    {
                        "id": "a",
                        "mean": [0, 0, 0, 0],
                        "process_noise": 1e-4,
                        "covariance": [
                            [1e3, 0, 0, 0],
                            [0, 1e3, 0, 0],
                            [0, 0, 1e150, 0],
                            [0, 0, 0, 1e150],
                        ],
                    }
                ],
            ),
            ["targets.0.covariance", "1e+150"],
        ),
        (dict(seed=True), ["seed", "boolean"]),
    ],
)
def test_extreme_scenarios_are_refused_before_any_work(cli, tmp_path, changes, needles):
    path = scenario_file(tmp_path, **changes)
    for command in (
        ["scenario", "check", path],
        ["simulate", path, "--planner", "greedy"],
        ["coverage", path, "--target", "a"],
    ):
        one_line_refusal(cli(*command), *needles)


@pytest.mark.parametrize("delay", ["inf", "nan", "-inf"])
def test_coverage_refuses_a_non_finite_delay(cli, tmp_path, delay):
    one_line_refusal(
        cli("coverage", scenario_file(tmp_path), "--target", "a", "--delay", delay),
        "--delay",
        delay.lstrip("-"),
    )


def test_output_paths_are_checked_before_the_mission_runs(cli, tmp_path, monkeypatch):
    import hptrack.cli.app as app_module

    def fail(*args, **kwargs):
        raise AssertionError("the mission ran")

    monkeypatch.setattr(app_module, "run_episode", fail)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    for option in ("--json", "--plot", "--record"):
        one_line_refusal(
            cli(
                "simulate",
                "--random",
                "--targets",
                2,
                "--planner",
                "greedy",
                option,
                blocker / "out",
            ),
            option,
            "file",
        )
    one_line_refusal(
        cli("simulate", "--random", "--targets", 2, "--planner", "greedy", "--json", tmp_path),
        "--json",
        "is a folder",
    )


def test_a_huge_record_is_refused_with_a_way_forward(cli, tmp_path):
    targets = [
        {"id": f"t{i}", "mean": [0, 0, 0, 0], "covariance": COV, "process_noise": 1e-4}
        for i in range(20)
    ]
    path = scenario_file(tmp_path, budget=450000.0, targets=targets)
    one_line_refusal(cli("simulate", path, "--planner", "stationary"), "GiB", "--belief-stride")


def test_benchmark_refuses_a_file_that_is_not_a_database(cli, tmp_path):
    db = tmp_path / "notes.txt"
    db.write_text("these are my notes, not a database\n" * 50)
    one_line_refusal(
        cli(
            "benchmark",
            "--targets",
            2,
            "--scenarios",
            1,
            "--planners",
            "stationary",
            "--db",
            db,
            "--out",
            tmp_path / "out",
        ),
        "--db",
        "notes.txt",
        "not an hptrack results database",
    )


def test_a_bare_option_suggests_only_planners_that_have_it(cli, tmp_path):
    args = ["benchmark", "--scenarios", 1, "--db", tmp_path / "b.db", "--out", tmp_path / "o"]
    line = cli(*args, "--planners", "mcts,greedy", "-o", "iterations=500").error_lines[0]
    assert line.endswith("say which planner, mcts.iterations=500") and "greedy." not in line
    one_line_refusal(
        cli(*args, "--planners", "stationary,greedy", "-o", "iterations=500"),
        "none of the running planners (stationary, greedy) has an option iterations",
    )


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--targets", "2,x"], ["--targets", "2,x"]),
        (["--planners", "mcts,nope"], ["unknown planner 'nope'"]),
        (["-o", "exploration=2"], ["say which planner", "mcts.exploration"]),
        (["-o", "mcts.iterations=abc"], ["planner 'mcts'", "option iterations", "'abc'"]),
        (["--iterations", "10", "--time-limit", "1"], ["--iterations or --time-limit"]),
        (["--first-seed", "-3"], ["--first-seed", "-3"]),
    ],
)
def test_bad_benchmark_options_are_one_line_refusals(cli, tmp_path, args, needles):
    one_line_refusal(
        cli(
            "benchmark",
            "--scenarios",
            1,
            "--planners",
            "mcts,greedy",
            "--db",
            tmp_path / "b.db",
            "--out",
            tmp_path / "out",
            *args,
        ),
        *needles,
    )


def test_a_bug_shows_its_traceback_and_exit_code_1(cli, monkeypatch):
    """An internal ValueError is a bug, not bad input: it must not be shown as if the user's
    input were wrong."""
    from hptrack.baselines import greedy

    def broken(self, observation):
        raise ValueError("an internal inconsistency")

    monkeypatch.setattr(greedy.GreedyPlanner, "act", broken)
    result = cli("simulate", "--random", "--targets", 2, "--seed", 1, "--planner", "greedy")
    assert result.code == 1
    assert "Traceback" in result.err and "an internal inconsistency" in result.err
    assert "This is a bug in hptrack" in result.err


def test_planners_lists_every_planner_with_each_options_default(cli):
    from hptrack.cli.app import option_defaults, preset_changes

    mcts = option_defaults("mcts")
    assert (mcts["exploration"], mcts["preset"], mcts["backup"]) == ("0.5", "revisit", "max")
    assert mcts["iterations"] == "20000" and mcts["time_limit"] == "none"
    assert mcts["rollout"] == "tour_plan"
    assert preset_changes("mcts") == {
        "paper": {"iterations": "100000", "backup": "sampled", "rollout": "uniform"},
        "improved": {"iterations": "100000", "rollout": "uniform"},
    }
    assert option_defaults("team-mcts")["preset"] == "improved"  # the teams keep their own
    assert preset_changes("team-mcts") == {
        "paper": {"backup": "sampled"},
        "revisit": {"iterations": "20000", "rollout": "tour_plan"},
    }
    assert option_defaults("coverage") == {"target": "required"}
    assert option_defaults("greedy") == {} and preset_changes("greedy") == {}
    result = cli("planners")
    assert result.code == 0
    for shown in ("mcts", "exploration=0.5", "coverage", "target=required", "horizon=6"):
        assert shown in result.out
    assert "-o preset=paper sets" in result.out


def test_simulate_json_names_the_subtasks_targets_by_id(cli, tmp_path):
    path = scenario_file(tmp_path)
    out = tmp_path / "c.json"
    result = cli("simulate", path, "--planner", "coverage", "-o", "target=b", "--json", out)
    assert result.code == 0, result.err
    subtasks = json.loads(out.read_text())["info"]["subtasks"]
    assert subtasks and all(s["target"] == "b" and "target_index" not in s for s in subtasks)
