"""The simulated world drives the controller: without faults it flies the simulator's mission;
with faults it keeps flying, logs every input and finishes the budget."""

import numpy as np
import pytest

from hptrack.interface import InputError
from hptrack.registry import make_planner
from hptrack.runtime.log import MissionLog, read_log
from hptrack.runtime.simulated import SimulatedFaults, run_simulated
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode

PLANNERS = [("greedy", None), ("mcts", {"iterations": 300})]

FAULTS = SimulatedFaults(
    odometry_rate_hz=5.0,
    odometry_drop_probability=0.2,
    odometry_outages=((12.0, 2.5),),
    detection_rate_hz=10.0,
    detection_latency_s=0.3,
    detection_jitter_s=0.6,
    detection_drop_probability=0.3,
    planner_delay_s=0.05,
    planner_slow_probability=0.2,
    planner_slow_delay_s=1.5,
    bad_input_rate_hz=3.0,
)


def _scenarios(flight_scenario):
    return [flight_scenario, random_scenario(3, seed=4).model_copy(update={"budget": 120.0})]


@pytest.mark.parametrize(("name", "options"), PLANNERS)
def test_without_faults_the_controller_flies_the_simulators_mission(flight_scenario, name, options):
    # Same streams, detections every tau, no planner delay: the controller's observations are
    # the simulator's up to rounding (closed-form prediction over a gap vs. step by step, and
    # the agent's move split into setpoint periods), so the decisions and U agree to 1e-9.
    for scenario in _scenarios(flight_scenario):
        for seed in (0, 1):
            want = run_episode(scenario, make_planner(name, options), seed=seed)
            got = run_simulated(scenario, make_planner(name, options), seed=seed)
            assert got.controller.end["reason"] == "budget"
            assert got.uncertainty == pytest.approx(want.uncertainty, abs=1e-9)
            np.testing.assert_allclose(got.record.agent_path, want.agent_path, atol=1e-9)
            np.testing.assert_array_equal(got.record.detections, want.detections)
            np.testing.assert_array_equal(got.record.true_states, want.true_states)
            assert not got.controller.rejected


@pytest.mark.parametrize(("name", "options"), PLANNERS)
def test_with_faults_it_keeps_flying_logs_everything_and_finishes(
    flight_scenario, tmp_path, name, options
):
    path = tmp_path / "m.jsonl"
    log = MissionLog(path)
    run = run_simulated(
        flight_scenario, make_planner(name, options), seed=3, faults=FAULTS, log=log
    )
    log.close()
    ctrl = run.controller
    assert ctrl.end["reason"] == "budget" and ctrl.end["time"] == flight_scenario.budget
    assert np.isfinite(run.uncertainty)
    travelled = np.sum(np.hypot(*np.diff(run.record.agent_path, axis=0).T))
    assert travelled > 100.0
    assert run.record.detections.any()
    records = read_log(path).records
    assert records == log.records[1:]
    inputs = [r for r in records if r["kind"] in ("odometry", "detection")]
    assert len(inputs) == run.fed["odometry"] + run.fed["detection"] + run.fed["bad"]
    refused = [r for r in inputs if not r["accepted"]]
    assert len(refused) == sum(
        v for k, v in ctrl.rejected.items() if k.split(":")[0] in ("odometry", "detection")
    )
    assert run.fed["bad"] > 100 and len(refused) >= run.fed["bad"]
    reasons = {k.split(": ")[1] for k in ctrl.rejected}
    assert {
        "non-finite",
        "jump",
        "unknown target",
        "out of order",
        "bad covariance",
        "in the future",
        "duplicate",
    } <= reasons
    modes = [r["mode"] for r in records if r["kind"] == "mode"]
    assert "odometry stale" in modes and modes[-1] == "mission over"
    assert any(r["kind"] == "late" for r in records)
    assert ctrl.accepted["detection"] > 0


def test_the_setpoint_rate_must_divide_the_time_step(flight_scenario):
    with pytest.raises(InputError, match="setpoint_rate_hz 3"):
        run_simulated(
            flight_scenario, make_planner("greedy"), faults=SimulatedFaults(setpoint_rate_hz=3.0)
        )
