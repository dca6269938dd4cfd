"""The ``clairvoyant`` reference (reads the true target states) on toy missions with exact
answers, and the guarantee that no other planner is handed the truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.baselines.clairvoyant import ClairvoyantPlanner
from hptrack.experiments.benchmark import gap_closed
from hptrack.interface import InputError, TruthReader
from hptrack.registry import PLANNERS, make_planner
from hptrack.scenario.model import AgentSpec, Scenario, TargetSpec
from hptrack.sim.episode import run_episode


def _one_target(x: float, budget: float = 60.0, q: float = 0.0) -> Scenario:
    return Scenario(
        budget=budget,
        agent=AgentSpec(position=(0.0, 0.0)),
        targets=[
            TargetSpec(
                id="t",
                mean=(x, 0.0, 0.0, 0.0),
                covariance=np.diag([100.0, 100.0, 0.01, 0.01]).tolist(),
                process_noise=q,
                truth=(x, 0.0, 0.0, 0.0),
            )
        ],
    )


def test_one_static_target_is_met_at_the_intercept_time_and_kept_to_the_end():
    """300 m away at 30 m/s with a 50 m footprint: met after 250 / 30 = 8.33 s, the end of
    step 17 (8.5 s); then measured at every step to the end of the budget."""
    record = run_episode(_one_target(300.0), ClairvoyantPlanner())
    seen = np.flatnonzero(record.detections[:, 0])
    assert seen[0] == math.ceil(250.0 / 30.0 / 0.5) == 17
    assert np.array_equal(seen, np.arange(17, 121))
    assert record.info["reads_truth"] and record.info["visits"][0]["target_index"] == 0


def test_the_simulator_hands_the_truth_to_a_truth_reader_only():
    seen = []

    class Spy(ClairvoyantPlanner):
        def see_truth(self, states):
            seen.append(states)
            super().see_truth(states)

    record = run_episode(_one_target(300.0, budget=5.0, q=1e-3), Spy())
    assert len(seen) == 10
    assert all(np.array_equal(s, t) for s, t in zip(seen, record.true_states[:-1], strict=True))
    readers = [name for name, entry in PLANNERS.items() if entry.reads_truth]
    assert readers == ["clairvoyant", "team-clairvoyant"]  # the references, one UAV and a team
    assert not any(isinstance(make_planner(name), TruthReader) for name in ("greedy", "mcts"))


def test_without_the_truth_it_refuses_to_act():
    planner = ClairvoyantPlanner()
    scenario = _one_target(300.0)
    planner.reset(scenario.mission_spec(), scenario.initial_observation(), None)
    with pytest.raises(InputError, match="reads the true target states"):
        planner.act(scenario.initial_observation())


def test_the_share_of_the_gap_closed():
    summary = {
        "greedy": {6: {"mean": 140.0}, 12: {"mean": 300.0}},
        "clairvoyant": {6: {"mean": 60.0}, 12: {"mean": 160.0}},
        "mcts": {6: {"mean": 80.0}, 12: {"mean": 230.0}},
    }
    gaps = gap_closed(summary)
    assert gaps["mcts"] == {6: 75.0, 12: 50.0}
    assert gaps["greedy"] == {6: 0.0, 12: 0.0} and gaps["clairvoyant"] == {6: 100.0, 12: 100.0}
    assert gap_closed({"greedy": summary["greedy"]}) == {}


def test_a_target_out_of_reach_is_flown_at_with_a_finite_stay():
    """3000 m away at 30 m/s, 60 s of budget: no target can be met in time, so the agent flies
    straight at the nearest and plans to stay there for the budget left (60 s, not inf)."""
    record = run_episode(_one_target(3000.0), ClairvoyantPlanner())
    assert record.info["visits"] == [{"step": 0, "target_index": 0, "stay_s": 60.0}]
    np.testing.assert_allclose(record.agent_path[-1], [60.0 * 30.0, 0.0], atol=1e-9)
    assert not record.detections.any()


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_plan_of_no_time_ranks_first_without_a_warning():
    """Two static targets already in the footprint: the two visits without a stay take no time,
    an infinite rate; the first of them (target 0, no stay) is flown, with no division
    warning."""
    scenario = _one_target(0.0, budget=5.0)
    targets = [
        scenario.targets[0].model_copy(update={"id": tid, "mean": m, "truth": m})
        for tid, m in (("a", (0.0, 10.0, 0.0, 0.0)), ("b", (0.0, -10.0, 0.0, 0.0)))
    ]
    record = run_episode(scenario.model_copy(update={"targets": targets}), ClairvoyantPlanner())
    assert record.info["visits"][0] == {"step": 0, "target_index": 0, "stay_s": 0.0}


def test_a_teams_gap_is_closed_between_its_greedy_and_clairvoyant_teams():
    summary = {
        "team-greedy": {12: {"mean": 300.0}},
        "team-clairvoyant": {12: {"mean": 100.0}},
        "team-mcts": {12: {"mean": 150.0}},
    }
    assert gap_closed(summary)["team-mcts"] == {12: 75.0}
