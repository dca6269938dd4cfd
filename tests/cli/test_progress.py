"""Progress outside a terminal: plain lines (first update, every interval, completion)."""

import io

from rich.console import Console

from hptrack.cli import common
from hptrack.cli.common import PlainProgress, progress_display


def _lines(progress: PlainProgress) -> list[str]:
    return progress.console.file.getvalue().splitlines()


def _plain(label: str, unit: str) -> PlainProgress:
    return PlainProgress(label, unit, Console(file=io.StringIO(), width=200))


def test_plain_progress_prints_the_first_update_and_the_completion():
    progress = _plain("benchmark", "episodes")
    with progress:
        task = progress.add_task("", total=None)
        for done in range(1, 31):
            progress.update(task, completed=done, total=30, description=f"mcts seed={done}")
        progress.update(task, completed=30)  # completing twice prints once
    lines = _lines(progress)
    assert len(lines) == 2
    assert lines[0].startswith("benchmark: 1/30 episodes (3 %), 00:00:")
    assert lines[0].endswith("; mcts seed=1")
    assert lines[1].startswith("benchmark: 30/30 episodes (100 %), 00:00:")
    assert "━" not in "".join(lines)


def test_plain_progress_prints_every_interval_and_without_a_total(monkeypatch):
    monkeypatch.setattr(common, "PLAIN_PROGRESS_INTERVAL_S", 0.0)
    progress = _plain("cases", "cases")
    task = progress.add_task("")
    for done in (1, 2, 3):
        progress.update(task, completed=done)
    assert [line.split(",")[0] for line in _lines(progress)] == [
        "cases: 1 cases",
        "cases: 2 cases",
        "cases: 3 cases",
    ]


def test_the_commands_print_plain_lines_when_not_on_a_terminal(cli):
    assert isinstance(progress_display("x", "steps"), PlainProgress)  # pytest captures stdout
    result = cli("simulate", "--random", "--targets", 2, "--seed", 0, "--planner", "greedy")
    assert result.code == 0, result.err
    assert "greedy mission: 1,800/1,800 steps (100 %)" in result.out
    before_the_table = result.out.split("┏")[0]
    assert "━" not in before_the_table and "…" not in before_the_table
