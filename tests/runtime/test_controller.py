import math
import time

import numpy as np
import pytest

from hptrack.interface import CurrentPlan, Subtask, SubtaskAction
from hptrack.models.measurement import kalman_update
from hptrack.models.miss_update import miss_update
from hptrack.runtime.controller import MissionController, plan_json
from hptrack.runtime.inputs import ControllerSettings
from hptrack.runtime.worker import InlineRunner, ThreadedRunner
from hptrack.scenario import parse_scenario
from hptrack.scenario.io import file_data
from hptrack.settings import NoSettings


class Recorder:
    """A planner that records its observations and steps 1 m east of the agent; it can fail
    or sleep at chosen steps."""

    name = "recorder"
    settings = NoSettings()

    def __init__(self, fail_at=(), sleep_s=0.0):
        self.fail_at, self.sleep_s = set(fail_at), sleep_s
        self.observations = []
        self.resets = 0

    def reset(self, mission, observation, rng):
        self.resets += 1

    def act(self, observation):
        self.observations.append(observation)
        if self.sleep_s:
            time.sleep(self.sleep_s)
        if observation.step in self.fail_at:
            raise RuntimeError(f"boom at {observation.step}")
        return observation.agent_position + np.array([1.0, 0.0])

    def current_plan(self):
        return CurrentPlan()

    def episode_info(self):
        return {}


def _controller(scenario, planner=None, delay=None, **settings):
    planner = planner or Recorder()
    return MissionController(
        scenario, planner, settings=ControllerSettings(**settings), runner=InlineRunner(delay)
    ), planner


def _textbook(mean, cov, q, duration, z=None, noise=None):
    """Prediction with explicit F and Q (continuous white-noise acceleration) and, with ``z``,
    the Kalman update written with matrices."""
    f = np.eye(4)
    f[0, 2] = f[1, 3] = duration
    a, b, c = duration**3 / 3, duration**2 / 2, duration
    big_q = q * np.block([[a * np.eye(2), b * np.eye(2)], [b * np.eye(2), c * np.eye(2)]])
    mean, cov = f @ mean, f @ cov @ f.T + big_q
    if z is not None:
        h = np.hstack([np.eye(2), np.zeros((2, 2))])
        gain = cov @ h.T @ np.linalg.inv(h @ cov @ h.T + noise)
        mean = mean + gain @ (z - h @ mean)
        cov = (np.eye(4) - gain @ h) @ cov
    return mean, cov


@pytest.mark.parametrize("custom_noise", [None, [[0.5, 0.2], [0.2, 3.0]]])
def test_beliefs_are_predicted_in_closed_form_over_any_gap(flight_scenario, custom_noise):
    ctrl, planner = _controller(flight_scenario)
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    ctrl.odometry(3.0, [1.0, 0.0])
    z = np.array([41.0, 9.0])
    assert ctrl.detection(3.3, "p1", z, custom_noise)
    ctrl.odometry(5.0, [2.0, 0.0])
    ctrl.setpoint(5.0)
    obs = planner.observations[-1]
    assert obs.step == 10 and obs.time == 5.0 and obs.detected.tolist() == [True, False]
    noise = (
        flight_scenario.agent.noise_covariance() if custom_noise is None else np.array(custom_noise)
    )
    q = flight_scenario.process_noise()
    mean, cov = _textbook(
        flight_scenario.means()[0], flight_scenario.covariances()[0], q[0], 3.3, z, noise
    )
    mean, cov = _textbook(mean, cov, q[0], 1.7)
    np.testing.assert_allclose(obs.means[0], mean, rtol=1e-10)
    np.testing.assert_allclose(obs.covariances[0], cov, rtol=1e-10, atol=1e-12)
    mean, cov = _textbook(flight_scenario.means()[1], flight_scenario.covariances()[1], q[1], 5.0)
    np.testing.assert_allclose(obs.covariances[1], cov, rtol=1e-10, atol=1e-12)


def _feed_good(ctrl):
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    ctrl.odometry(0.4, [2.0, 0.0])
    ctrl.detection(0.4, "p1", [31.0, 10.0])
    ctrl.setpoint(0.4)


BAD = {
    "odometry non-finite": (lambda c: c.odometry(0.45, [math.nan, 0.0]), "odometry: non-finite"),
    "odometry malformed": (lambda c: c.odometry(0.45, [1.0, 2.0, 3.0]), "odometry: malformed"),
    "odometry jump": (lambda c: c.odometry(0.45, [500.0, 0.0]), "odometry: jump"),
    "odometry out of order": (lambda c: c.odometry(0.3, [1.0, 0.0]), "odometry: out of order"),
    "odometry duplicate": (lambda c: c.odometry(0.4, [2.0, 0.0]), "odometry: duplicate"),
    "unknown target": (lambda c: c.detection(0.45, "p9", [1.0, 1.0]), "detection: unknown target"),
    "target id not text": (lambda c: c.detection(0.45, 7, [1.0, 1.0]), "detection: unknown target"),
    "detection non-finite": (
        lambda c: c.detection(0.45, "p2", [math.inf, 1.0]),
        "detection: non-finite",
    ),
    "detection time NaN": (
        lambda c: c.detection(math.nan, "p2", [1.0, 1.0]),
        "detection: non-finite",
    ),
    "detection before start": (
        lambda c: c.detection(-1.0, "p2", [1.0, 1.0]),
        "detection: before the start",
    ),
    "detection future": (
        lambda c: c.detection(2.0, "p2", [30.0, -10.0]),
        "detection: in the future",
    ),
    "detection duplicate": (lambda c: c.detection(0.4, "p1", [31.0, 10.0]), "detection: duplicate"),
    "bad covariance": (
        lambda c: c.detection(0.45, "p2", [30.0, -10.0], [[1, 2], [2, 1]]),
        "detection: bad covariance",
    ),
    "malformed covariance": (
        lambda c: c.detection(0.45, "p2", [30.0, -10.0], [1.0, 2.0]),
        "detection: malformed",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_changes_nothing_and_is_counted_and_logged(flight_scenario, case):
    feed, reason = BAD[case]
    good, good_planner = _controller(flight_scenario)
    bad, bad_planner = _controller(flight_scenario)
    for ctrl in (good, bad):
        _feed_good(ctrl)
    assert feed(bad) is False
    for ctrl in (good, bad):
        ctrl.odometry(0.5, [3.0, 0.0])
        ctrl.setpoint(0.5)
    a, b = good_planner.observations[-1], bad_planner.observations[-1]
    assert a.step == b.step == 1
    np.testing.assert_array_equal(a.means, b.means)
    np.testing.assert_array_equal(a.covariances, b.covariances)
    np.testing.assert_array_equal(a.agent_position, b.agent_position)
    np.testing.assert_array_equal(a.detected, b.detected)
    assert dict(bad.rejected) == {reason: 1} and not good.rejected
    refused = [r for r in bad.log.records if r.get("accepted") is False]
    assert len(refused) == 1 and f"{refused[0]['kind']}: {refused[0]['reason']}" == reason


def test_an_old_detection_beyond_the_tolerance_is_refused(flight_scenario):
    ctrl, _ = _controller(flight_scenario, reorder_tolerance_s=1.0, future_tolerance_s=5.0)
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(3.0)
    assert ctrl.detection(3.0, "p1", [40.0, 10.0])
    assert ctrl.detection(2.5, "p2", [37.0, -10.0])  # within 1 s: filtered in time order
    assert not ctrl.detection(1.5, "p2", [34.0, -10.0])
    assert dict(ctrl.rejected) == {"detection: out of order": 1}


def test_a_late_detection_counts_at_the_next_tick(flight_scenario):
    ctrl, planner = _controller(flight_scenario)
    for k in range(3):
        ctrl.odometry(0.5 * k, [0.0, 0.0])
        ctrl.setpoint(0.5 * k)
    ctrl.detection(1.0, "p2", [33.0, -10.0])  # taken at tick 2's time, arrives after it
    assert not planner.observations[2].detected.any()
    ctrl.odometry(1.5, [0.0, 0.0])
    ctrl.setpoint(1.5)
    obs = planner.observations[3]
    assert obs.detected.tolist() == [False, True]
    assert obs.covariances[1, 0, 0] < planner.observations[2].covariances[1, 0, 0]


def test_a_find_while_the_planner_is_busy_is_not_lost(flight_scenario):
    ctrl, planner = _controller(
        flight_scenario, delay=lambda tick: 1.2 if tick == 0 else 0.0, planner_deadline_s=5.0
    )
    t = 0.0
    while t <= 2.0:
        ctrl.odometry(t, [0.0, 0.0])
        if abs(t - 0.6) < 1e-9:
            ctrl.detection(t, "p1", [32.0, 10.0])
        ctrl.setpoint(t)
        t = round(t + 0.1, 10)
    steps = [obs.step for obs in planner.observations]
    assert steps == [0, 3, 4]  # ticks 1 and 2 were skipped while busy
    assert planner.observations[1].detected.tolist() == [True, False]
    skipped = [r for r in ctrl.log.records if r["kind"] == "tick" and not r["submitted"]]
    assert [r["k"] for r in skipped] == [1, 2]
    assert all("busy" in r["reason"] for r in skipped)


def test_stale_odometry_holds_and_says_so_then_resumes(flight_scenario):
    ctrl, _ = _controller(flight_scenario, stale_odometry_s=1.0)
    ctrl.odometry(0.0, [0.0, 0.0])
    assert not ctrl.setpoint(0.0).hold
    ctrl.odometry(1.0, [5.0, 0.0])
    assert not ctrl.setpoint(1.9).hold
    held = ctrl.setpoint(2.1)
    assert held.hold and held.reason == "odometry stale" and "1.10 s" in held.detail
    np.testing.assert_array_equal(held.position, [5.0, 0.0])
    ctrl.odometry(2.2, [6.0, 0.0])
    back = ctrl.setpoint(2.2)
    assert not back.hold
    modes = [r["mode"] for r in ctrl.log.records if r["kind"] == "mode"]
    assert modes == ["tracking", "odometry stale", "tracking"]


def test_a_late_plan_is_replaced_by_the_greedy_fallback_at_once(flight_scenario):
    ctrl, _ = _controller(
        flight_scenario, delay=lambda tick: 2.0 if tick == 2 else 0.0, planner_deadline_s=1.0
    )
    out = {}
    t = 0.0
    while t <= 3.5:
        ctrl.odometry(t, [t, 0.0])
        out[t] = ctrl.setpoint(t)
        t = round(t + 0.25, 10)
    np.testing.assert_array_equal(out[0.5].position, [1.5, 0.0])
    for when in (1.0, 1.5, 2.0):  # tick 2's plan is out until 3.0 s: tick 1's until the deadline
        np.testing.assert_array_equal(out[when].position, [1.5, 0.0])
    # deadline missed at 2.25 s: greedy on the beliefs then (p1, whose mean walks east at
    # 3 m/s from x = 30; p2 ties and comes second), re-decided at each tick while late
    for when, x in ((2.25, 36.75), (2.75, 37.5), (3.0, 39.0)):
        assert out[when].reason == "fallback" and not out[when].hold
        np.testing.assert_allclose(out[when].position, [x, 10.0], atol=1e-12)
    np.testing.assert_array_equal(out[3.5].position, [4.5, 0.0])  # the planner again
    assert out[3.5].reason == "tracking"
    late = [r for r in ctrl.log.records if r["kind"] == "late"]
    assert [(r["k"], r["t"]) for r in late] == [(2, 2.25)]
    fallbacks = [(r["k"], r["t"]) for r in ctrl.log.records if r["kind"] == "fallback"]
    assert fallbacks == [(4, 2.25), (5, 2.5), (6, 3.0)]
    plans = {r["k"]: r for r in ctrl.log.records if r["kind"] == "plan"}
    assert plans[2]["status"] == "late" and "not flown" in plans[2]["detail"]
    assert plans[1]["status"] == "ok"


def test_the_reference_leaves_the_odometry_at_the_planned_speed(flight_scenario):
    class Far(Recorder):
        def act(self, observation):
            return observation.agent_position + np.array([30.0, 40.0])

    ctrl, _ = _controller(flight_scenario, planner=Far())
    ctrl.odometry(0.0, [1.0, 2.0])
    sp = ctrl.setpoint(0.0)
    np.testing.assert_array_equal(sp.reference, [1.0, 2.0])
    np.testing.assert_allclose(sp.velocity, [8.0 * 0.6, 8.0 * 0.8])  # 8 m/s towards it
    ctrl.odometry(0.25, [2.0, 3.0])
    sp = ctrl.setpoint(0.25)
    np.testing.assert_allclose(sp.reference, [1.0 + 1.2, 2.0 + 1.6])
    np.testing.assert_array_equal(sp.position, [31.0, 42.0])
    ctrl.odometry(0.5, [3.0, 4.0])  # tick 1: a new leg from this odometry...
    sp = ctrl.setpoint(0.5)
    ahead = np.array([1.0 + 2.4, 2.0 + 3.2])  # ... shifted by the lag behind the last reference
    np.testing.assert_allclose(sp.reference, ahead)
    np.testing.assert_allclose(sp.position, [33.0, 44.0])  # the planner's waypoint
    np.testing.assert_allclose(ctrl.setpoint(0.75).reference, ahead + [1.2, 1.6])
    assert [r["speed_m_s"] for r in ctrl.log.records if r["kind"] == "plan"] == [8.0, 8.0]


class East(Recorder):
    """Steps one step (4 m) east of the agent."""

    def act(self, observation):
        return observation.agent_position + np.array([4.0, 0.0])


@pytest.mark.parametrize("keep_lag", [True, False])
def test_a_new_leg_keeps_the_vehicles_lag_up_to_one_step_or_starts_at_the_odometry(
    flight_scenario, keep_lag
):
    ctrl, _ = _controller(flight_scenario, planner=East(), keep_lag=keep_lag)
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)  # the reference reaches (4, 0) at 0.5 s; the vehicle lags
    ctrl.odometry(0.5, [3.0, 0.0])
    sp = ctrl.setpoint(0.5)
    lag = 1.0 if keep_lag else 0.0
    np.testing.assert_allclose(sp.reference, [3.0 + lag, 0.0])
    np.testing.assert_allclose(ctrl.setpoint(0.75).reference, [5.0 + lag, 0.0])
    np.testing.assert_allclose(ctrl.setpoint(0.75).velocity, [8.0, 0.0])
    ctrl.odometry(1.0, [-3.0, 0.0])  # far behind: at most one step (4 m) is kept
    sp = ctrl.setpoint(1.0)
    np.testing.assert_allclose(sp.reference, [-3.0 + (4.0 if keep_lag else 0.0), 0.0])


def test_a_leg_after_a_hold_starts_at_the_odometry(flight_scenario):
    ctrl, _ = _controller(flight_scenario, planner=East())
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    assert ctrl.setpoint(1.2).hold  # no odometry for 1.2 s: stale, hold
    ctrl.odometry(1.3, [1.0, 0.0])
    sp = ctrl.setpoint(1.5)  # tick 3 flies again, from the odometry
    assert not sp.hold
    np.testing.assert_allclose(sp.reference, [1.0, 0.0])


def test_a_short_leg_stops_at_its_waypoint(flight_scenario):
    ctrl, _ = _controller(flight_scenario)  # steps 1 m east: there after 0.125 s at 8 m/s
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    ctrl.odometry(0.25, [0.5, 0.0])
    sp = ctrl.setpoint(0.25)
    np.testing.assert_array_equal(sp.reference, [1.0, 0.0])
    np.testing.assert_array_equal(sp.velocity, [0.0, 0.0])


def test_detections_outside_the_area_or_with_absurd_noise_are_refused(flight_scenario):
    from hptrack.runtime.inputs import mission_area

    centre, radius = mission_area(flight_scenario)
    assert radius == pytest.approx(8.0 * 60.0 + 10.0 + 10.0)  # v_a B + w/2 + 10 sigma
    ctrl, _ = _controller(flight_scenario)
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    assert not ctrl.detection(0.0, "p1", [1e300, 1e300])
    assert not ctrl.detection(0.0, "p1", [centre[0] + radius + 1.0, centre[1]])
    assert not ctrl.detection(0.0, "p1", [30.0, 10.0], 1e308 * np.eye(2) / 1e300 * 1e9)
    assert not ctrl.detection(0.0, "p1", [30.0, 10.0], 1e-300 * np.eye(2))
    assert ctrl.detection(0.0, "p1", [30.0, 10.0], 1e8 * np.eye(2))
    assert ctrl.rejected == {"detection: outside the area": 2, "detection: bad covariance": 2}
    assert not ctrl.finished


def test_a_failing_planner_holds_and_recovers(flight_scenario):
    planner = Recorder(fail_at={2})
    ctrl, _ = _controller(flight_scenario, planner=planner)
    out = {}
    for k in range(5):
        ctrl.odometry(0.5 * k, [k, 0.0])
        out[k] = ctrl.setpoint(0.5 * k)
    assert out[2].hold and out[2].reason == "planner error" and "boom at 2" in out[2].detail
    np.testing.assert_array_equal(out[2].position, [2.0, 0.0])
    assert not out[3].hold
    errors = [r for r in ctrl.log.records if r["kind"] == "plan" and r["status"] == "error"]
    assert len(errors) == 1 and "RuntimeError: boom at 2" in errors[0]["error"]
    assert planner.resets == 1


def test_setpoint_never_waits_for_a_slow_planner(flight_scenario):
    planner = Recorder(sleep_s=0.3)
    ctrl = MissionController(flight_scenario, planner, runner=ThreadedRunner())
    ctrl.odometry(0.0, [0.0, 0.0])
    start = time.perf_counter()
    slowest = 0.0
    first = None
    while time.perf_counter() - start < 1.0:
        t = time.perf_counter() - start
        ctrl.odometry(t, [0.0, 0.0])
        before = time.perf_counter()
        sp = ctrl.setpoint(t)
        slowest = max(slowest, time.perf_counter() - before)
        if first is None and not sp.hold:
            first = t
        time.sleep(0.01)
    ctrl.close()
    assert slowest < 0.05
    assert first is not None and 0.25 < first < 0.6


def test_before_any_odometry_it_holds_at_the_scenario_start(flight_scenario):
    ctrl, planner = _controller(flight_scenario)
    sp = ctrl.setpoint(0.0)
    assert sp.hold and sp.reason == "no odometry yet"
    np.testing.assert_array_equal(sp.position, flight_scenario.agent.position)
    assert not planner.observations


def test_the_mission_ends_at_the_budget(flight_scenario):
    ctrl, _ = _controller(flight_scenario)
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    ctrl.detection(0.0, "p1", [30.0, 10.0])
    ctrl.odometry(59.9, [0.0, 0.0])
    ctrl.setpoint(59.9)
    assert not ctrl.finished
    ctrl.odometry(60.0, [0.0, 0.0])
    sp = ctrl.setpoint(60.0)
    assert ctrl.finished and sp.hold and sp.reason == "mission over"
    end = ctrl.end
    assert end["reason"] == "budget" and end["time"] == 60.0
    q = flight_scenario.process_noise()
    _, cov = _textbook(flight_scenario.means()[1], flight_scenario.covariances()[1], q[1], 60.0)
    assert end["per_target_logdet"]["p2"] == pytest.approx(
        math.log(np.linalg.det(cov[:2, :2])), rel=1e-10
    )
    assert not ctrl.detection(60.1, "p1", [30.0, 10.0])
    assert ctrl.rejected["detection: after the end"] == 1


def test_the_current_sub_task_names_a_follow_a_dwell_and_a_pursuit():
    from hptrack.cli.flight import _subtask_text

    ids = ("t1", "t2")
    dwell = CurrentPlan(Subtask("dwell", 1, 30, 8), after_find=SubtaskAction("pursue", 0))
    assert plan_json(dwell, ids) == {
        "kind": "dwell",
        "target": "t2",
        "start_step": 30,
        "parameter": 8,
    }
    assert _subtask_text(dwell, ids) == "dwell on t2 (since step 30)"
    follow = CurrentPlan(Subtask("follow", 0, 7))
    assert _subtask_text(follow, ids) == "follow t1 (since step 7)"
    pursuit = CurrentPlan(Subtask("pursue", 0, 0, p_find=0.5), SubtaskAction("pursue", 1))
    assert plan_json(pursuit, ids) == {
        "kind": "pursue",
        "target": "t1",
        "start_step": 0,
        "p_find": 0.5,
    }
    assert _subtask_text(pursuit, ids) == "pursue t1 (since step 0, p_find 0.50)"
    assert plan_json(CurrentPlan(), ids) is None and _subtask_text(None, ids) == "-"
    # the shapes older mission logs hold read as the same records
    older = [
        {"dwell": "t2", "since_step": 30},
        {"follow": "t1", "since_step": 7},
        {"target": "t1", "since_step": 0, "p_find": 0.5},
    ]
    assert [Subtask.from_json(e, ids) for e in older] == [
        Subtask("dwell", 1, 30),
        follow.subtask,
        pursuit.subtask,
    ]


def test_the_controller_shows_the_hierarchical_planners_current_plan(flight_scenario):
    from hptrack.registry import make_planner

    ctrl, _ = _controller(flight_scenario, planner=make_planner("mcts", {"iterations": 200}))
    ctrl.odometry(0.0, [0.0, 0.0])
    ctrl.setpoint(0.0)
    plan = ctrl.status()["plan"]
    assert plan.subtask.kind == "pursue" and plan.subtask.start_step == 0
    assert 0.0 < plan.subtask.p_find <= 1.0
    first = next(r for r in ctrl.log.records if r["kind"] == "plan")
    assert first["subtask"] == plan_json(plan, flight_scenario.target_ids)
    header = ctrl.log.records[0]
    assert header["planner_settings"]["iterations"] == 200


def test_with_negative_information_each_tick_is_a_look_that_missed_the_targets_not_detected(
    flight_scenario,
):
    """Tick 0 from (25, 10) m misses both targets (p1's belief under the footprint); p1 is
    detected at 0.3 s, so tick 1 misses p2 only: the beliefs as the miss update and the Kalman
    update give them one by one. The paper's sensor (the default) leaves the priors."""
    data = file_data(flight_scenario)
    for name in ("sensor_diameter", "measurement_noise_std"):
        data["agent"].pop(name)
    data["sensor"] = {
        "diameter": 20.0,
        "measurement_noise_std": 1.0,
        "detection_probability": 0.8,
        "negative_information": True,
    }
    scenario = parse_scenario(data)
    ctrl, planner = _controller(scenario)
    ctrl.odometry(0.0, [25.0, 10.0])
    ctrl.setpoint(0.0)
    ctrl.detection(0.3, "p1", [31.0, 10.0])
    ctrl.odometry(0.5, [26.0, 10.0])
    ctrl.setpoint(0.5)
    first, second = planner.observations
    motion, q = scenario.mission_spec().motion, scenario.process_noise()
    table = (np.zeros(1), np.array([0.8]))
    means, covs = scenario.means(), scenario.covariances()
    for i in range(2):
        miss_update(means[i], covs[i], 25.0, 10.0, 10.0, *table)
    np.testing.assert_allclose(first.means, means, rtol=1e-12)
    np.testing.assert_allclose(first.covariances, covs, rtol=1e-12)
    assert covs[0, 0, 0] > 1.2 * scenario.covariances()[0, 0, 0]  # the miss moved p1
    m, c = motion.predict(means, covs, q, np.array([0.3, 0.5]))
    kalman_update(m[0].copy(), c[0].copy(), np.array([31.0, 10.0]), np.eye(2), m[0], c[0])
    m[0], c[0] = (x[0] for x in motion.predict(m[:1], c[:1], q[:1], 0.2))
    miss_update(m[1], c[1], 26.0, 10.0, 10.0, *table)
    np.testing.assert_allclose(second.means, m, rtol=1e-10)
    np.testing.assert_allclose(second.covariances, c, rtol=1e-10, atol=1e-12)
    plain, recorder = _controller(flight_scenario)
    plain.odometry(0.0, [25.0, 10.0])
    plain.setpoint(0.0)
    np.testing.assert_array_equal(
        recorder.observations[0].covariances, flight_scenario.covariances()
    )
