import json

import numpy as np
import pytest
from typer.testing import CliRunner

from hptrack.baselines.stationary import StationaryPlanner
from hptrack.cli.app import app
from hptrack.experiments.benchmark import (
    BenchmarkConfig,
    never_observed_uncertainty,
    reductions,
    run_benchmark,
    scenario_for,
    summarise,
)
from hptrack.experiments.store import ResultStore
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode

CONFIG = BenchmarkConfig(planners=("greedy", "stationary"), target_counts=(2, 3), scenarios=2)


def test_interrupted_run_keeps_finished_episodes_and_resumes_without_duplicates(tmp_path):
    store = ResultStore(tmp_path / "b.db")

    def stop_after_three(row, finished, total):
        if finished == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_benchmark(CONFIG, store, on_done=stop_after_three)
    assert len(store.rows()) == 3
    store.close()
    store = ResultStore(tmp_path / "b.db")
    assert run_benchmark(CONFIG, store) == len(CONFIG.keys()) - 3
    assert run_benchmark(CONFIG, store) == 0
    rows = store.rows()
    assert len(rows) == len({r.key for r in rows}) == 8


def test_parallel_run_equals_serial_run(tmp_path):
    serial, parallel = ResultStore(tmp_path / "s.db"), ResultStore(tmp_path / "p.db")
    run_benchmark(CONFIG, serial)
    run_benchmark(CONFIG, parallel, workers=2)
    u = {r.key: r.uncertainty for r in serial.rows()}
    assert u == {r.key: r.uncertainty for r in parallel.rows()}


def test_never_observed_equals_a_mission_that_sees_nothing():
    scenario = random_scenario(3, seed=1, agent={"position": (1e6, 1e6)})
    record = run_episode(scenario, StationaryPlanner())
    assert not record.detections.any()
    assert never_observed_uncertainty(scenario) == pytest.approx(record.uncertainty, rel=1e-12)
    # the notes' scale: about 25.65 per target with the paper's priors and the default Q
    values = [never_observed_uncertainty(random_scenario(1, seed=s)) for s in range(300)]
    assert np.mean(values) == pytest.approx(25.65, abs=0.1)


def test_summary_and_reductions_arithmetic(tmp_path):
    store = ResultStore(tmp_path / "b.db")
    run_benchmark(CONFIG, store)
    summary = summarise(store.rows())
    cell = summary["greedy"][2]
    u = [r.uncertainty for r in store.rows() if r.key.planner == "greedy" and r.key.n_targets == 2]
    assert cell["mean"] == pytest.approx(np.mean(u)) and cell["std"] == pytest.approx(np.std(u))
    red = reductions(summary)[("greedy", "stationary")][2]
    base = summary["stationary"][2]["mean"]
    assert red == pytest.approx(100 * (base - cell["mean"]) / base)


def test_scenarios_follow_seeds_and_setting():
    key = CONFIG.keys()[0]
    assert scenario_for(key) == random_scenario(key.n_targets, key.seed, homogeneous=True)


def test_benchmark_command_end_to_end(tmp_path):
    result = CliRunner().invoke(app, [
        "benchmark", "--targets", "2", "--scenarios", "2", "--planners", "greedy,stationary",
        "--db", str(tmp_path / "b.db"), "--out", str(tmp_path / "out"),
        "--json", str(tmp_path / "b.json")])
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "b.json").read_text())
    assert set(data) == {"greedy", "stationary"}
    assert data["greedy"]["2"]["episodes"] == 2
    for name in ("table.md", "episodes.csv", "episodes_summary.csv", "uncertainty_boxes.png",
                 "trajectories.png"):
        assert (tmp_path / "out" / name).exists(), name
    assert "never observed" in (tmp_path / "out" / "table.md").read_text()
