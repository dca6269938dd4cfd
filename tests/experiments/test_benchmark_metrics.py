"""The tracking metrics in the benchmark: stored per episode, reported by ``--metric``."""

import csv
import json

import pytest

from hptrack.experiments.benchmark import run_one, scenario_for, summarise
from hptrack.experiments.report import markdown_tables
from hptrack.experiments.store import EpisodeKey
from hptrack.registry import planner_entry, planner_settings
from hptrack.sim.episode import run_episode
from hptrack.sim.record import EpisodeRow


def test_an_episode_row_holds_the_records_metrics():
    key = EpisodeKey("greedy", 3, 2, "homogeneous", planner_settings("greedy", None).canonical())
    row = run_one(key)
    scenario = scenario_for(key)
    record = run_episode(
        scenario, planner_entry("greedy").factory(planner_settings("greedy", None))
    )
    metrics = record.metrics()
    assert row.uncertainty == record.uncertainty
    assert (row.gospa_mean, row.gospa_end, row.track_loss) == (
        metrics["gospa_mean"],
        metrics["gospa_end"],
        metrics["track_loss"],
    )
    assert row.metric("never_detected") == metrics["targets_never_detected"]
    assert 0.0 < row.gospa_end <= 50.0 * 3**0.5  # at most c sqrt(n) for n beliefs and truths


def _rows() -> list[EpisodeRow]:
    def row(planner, seed, u, metrics):
        key = EpisodeKey(planner, 2, seed, "homogeneous", "{}")
        return EpisodeRow(key, u, 51.3, 0, 1.0, {"targets_never_detected": seed}, *metrics)

    return [
        row("greedy", 0, 30.0, (40.0, 60.0, 1)),
        row("greedy", 1, 34.0, (50.0, 70.0, 0)),
        row("greedy", 2, 32.0, (None, None, None)),  # stored before the metrics
        row("stationary", 0, 40.0, (None, None, None)),
    ]


def test_the_reports_metric_is_chosen_and_rows_without_it_are_left_out():
    rows = _rows()
    assert summarise(rows, metric="U")["greedy"][2]["mean"] == 32.0
    cell = summarise(rows, metric="gospa_end")["greedy"][2]
    assert (cell["mean"], cell["std"], cell["episodes"]) == (65.0, 5.0, 2)
    assert summarise(rows, metric="track_loss")["greedy"][2]["mean"] == 0.5
    assert summarise(rows, metric="never_detected")["greedy"][2]["mean"] == 1.0
    text = markdown_tables(rows, planners=("greedy", "stationary"), metric="gospa_end")
    assert text.startswith("Mean ± std of GOSPA at the budget's end, m (lower is better)")
    assert "| greedy | 65.00 ± 5.00 (2) |" in text and "| stationary | - (0) |" in text
    assert "never observed" not in text and "Reduction" not in text
    u = markdown_tables(rows, planners=("greedy", "stationary"))
    assert u.startswith("Mean ± std of U") and "| greedy | 32.00 ± 1.63 (3) |" in u
    assert "never observed" in u and "| greedy vs stationary | 20.00 |" in u


def test_benchmark_metric_option(cli, tmp_path):
    common = ("benchmark", "--targets", 2, "--scenarios", 1, "--planners", "greedy")
    common += ("--db", tmp_path / "b.db", "--figure-planners", "greedy")
    out = tmp_path / "out"
    result = cli(*common, "--out", out, "--metric", "gospa_mean", "--json", tmp_path / "g.json")
    assert result.code == 0, result.err
    assert "GOSPA over the mission's steps, mean, m" in (out / "table.md").read_text()
    with (out / "episodes.csv").open(newline="") as fh:
        (episode,) = list(csv.DictReader(fh))
    with (out / "episodes_summary.csv").open(newline="") as fh:
        (cell,) = list(csv.DictReader(fh))
    assert float(cell["mean_gospa_mean"]) == float(episode["gospa_mean"])
    assert int(episode["track_loss"]) >= 0 and int(episode["never_detected"]) >= 0
    data = json.loads((tmp_path / "g.json").read_text())
    assert data["greedy"]["2"]["mean"] == float(episode["gospa_mean"])
    again = cli(*common, "--out", out, "--json", tmp_path / "u.json")  # U, as today
    assert again.code == 0 and "0 episodes run now" in again.out
    assert json.loads((tmp_path / "u.json").read_text())["greedy"]["2"]["mean"] == float(
        episode["U"]
    )
    assert "never observed" in (out / "table.md").read_text()


@pytest.mark.parametrize("value", ["ospa", "u", ""])
def test_an_unknown_metric_is_refused_in_one_line(cli, tmp_path, value):
    cli("benchmark", "--metric", value, "--db", tmp_path / "b.db").refused(
        "--metric must be one of U, gospa_mean, gospa_end, track_loss, never_detected", repr(value)
    )
    assert not (tmp_path / "b.db").exists()


def test_the_library_benchmark_summarises_the_metric_asked(tmp_path):
    from hptrack.experiments.benchmark import benchmark
    from hptrack.interface import InputError

    db = tmp_path / "b.db"
    gospa = benchmark(("greedy",), (2,), 1, db=db, metric="gospa_end")["greedy"][2]
    u = benchmark(("greedy",), (2,), 1, db=db)["greedy"][2]
    key = EpisodeKey("greedy", 2, 0, "homogeneous", planner_settings("greedy", None).canonical())
    row = run_one(key)
    assert (gospa["mean"], u["mean"]) == (row.gospa_end, row.uncertainty)
    with pytest.raises(InputError, match="--metric must be one of"):
        benchmark(("greedy",), (2,), 1, metric="ospa")
