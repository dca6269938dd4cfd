"""``hptrack examples`` lists and copies the shipped examples; the small ones run as copied."""

import re
import subprocess
import sys

import pytest

from hptrack.cli.examples import shipped_examples

EXPECTED = {
    "plan_once.py",
    "run_episode.py",
    "benchmark.py",
    "env_ppo.py",
    "fly_simulated.py",
    "paper-flight.yaml",
    "fenced-flight.yaml",
    "unlabelled-flight.yaml",
    "team-flight.yaml",
    "stonesoup_tracking.py",
}


def test_every_example_is_shipped_and_listed_with_its_summary(cli):
    assert set(shipped_examples()) == EXPECTED
    result = cli("examples")
    assert result.code == 0
    for name in EXPECTED:
        assert name in result.out
    assert "Plan one decision" in result.out


def test_copy_all_then_refuse_to_overwrite(cli, tmp_path):
    result = cli("examples", "--to", str(tmp_path / "ex"))
    assert result.code == 0
    assert {p.name for p in (tmp_path / "ex").iterdir()} == EXPECTED
    again = cli("examples", "plan_once.py", "--to", str(tmp_path / "ex"))
    assert again.code == 2
    assert again.error_lines == [
        f"error: --to {tmp_path / 'ex'}: plan_once.py exists already (add --force to overwrite)"
    ]
    assert cli("examples", "plan_once.py", "--to", str(tmp_path / "ex"), "--force").code == 0


@pytest.mark.parametrize("force", [False, True])
def test_a_destination_that_is_no_file_is_refused_before_anything_is_copied(cli, tmp_path, force):
    folder = tmp_path / "ex"
    (folder / "plan_once.py").mkdir(parents=True)  # a folder where a script would go
    (folder / "benchmark.py").symlink_to(tmp_path / "nowhere" / "x")  # a link to elsewhere
    result = cli("examples", "--to", folder, *(["--force"] if force else []))
    assert result.code == 2 and len(result.error_lines) == 1, result.err
    assert "benchmark.py is a folder, a link or a device, not a file" in result.err
    assert sorted(p.name for p in folder.iterdir()) == ["benchmark.py", "plan_once.py"]
    assert not (tmp_path / "nowhere").exists()


def test_unknown_example_is_one_line(cli):
    result = cli("examples", "nope.py")
    assert result.code == 2
    assert len(result.error_lines) == 1 and "unknown example 'nope.py'" in result.err


def run_example(folder, *args) -> str:
    done = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=folder)
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_copied_examples_run(cli, tmp_path):
    cli("examples", "plan_once.py", "run_episode.py", "--to", str(tmp_path))
    plan = run_example(tmp_path, "plan_once.py", "--targets", "2", "--iterations", "2000")
    assert plan.startswith("pursue t")
    run = run_example(tmp_path, "run_episode.py", "--planner", "greedy", "--targets", "2")
    assert run.splitlines()[-1].startswith("U = ")


def test_benchmark_example_prints_a_row_per_planner(cli, tmp_path):
    cli("examples", "benchmark.py", "--to", str(tmp_path))
    out = run_example(
        tmp_path,
        "benchmark.py",
        "--planners",
        "greedy,stationary",
        "--targets",
        "2",
        "--scenarios",
        "2",
    )
    header, greedy, stationary = out.splitlines()
    assert header.split() == ["planner", "n=2"]
    assert greedy.split()[0] == "greedy" and stationary.split()[0] == "stationary"
    assert float(greedy.split()[1]) < float(stationary.split()[1])


@pytest.mark.slow
def test_simulated_flight_example_finishes_its_mission(cli, tmp_path):
    cli("examples", "fly_simulated.py", "paper-flight.yaml", "--to", str(tmp_path))
    out = run_example(tmp_path, "fly_simulated.py")
    assert out.startswith("U = ") and "inputs rejected" in out


def test_the_commands_in_the_examples_name_files_of_the_copied_folder(cli, tmp_path):
    # each command an example shows (a comment, a docstring) runs in the folder it was
    # copied to: every script or scenario it names is there
    cli("examples", "--to", str(tmp_path))
    commands = 0
    for path in tmp_path.iterdir():
        for command in re.findall(r"(?:hptrack|python3?) [^\n#]+", path.read_text()):
            for name in re.findall(r"[\w./-]+\.(?:yaml|py)\b", command):
                commands += 1
                assert (tmp_path / name).is_file(), f"{path.name}: {command!r} names {name}"
    assert commands >= 5  # the flight's two commands and the Stone Soup example's three
