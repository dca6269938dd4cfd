"""The controller's parts, each alone: clock, input checks, journal, planner worker and
fallback, mission history."""

import math
import time

import numpy as np
import pytest

from hptrack.interface import CurrentPlan
from hptrack.runtime.beliefs import BeliefTimeline
from hptrack.runtime.clock import MissionClock, step_of
from hptrack.runtime.inputs import ControllerSettings, InputChecks, mission_area, raw, vector
from hptrack.runtime.journal import Journal
from hptrack.runtime.record import MissionHistory
from hptrack.runtime.worker import (
    Fallback,
    InlineRunner,
    PlannerWorker,
    ThreadedRunner,
    observation,
)
from hptrack.settings import NoSettings


def test_the_clock_ticks_once_per_step_skips_and_stops_at_the_budget():
    clock = MissionClock(0.5, 4)
    assert clock.due(0.0) == (0, 0) and clock.due(0.49) is None
    assert clock.due(0.5 - 1e-12) == (1, 0)  # within the step rule's slack
    assert clock.due(1.75) == (3, 1)  # tick 2 skipped
    assert clock.due(9.0) == (4, 0) and clock.due(10.0) is None  # the budget's end, once
    assert step_of(1.5, 0.5) == 3 and step_of(1.4999999999999, 0.5) == 3


def test_the_clock_refuses_calls_that_go_back_and_moves_only_forward():
    clock = MissionClock(0.5, 10)
    assert clock.call(1.0) == (1.0, None)
    t, problem = clock.call(0.5)
    assert t == 1.0 and "before the last call" in problem
    t, problem = clock.call(math.nan)
    assert t == 1.0 and "not finite" in problem
    clock.observe(3.0)
    clock.observe(2.0)
    assert clock.now == 3.0 and clock.ahead(3.25) == 0.25


@pytest.fixture
def checks(flight_scenario):
    return InputChecks(flight_scenario, ControllerSettings())


def _beliefs(scenario):
    mission = scenario.mission_spec()
    return BeliefTimeline(
        scenario.means(), scenario.covariances(), mission.process_noise, mission.motion, 2.0
    )


def test_odometry_checks_name_each_reason(checks):
    p = np.array([0.0, 0.0])
    assert checks.odometry(1.0, None, None, None)[0] == "malformed"
    assert checks.odometry(1.0, np.array([math.inf, 0.0]), None, None)[0] == "non-finite"
    assert checks.odometry(-1.0, p, None, None)[0] == "before the start"
    assert checks.odometry(1.0, p, None, "budget") == (
        "after the end",
        "the mission ended (budget)",
    )
    last = (1.0, p)
    assert checks.odometry(0.5, p, last, None)[0] == "out of order"
    assert checks.odometry(1.0, p, last, None)[0] == "duplicate"
    # 2 x 8 m/s x 0.5 s + 3 m = 11 m allowed
    assert checks.odometry(1.5, np.array([11.0, 0.0]), last, None) is None
    assert checks.odometry(1.5, np.array([11.01, 0.0]), last, None)[0] == "jump"


def test_detection_checks_name_each_reason(checks, flight_scenario):
    beliefs = _beliefs(flight_scenario)
    z = np.array([30.0, 10.0])

    def reason(t=1.0, tid="p1", pos=z, cov=None, ahead=0.0):
        check = checks.detection(t, tid, pos, cov, ahead, None, beliefs)
        return None if check.problem is None else check.problem[0]

    assert reason() is None
    assert reason(tid="nope") == reason(tid=3) == "unknown target"
    assert reason(pos=None) == "malformed"
    assert reason(pos=np.array([math.nan, 0.0])) == "non-finite"
    assert reason(pos=np.array([1e300, 0.0])) == "outside the area"
    assert reason(cov=[[1.0, 2.0], [2.0, 1.0]]) == "bad covariance"  # not positive definite
    assert reason(cov=2e8 * np.eye(2)) == reason(cov=1e-13 * np.eye(2)) == "bad covariance"
    assert reason(cov="x") == "malformed"
    assert reason(ahead=0.6) == "in the future"
    beliefs.add(0, 5.0, z, np.eye(2), 1)
    assert reason(t=2.9) == "out of order" and reason(t=3.1) is None
    assert reason(t=5.0) == "duplicate"
    accepted = checks.detection(3.1, "p2", z, 2.0 * np.eye(2), 0.0, None, beliefs)
    assert accepted.index == 1 and np.array_equal(accepted.noise, 2.0 * np.eye(2))


def test_the_mission_area_is_what_the_vehicle_can_reach_plus_its_footprint(flight_scenario):
    centre, radius = mission_area(flight_scenario)
    np.testing.assert_array_equal(centre, [0.0, 0.0])
    assert radius == 8.0 * 60.0 + 10.0 + 10.0 * 1.0


def test_numbers_only_and_none_that_overflow():
    assert vector([10**400, 1.0], (2,)) is None
    assert isinstance(raw([10**400]), str)
    assert vector([[1, 2], [3, 4]], (2,)) is None
    assert vector(["30", 10], (2,)) is None and vector([True, 10], (2,)) is None
    assert vector(np.array(["1", "2"]), (2,)) is None
    assert vector((1, np.float32(2.5)), (2,)).tolist() == [1.0, 2.5]
    assert vector([[1, 0], [0, 1]], (2, 2)).tolist() == [[1.0, 0.0], [0.0, 1.0]]


def test_the_journal_numbers_a_calls_records_and_counts_inputs():
    journal = Journal()
    journal.write({"kind": "header"})
    with journal.call() as number:
        journal.accept("odometry", {"kind": "odometry", "t": 0.0})
    journal.refuse("detection", {"kind": "detection", "t": 0.0}, "duplicate", "again")
    with journal.call():
        journal.write({"kind": "mode", "t": 0.1})
    records = journal.log.records
    assert [r.get("call") for r in records] == [None, number, None, number + 1]
    assert records[1]["accepted"] is True and records[2]["reason"] == "duplicate"
    assert journal.accepted == {"odometry": 1}
    assert journal.rejected == {"detection: duplicate": 1}


class _Steps:
    """Steps 1 m east; sleeps, fails or answers garbage at chosen steps."""

    name = "steps"
    settings = NoSettings()

    def __init__(self, sleep_s=0.0, fail_at=(), garbage_at=()):
        self.sleep_s, self.fail_at, self.garbage_at = sleep_s, set(fail_at), set(garbage_at)
        self.resets = 0

    def reset(self, mission, obs, rng):
        self.resets += 1

    def act(self, obs):
        time.sleep(self.sleep_s)
        if obs.step in self.fail_at:
            raise RuntimeError("boom")
        if obs.step in self.garbage_at:
            return np.array([math.nan, 0.0])
        return obs.agent_position + [1.0, 0.0]

    def current_plan(self):
        return CurrentPlan()

    def episode_info(self):
        return {"resets": self.resets}


def _obs(k, mission):
    n = mission.n_targets
    return observation(
        k,
        0.5 * k,
        mission.budget,
        np.zeros(2),
        np.zeros((n, 4)),
        np.tile(np.eye(4), (n, 1, 1)),
        np.zeros(n, bool),
    )


def test_the_worker_delivers_late_and_failed_calls_with_their_state(flight_scenario):
    mission = flight_scenario.mission_spec()
    planner = _Steps(fail_at={0}, garbage_at={2})
    delays = {0: 0.0, 1: 1.5, 2: 0.0}
    worker = PlannerWorker(
        planner, mission, np.random.default_rng(0), InlineRunner(delays.get), 1.0
    )
    assert worker.poll(0.0) is None and worker.info() == {}
    worker.submit(_obs(0, mission), 0.0)
    failed = worker.poll(0.0)
    assert failed.outcome.error == "RuntimeError: boom" and not worker.started  # reset again
    worker.submit(_obs(1, mission), 0.5)
    assert planner.resets == 2
    first = worker.poll(1.0)
    assert first.outcome is None and not first.late
    late = worker.poll(1.6)
    assert late.newly_late and late.late and late.tick == 1
    assert not worker.poll(1.8).newly_late  # said once
    arrived = worker.poll(2.0)
    assert arrived.late and arrived.outcome.waypoint.tolist() == [1.0, 0.0]
    worker.submit(_obs(2, mission), 2.0)
    assert "invalid waypoint" in worker.poll(2.0).outcome.error
    assert worker.info() == {"resets": 2}


def test_the_threaded_worker_waits_for_a_slow_first_plan_without_blocking_polls(
    flight_scenario,
):
    mission = flight_scenario.mission_spec()
    worker = PlannerWorker(
        _Steps(sleep_s=0.3), mission, np.random.default_rng(0), ThreadedRunner(), 1.0
    )
    worker.submit(_obs(0, mission), 0.0)
    start = time.perf_counter()
    assert worker.poll(0.0).outcome is None and time.perf_counter() - start < 0.05
    assert not worker.wait(0.01)
    assert worker.info()["unavailable"].endswith("tick 0")
    assert worker.wait(5.0)
    assert worker.poll(0.0).outcome.waypoint.tolist() == [1.0, 0.0]
    worker.close()


def test_the_fallback_is_greedy_on_the_beliefs_it_is_given(flight_scenario):
    mission = flight_scenario.mission_spec()
    fallback = Fallback(mission, seed=1)
    means = flight_scenario.means()
    obs = observation(
        0,
        0.0,
        mission.budget,
        np.zeros(2),
        means,
        flight_scenario.covariances(),
        np.zeros(2, bool),
    )
    assert not fallback.active
    np.testing.assert_array_equal(fallback.decide(obs), means[0, :2])  # p1 wins the tie
    assert fallback.active
    fallback.stop()
    assert not fallback.active


def test_the_history_holds_the_agent_between_ticks_and_ends_with_the_final_beliefs(
    flight_scenario,
):
    mission = flight_scenario.mission_spec()
    history = MissionHistory(mission, np.array([5.0, 5.0]))
    n = mission.n_targets
    means, covs = np.zeros((n, 4)), np.tile(np.eye(4), (n, 1, 1))
    history.tick(0, None, means, covs, np.array([True, False]))
    history.tick(2, np.array([1.0, 0.0]), means + 1, covs, np.zeros(n, bool))
    with pytest.raises(RuntimeError):
        history.episode_record("steps", 1, {})
    history.end(1.5, np.array([2.0, 0.0]), means + 2, 2 * covs, np.array([False, True]))
    record = history.episode_record("steps", 1, {"x": 1})
    np.testing.assert_array_equal(
        record.agent_path, [[5.0, 5.0], [5.0, 5.0], [1.0, 0.0], [2.0, 0.0]]
    )
    assert record.belief_steps.tolist() == [0, 2, 3]
    np.testing.assert_array_equal(record.belief_means[-1], means + 2)
    expected = [[True, False], [False, False], [False, False], [False, True]]
    assert record.detections.tolist() == expected
    assert np.isnan(record.true_states).all() and record.info == {"x": 1}


def test_a_leg_moves_its_reference_at_its_speed_and_stops_at_its_end():
    from hptrack.runtime.legs import Leg

    leg = Leg(np.array([0.0, 0.0]), 2.0, np.array([3.0, 4.0]), 2.0)
    reference, velocity = leg.at(1.0)  # before its start: at the start, already moving
    np.testing.assert_array_equal(reference, [0.0, 0.0])
    np.testing.assert_allclose(velocity, [1.2, 1.6])
    reference, velocity = leg.at(3.0)
    np.testing.assert_allclose(reference, [1.2, 1.6])
    reference, velocity = leg.at(4.5)  # 5 m at 2 m/s: there after 2.5 s
    np.testing.assert_array_equal(reference, [3.0, 4.0])
    np.testing.assert_array_equal(velocity, [0.0, 0.0])


def test_true_targets_draw_their_first_step_before_any_flight(flight_scenario):
    """The flight's simulated targets take their first step when made (so the true-motion
    kernel is loaded before a flight starts), and drawing it then changes no state: the
    steps are those of the simulator's true motion, one draw per step in order."""
    from hptrack.models.truth_motion import sample_truth
    from hptrack.runtime.world import TrueTargets
    from hptrack.sim.step import initial_true_states

    targets = TrueTargets(flight_scenario, np.random.default_rng(1), np.random.default_rng(2))
    assert len(targets.states) == 2
    spec = flight_scenario.mission_spec()
    motion = np.random.default_rng(2)
    states = [initial_true_states(flight_scenario, np.random.default_rng(1))]
    for _ in range(3):
        states.append(
            sample_truth(
                flight_scenario.truth_motion_model(np.random.default_rng(0)),
                spec.record,
                states[-1],
                spec.process_noise,
                motion,
            )
        )
    for k, expected in enumerate(states):
        np.testing.assert_array_equal(targets.state(k), expected)
