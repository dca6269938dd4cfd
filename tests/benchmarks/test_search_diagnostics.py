"""The diagnostics quoted in the docs (``benchmarks/search_diagnostics.py``) on toy databases
whose answers are known exactly."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

from hptrack.experiments.store import EpisodeKey, EpisodeRow, ResultStore
from hptrack.planning.hierarchical import MctsSettings

SCRIPT = Path(__file__).parents[2] / "benchmarks" / "search_diagnostics.py"


@pytest.fixture(scope="module")
def diagnostics():
    spec = importlib.util.spec_from_file_location("search_diagnostics", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _settings(**options) -> str:
    return MctsSettings.from_options(
        "mcts", {"preset": "improved", "iterations": 10, **options}
    ).canonical()


def _pursuit(target, start, end, outcome, intercept=5.0, expected=2.0, cutoff=40.0, p=0.9):
    return {
        "target_index": target,
        "start_step": start,
        "end_step": end,
        "outcome": outcome,
        "intercept_time": intercept,
        "expected_time": expected,
        "t_cutoff": cutoff,
        "p_find": p,
    }


def _store(tmp_path: Path, rows: list[tuple[int, str, float, list[dict]]]) -> Path:
    path = tmp_path / "toy.db"
    store = ResultStore(path)
    for seed, settings, u, subtasks in rows:
        store.add(
            EpisodeRow(
                EpisodeKey("mcts", 3, seed, "homogeneous", settings),
                u,
                75.0,
                0,
                1.0,
                {"subtasks": subtasks},
            )
        )
    store.close()
    return path


def _today(entries: list[dict]) -> list[dict]:
    """The same sub-task log in the shape planners write today (`Subtask.to_json`)."""
    from hptrack.subtasks import read_subtasks

    return [e.to_json() for e in read_subtasks(entries, ["0", "1", "2"])]


@pytest.mark.parametrize("shape", [list, _today], ids=["older", "today"])
def test_lost_counts_targets_never_found_and_their_share(tmp_path, diagnostics, capsys, shape):
    # seed 0: target 0 found, 1 only missed, 2 never pursued; seed 1: all three found
    # (target 1 after a miss). Each target left alone is worth 75 / 3 = 25 of U. The logs
    # read the same in the shape written before `Subtask.to_json` and in today's.
    plain = _settings()
    db = _store(
        tmp_path,
        [
            (
                0,
                plain,
                60.0,
                shape(
                    [
                        _pursuit(0, 0, 20, "found"),
                        _pursuit(1, 20, 120, "missed"),
                        {"follow": 0, "start_step": 120},
                    ]
                ),
            ),
            (
                1,
                plain,
                36.0,
                shape(
                    [
                        _pursuit(0, 0, 20, "found"),
                        _pursuit(1, 20, 120, "missed"),
                        _pursuit(2, 120, 140, "found"),
                        _pursuit(1, 140, 160, "found"),
                    ]
                ),
            ),
            (0, _settings(dwell=20.0), 99.0, []),  # another search, filtered out below
        ],
    )
    diagnostics.lost(db, ["dwell=0"])
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1
    # never found: 2 and 0, so 1 per episode (0.5 never pursued, 0.5 only missed); their U at
    # most 2 x 25 = 50 of 96; the other four targets at least (96 - 50) / 4 = 11.5 each
    assert (
        "2 episodes, mean U 48.00; never found 1.00 per episode (never pursued 0.50, only "
        "missed 0.50), each worth up to 25.00 of U, together at most 52 % of U; the others "
        "at least 11.5 per target; mean U by the number never found: 0: 36.0 (1), "
        "2: 60.0 (1)" in out[0]
    )


def test_model_accuracy_compares_flown_and_predicted_durations(tmp_path, diagnostics, capsys):
    # tau = 0.5 s: a find of 20 steps lasts 10 s against 5 + 2 = 7 s predicted; a miss of 100
    # steps 50 s against 5 + 40 = 45 s
    db = _store(
        tmp_path,
        [
            (
                0,
                _settings(),
                50.0,
                [_pursuit(0, 0, 20, "found", p=0.8), _pursuit(1, 20, 120, "missed", p=0.6)],
            )
        ],
    )
    diagnostics.model_accuracy(db)
    out = capsys.readouterr().out
    assert "n=3 found: 1 sub-tasks, mean duration 10.0 s flown against 7.0 s predicted" in out
    assert "n=3 missed: 1 sub-tasks, mean duration 50.0 s flown against 45.0 s predicted" in out
    assert "n=3: find rate 0.500 against mean p_find 0.700" in out


def test_paired_pairs_episodes_by_resolved_options(tmp_path, diagnostics, capsys):
    db = _store(
        tmp_path,
        [
            (0, _settings(), 50.0, []),
            (1, _settings(), 40.0, []),
            (0, _settings(dwell=20.0), 47.0, []),
            (1, _settings(dwell=20.0), 41.0, []),
        ],
    )
    diagnostics.paired(db, [db], ["dwell=20"], ["dwell=0"])
    row = capsys.readouterr().out.strip().splitlines()[-1]
    # differences -3 and +1: mean -1, standard error 2
    assert re.fullmatch(r"\| homogeneous \| 3 \| -1\.00 \+- 2\.00 \(2\) \|", row)


def test_subtasks_lists_each_pursuit_with_its_estimate(diagnostics, capsys):
    """Each preset's line: U, then every sub-task flown, a pursuit with the ``p_find`` and
    predicted duration the MDP gave it when it started (the paper's flight example)."""
    scenario = Path(__file__).parents[2] / "examples" / "paper-flight.yaml"
    diagnostics.subtasks(scenario, 200, seed=0)
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["paper", "improved"]
    for line in lines:
        assert re.search(
            r"U = \d+\.\d\d; p[12] (found|missed) \(p_find [01]\.\d\d, \d+\.\d s\)", line
        )


def test_optimum_prints_the_exact_best_plan_per_estimator(diagnostics, capsys):
    """The paper's flight: each estimator's exact optimum (the values the MDP tests check),
    the search's value, the switches of the best plan and the value of following instead."""
    scenario = Path(__file__).parents[2] / "examples" / "paper-flight.yaml"
    diagnostics.optimum(scenario, 2000, "drop")
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines] == ["paper", "sharp"]
    assert lines[0].startswith("paper: best expected U 15.61 (211 states; the search, 2000 ")
    assert "switches 17;" in lines[0] and "following it 16.05, best 14.72" in lines[0]
    assert lines[1].startswith("sharp: best expected U 7.12 (319 states;")
    assert "switches 26;" in lines[1] and "following it 16.05, best 6.60" in lines[1]


def test_subtasks_takes_more_options(diagnostics, capsys):
    """``--options`` reaches both presets' planners: an unknown value is refused by them."""
    scenario = Path(__file__).parents[2] / "examples" / "paper-flight.yaml"
    diagnostics.subtasks(scenario, 200, seed=0, options='{"estimator": "sharp"}')
    assert [line.split(":")[0] for line in capsys.readouterr().out.splitlines()] == [
        "paper",
        "improved",
    ]
    with pytest.raises(Exception, match="estimator"):
        diagnostics.subtasks(scenario, 200, seed=0, options='{"estimator": "blunt"}')
