"""Detections without identity: the detector's statistics (Poisson clutter, uniform over the
footprint, Pd, R), the chance of a belief inside the footprint, the tracker's likelihood-ratio
association (a wide belief does not take a false alarm it should not), the M-of-N rule exactly,
and the simulator's episodes and records."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.interface import MissionSpec
from hptrack.models.association import gate_threshold
from hptrack.models.detector import Detector
from hptrack.models.measurement import kalman_update
from hptrack.models.sensor import FootprintSensor, detecting_sensor
from hptrack.models.tracking import (
    GATE_PROBABILITY,
    Tracker,
    footprint_probability,
    new_track_covariance,
)
from hptrack.scenario import parse_scenario, random_scenario
from hptrack.scenario.io import ScenarioError, file_data
from hptrack.sim.episode import run_episode
from hptrack.sim.metrics import outside_ellipse
from hptrack.sim.record import EpisodeRecord

R = np.diag([10.0, 10.0])
FOOTPRINT = FootprintSensor(100.0, R)
AGENT = np.array([0.0, 0.0])


def test_clutter_is_poisson_and_uniform_over_the_footprint():
    detector = Detector(FOOTPRINT, R, 1e-4, np.random.default_rng(7))
    looks = [detector.look(AGENT, np.empty((0, 2))) for _ in range(20_000)]
    counts = np.array([len(d.sources) for d in looks])
    mean = 1e-4 * math.pi * 50.0**2  # 0.785 per look
    assert abs(counts.mean() - mean) < 3 * math.sqrt(mean / counts.size)
    assert abs(counts.var() - mean) < 0.05 * mean  # Poisson: variance = mean
    points = np.concatenate([d.positions for d in looks])
    assert np.all(np.concatenate([d.sources for d in looks]) == -1)
    r2 = np.sum(points**2, axis=1) / 50.0**2
    assert r2.max() <= 1.0
    # uniform over the disc: r^2 / R^2 ~ U(0, 1), angle uniform
    assert abs(r2.mean() - 0.5) < 3 * math.sqrt(1 / 12 / r2.size)
    assert abs(np.mean(points[:, 0])) < 3 * 25.0 / math.sqrt(r2.size)


def test_targets_are_detected_at_pd_with_noise_r():
    sensor = detecting_sensor(100.0, R, 0.7, 15.0)
    detector = Detector(sensor, R, 0.0, np.random.default_rng(3))
    targets = np.array([[5.0, 5.0], [200.0, 0.0]])  # inside, outside
    looks = [detector.look(AGENT, targets) for _ in range(20_000)]
    hits = np.array([len(d.sources) for d in looks])
    assert set(np.concatenate([d.sources for d in looks]).tolist()) == {0}
    assert abs(hits.mean() - 0.7) < 3 * math.sqrt(0.21 / hits.size)
    errors = np.concatenate([d.positions for d in looks]) - targets[0]
    np.testing.assert_allclose(np.cov(errors.T), R, rtol=0.05, atol=0.3)
    # the paper's sensor reports every target inside, and only them
    certain = Detector(FOOTPRINT, R, 0.0, np.random.default_rng(3))
    assert all(certain.look(AGENT, targets).sources.tolist() == [0] for _ in range(100))


def test_footprint_probability_matches_the_closed_form_of_a_centred_circle():
    for sigma in (3.0, 30.0, 300.0, 3000.0):
        p = footprint_probability(AGENT, 50.0, AGENT[None], np.diag([sigma**2] * 2)[None])
        assert p[0] == pytest.approx(-math.expm1(-(50.0**2) / (2 * sigma**2)), rel=1e-9)


def _tracker(density: float, confirmation=(3, 5), association="gnn") -> Tracker:
    mission = MissionSpec()
    priors = np.array([np.diag([900.0, 900.0, 0.3, 0.3])])
    return Tracker(
        mission.motion,
        FOOTPRINT,
        R,
        density,
        association,
        confirmation,
        1e-4,
        new_track_covariance(R, priors),
    )


def _belief(x: float, y: float, var: float) -> tuple[np.ndarray, np.ndarray]:
    return np.array([[x, y, 0.0, 0.0]]), np.array([np.diag([var, var, 0.01, 0.01])])


def test_a_wide_belief_takes_a_report_only_when_its_density_beats_the_clutter():
    # a belief of std 2000 m centred 30 m from the report: Pd N(z; zhat, S) ~ 4e-8 per m^2
    z = np.array([[30.0, 0.0]])
    means, covs = _belief(0.0, 0.0, 2000.0**2)
    s = 2000.0**2 + 10.0
    density = math.exp(-0.5 * 900.0 / s) / (2 * math.pi * s)
    inside = footprint_probability(AGENT, 50.0, means[:, :2], covs[:, :2, :2])[0]
    miss = 1 - inside * GATE_PROBABILITY
    threshold = density / miss  # the clutter density at which both weigh the same
    for clutter, takes in ((threshold * 1.01, False), (threshold * 0.99, True)):
        m, c = means.copy(), covs.copy()
        look = _tracker(clutter).look(AGENT, m, c, z)
        assert look.belief_of.tolist() == ([0] if takes else [-1])
        assert look.seen.tolist() == [takes]
    # a narrow belief takes it and is Kalman-updated
    m, c = _belief(25.0, 0.0, 100.0)
    want_m, want_c = m.copy(), c.copy()
    kalman_update(want_m[0], want_c[0], z[0], R, want_m[0], want_c[0])
    look = _tracker(1e-6).look(AGENT, m, c, z)
    assert look.belief_of.tolist() == [0]
    np.testing.assert_array_equal(m, want_m)
    np.testing.assert_array_equal(c, want_c)


def _looks(pattern: str, confirmation=(3, 5)) -> list[int]:
    """The looks (1-based) at which a tentative track claims the far belief, for reports at
    the footprint's centre in the looks of ``pattern`` (``x`` a report, ``.`` none)."""
    tracker = _tracker(1e-6, confirmation)
    means, covs = _belief(5000.0, 0.0, 100.0)  # far outside: claims no report
    claims = []
    for look, mark in enumerate(pattern, start=1):
        reports = np.array([[1.0, -1.0]]) if mark == "x" else np.empty((0, 2))
        result = tracker.look(AGENT, means, covs, reports)
        assert result.belief_of.tolist() == [-1] * len(reports)
        if result.claims:
            assert result.claims == [(0, 0)] and result.seen.tolist() == [True]
            claims.append(look)
            means, covs = _belief(5000.0, 0.0, 100.0)
    return claims


def test_m_of_n_confirms_exactly():
    assert _looks("xxx") == [3]
    assert _looks("xx.x") == [4]
    assert _looks("x..xx") == [5]  # 3 of the first 5 looks
    assert _looks("x...xx") == []  # the first dropped after 4 looks, the second at 2 hits
    assert _looks("x...xxx") == [7]
    assert _looks("x", confirmation=(1, 1)) == [1]
    assert _looks("x.x", confirmation=(2, 2)) == []


def test_a_confirmed_track_takes_the_state_of_its_filter():
    tracker = _tracker(1e-6, (2, 3))
    means, covs = _belief(5000.0, 0.0, 100.0)
    tracker.look(AGENT, means, covs, np.array([[1.0, -1.0]]))
    track = tracker.tentative[0]
    predicted = tracker.motion.predict(
        track.mean[None], track.covariance[None], 1e-4, tracker.motion.time_step
    )
    m, c = predicted[0][0].copy(), predicted[1][0].copy()
    kalman_update(m, c, np.array([2.0, 0.0]), R, m, c)
    tracker.look(AGENT, means, covs, np.array([[2.0, 0.0]]))
    np.testing.assert_allclose(means[0], m, rtol=1e-15)
    np.testing.assert_allclose(covs[0], c, rtol=1e-15)


def test_a_teams_later_looks_in_a_step_neither_move_the_tentative_tracks_nor_count_a_look():
    # a report at a step's first look, then a second UAV's look of the same step: the track
    # stays where the first look put it, at one look; the next step predicts it once
    tracker = _tracker(1e-6, (3, 5))
    means, covs = _belief(5000.0, 0.0, 100.0)
    tracker.look(AGENT, means, covs, np.array([[1.0, -1.0]]))
    track = tracker.tentative[0]
    mean, cov = track.mean.copy(), track.covariance.copy()
    tracker.look(AGENT + 300.0, means, covs, np.empty((0, 2)), new_step=False)
    assert tracker.tentative == [track] and track.looks == 1 and track.hits == 1
    np.testing.assert_array_equal(track.mean, mean)
    np.testing.assert_array_equal(track.covariance, cov)
    tracker.look(AGENT + 300.0, means, covs, np.empty((0, 2)))
    predicted = tracker.motion.predict(mean[None], cov[None], 1e-4, tracker.motion.time_step)
    assert track.looks == 2
    np.testing.assert_array_equal(track.mean, predicted[0][0])


def test_jpda_splits_a_report_between_two_close_beliefs():
    means = np.array([[-3.0, 0.0, 0.0, 0.0], [3.0, 0.0, 0.0, 0.0]])
    covs = np.array([np.diag([50.0, 50.0, 0.01, 0.01])] * 2)
    look = _tracker(1e-6, association="jpda").look(AGENT, means, covs, np.array([[0.0, 0.0]]))
    assert look.belief_of[0] in (0, 1) and 0.45 < look.weight[0] < 0.55
    assert abs(means[0, 0] + means[1, 0]) < 1e-9  # symmetric
    assert gate_threshold(GATE_PROBABILITY) == pytest.approx(-2 * math.log(1e-4))


def test_lost_tracks_by_the_99_percent_ellipse():
    means, covs = _belief(0.0, 0.0, 100.0)
    for distance, lost in ((30.0, False), (31.0, True)):  # sqrt(9.21 * 100) = 30.35 m
        truth = np.array([[distance, 0.0, 0.0, 0.0]])
        assert outside_ellipse(means[:, :2], covs[:, :2, :2], truth[:, :2]).tolist() == [lost]


def _data(**sensor) -> dict:
    data = file_data(random_scenario(3, seed=2, budget=200.0))
    data["sensor"] = sensor
    return data


def test_the_fields_are_validated_in_one_line():
    with pytest.raises(ScenarioError, match="false_alarm_density 1e-06 per m\\^2 needs labelled"):
        parse_scenario(_data(false_alarm_density=1e-6))
    with pytest.raises(ScenarioError, match="confirmation \\[M, N\\] needs M <= N"):
        parse_scenario(_data(labelled=False, confirmation=[4, 3]))
    with pytest.raises(ScenarioError, match="sensor.association"):
        parse_scenario(_data(labelled=False, association="mht"))
    with pytest.raises(ScenarioError, match="sensor.labelled"):
        parse_scenario(_data(labelled="no"))
    # the defaults are left out of a written file
    assert file_data(parse_scenario(_data(labelled=True, confirmation=[3, 5])))["sensor"] == {
        "model": "footprint",
        "diameter": 100.0,
        "measurement_noise_std": math.sqrt(10.0),
    }


def test_an_unlabelled_episode_records_its_associations(tmp_path):
    labelled = run_episode(parse_scenario(_data()), GreedyPlanner(), seed=1)
    assert labelled.associations is None and labelled.tracking_summary() == {}
    data = _data(labelled=False, false_alarm_density=1e-5, detection_probability=0.9)
    record = run_episode(parse_scenario(data), GreedyPlanner(), seed=1)
    rows = record.associations
    assert rows is not None and rows.shape[1] == 6 and len(rows) > 0
    assert np.all(np.isin(rows[:, 3], [-1, 0, 1, 2]))
    # every report that went to a belief made it seen at that step
    went = rows[rows[:, 4] >= 0]
    assert np.all(record.detections[went[:, 0].astype(int), went[:, 4].astype(int)])
    summary = record.summary()["tracking"]
    assert summary["reports"] == len(rows)
    assert summary["false_alarms"] == int(np.sum(rows[:, 3] < 0)) > 0
    path = tmp_path / "episode.npz"
    record.save(path)
    again = EpisodeRecord.load(path)
    np.testing.assert_array_equal(again.associations, rows)
    assert again.wrong_associations() == record.wrong_associations()
    # the same seed, the same episode
    twice = run_episode(parse_scenario(data), GreedyPlanner(), seed=1)
    np.testing.assert_array_equal(twice.associations, rows)
    assert twice.uncertainty == record.uncertainty


def test_the_cli_refuses_clutter_with_named_detections(cli, tmp_path):
    import yaml

    path = tmp_path / "clutter.yaml"
    path.write_text(yaml.safe_dump(_data(false_alarm_density=1e-6)))
    cli("simulate", path).refused("false_alarm_density 1e-06", "labelled: false")
    path.write_text(yaml.safe_dump(_data(labelled=False, confirmation=[0, 5])))
    cli("simulate", path).refused("sensor.confirmation.0", "greater than or equal to 1")
    path.write_text(yaml.safe_dump(_data(labelled=False, negative_information=True)))
    cli("simulate", path).refused("negative_information needs labelled: true")


def test_a_written_scenario_keeps_the_fields_with_their_comments(tmp_path):
    from hptrack.scenario.io import load_scenario, save_scenario

    fields = dict(labelled=False, false_alarm_density=1e-6, association="jpda", confirmation=[2, 4])
    scenario = parse_scenario(_data(**fields))
    path = tmp_path / "s.yaml"
    save_scenario(scenario, path)
    assert load_scenario(path) == scenario
    lines = path.read_text().splitlines()
    for name in fields:
        (line,) = [x for x in lines if x.strip().startswith(f"{name}:")]
        assert "  # " in line, line
