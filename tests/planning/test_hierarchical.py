"""The hierarchical planner in the simulator (paper Fig. 2, Sec. IV-C-4)."""

import numpy as np
import pytest
from typer.testing import CliRunner

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.cli.app import app
from hptrack.planning.hierarchical import HierarchicalPlanner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode


def test_conditional_plan_is_followed_and_misses_leave_the_list():
    record = run_episode(random_scenario(3, seed=2, homogeneous=True),
                         HierarchicalPlanner(iterations=2000))
    log = record.info["subtasks"]
    assert len(log) >= 3
    assert len(record.info["searches"]) >= len(log)
    assert all(s["stopped_by"] == "iterations" and s["simulations"] == 2000
               for s in record.info["searches"])
    for done, nxt in zip(log, log[1:], strict=False):
        if "outcome" not in done:
            break
        planned = done["plan_after_find" if done["outcome"] == "found" else "plan_after_miss"]
        nxt_target = nxt.get("target_index", nxt.get("follow"))
        if planned is not None and nxt.get("start_step") == done["end_step"]:
            if done["outcome"] == "missed":
                assert nxt_target != done["target_index"]
            assert nxt_target == planned or "follow" in nxt
        if done["outcome"] == "found":
            k = done["end_step"]
            assert record.detections[k, done["target_index"]]


def test_same_seed_same_mission():
    scenario = random_scenario(3, seed=5, homogeneous=True)
    a = run_episode(scenario, HierarchicalPlanner(iterations=1000))
    b = run_episode(scenario, HierarchicalPlanner(iterations=1000))
    np.testing.assert_array_equal(a.agent_path, b.agent_path)
    assert a.uncertainty == b.uncertainty


@pytest.mark.slow
def test_mcts_beats_greedy_on_twenty_three_target_scenarios():
    u_mcts, u_greedy = [], []
    for seed in range(20):
        scenario = random_scenario(3, seed=seed, homogeneous=True)
        u_mcts.append(run_episode(scenario, HierarchicalPlanner(iterations=2000)).uncertainty)
        u_greedy.append(run_episode(scenario, GreedyPlanner()).uncertainty)
    assert np.mean(u_mcts) < np.mean(u_greedy) - 10.0


def test_invalid_effort_is_refused():
    with pytest.raises(ValueError, match="iterations"):
        HierarchicalPlanner(iterations=0)
    with pytest.raises(ValueError, match="time_limit"):
        HierarchicalPlanner(time_limit=-1.0)


def test_simulate_command_with_mcts(tmp_path):
    result = CliRunner().invoke(app, ["simulate", "--random", "--targets", "2", "--planner",
                                      "mcts", "--iterations", "500", "--json",
                                      str(tmp_path / "m.json")])
    assert result.exit_code == 0, result.output
    assert "mcts mission" in result.output
