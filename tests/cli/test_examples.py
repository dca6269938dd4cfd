"""``hptrack examples`` lists and copies the shipped examples; the small ones run as copied."""

import subprocess
import sys

from hptrack.cli.examples import shipped_examples

EXPECTED = {
    "plan_once.py",
    "run_episode.py",
    "benchmark.py",
    "env_ppo.py",
    "fly_simulated.py",
    "paper-flight.yaml",
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
