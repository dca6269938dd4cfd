"""``hptrack simulate`` prints the tracking metrics beside U and writes them to its --json."""

import json

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode


def test_simulate_prints_and_writes_gospa_and_track_loss(cli, tmp_path):
    result = cli(
        "simulate", "--random", "--targets", 3, "--seed", 1, "--planner", "greedy",
        "--json", tmp_path / "s.json",
    )  # fmt: skip
    assert result.code == 0, result.err
    metrics = run_episode(random_scenario(3, seed=1), GreedyPlanner()).metrics()
    lines = result.out.splitlines()
    assert (
        f"GOSPA (p = 2, c = 50 m): mean {metrics['gospa_mean']:.3f} m, "
        f"end {metrics['gospa_end']:.3f} m" in lines
    )
    assert (
        f"track loss: {metrics['track_loss']} of 3 targets at the end (outside the 99 % "
        "ellipse, or swapped)" in lines
    )
    data = json.loads((tmp_path / "s.json").read_text())
    assert {k: data[k] for k in metrics} == metrics
