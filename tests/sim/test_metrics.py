"""Tracking metrics (`hptrack.sim.metrics`): GOSPA on toy sets with values computed by hand and
against Stone Soup's ``GOSPAMetric``, track loss, and the episode record's metrics."""

import datetime
import math

import numpy as np
import pytest

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.scenario import random_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.metrics import (
    ELLIPSE_CHI2,
    gospa,
    gospa_assignment,
    gospa_cutoff,
    gospa_history,
    never_detected,
    outside_ellipse,
    track_lost,
)
from hptrack.sim.record import EpisodeRecord


def test_gospa_of_toy_sets_is_the_hand_computed_value():
    c = 50.0
    # two pairs at 3 m and 4 m: sqrt(9 + 16)
    assert gospa([[0, 0], [10, 0]], [[0, 3], [10, 4]], c) == pytest.approx(5.0, rel=1e-15)
    # label-free: the same points in another order are at distance 0
    assert gospa([[10, 0], [0, 0]], [[0, 0], [10, 0]], c) == 0.0
    # one truth missed: c^2 / 2 for it
    assert gospa([[0, 0]], [[0, 0], [100, 100]], c) == pytest.approx(math.sqrt(1250.0))
    assert gospa([[0, 0], [100, 100]], [[0, 0]], c) == pytest.approx(math.sqrt(1250.0))
    # a pair farther than c counts as one missed and one false: c
    assert gospa([[0, 0]], [[60, 0]], c) == pytest.approx(50.0, rel=1e-15)
    # no estimates: every truth missed
    assert gospa(np.zeros((0, 2)), [[0, 0], [1, 1], [2, 2]], c) == pytest.approx(
        math.sqrt(3 * 1250.0)
    )
    assert gospa(np.zeros((0, 2)), np.zeros((0, 2)), c) == 0.0
    # p = 1, alpha = 1: min(5, 10) + 10 / 1 for the missed one
    assert gospa([[0, 0]], [[3, 4], [100, 0]], 10.0, p=1, alpha=1) == pytest.approx(15.0)
    # the assignment: estimate 0 to truth 1, estimate 1 (far from every truth) unassigned
    d, pairs = gospa_assignment([[0, 1], [500, 500]], [[80, 0], [0, 0]], c)
    assert pairs.tolist() == [1, -1]
    assert d == pytest.approx(math.sqrt(1.0 + 2 * 1250.0))
    with pytest.raises(ValueError, match="c > 0"):
        gospa([[0, 0]], [[0, 0]], 0.0)


@pytest.mark.parametrize(("m", "n"), [(4, 4), (3, 6), (6, 3), (1, 5)])
def test_gospa_agrees_with_stone_soups(m, n):
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.types.state import State

    rng = np.random.default_rng(m * 10 + n)
    t = datetime.datetime(2026, 1, 1)
    for _ in range(5):
        x = rng.uniform(0.0, 150.0, (m, 2))
        y = rng.uniform(0.0, 150.0, (n, 2))
        metric = GOSPAMetric(c=50.0, p=2, measure=Euclidean(mapping=(0, 1)))
        theirs, _ = metric.compute_gospa_metric(
            [State(v.reshape(2, 1), timestamp=t) for v in x],
            [State(v.reshape(2, 1), timestamp=t) for v in y],
        )
        assert gospa(x, y, 50.0) == pytest.approx(theirs.value["distance"], rel=1e-12)


def test_gospa_history_is_gospa_at_each_step():
    rng = np.random.default_rng(3)
    x, y = rng.normal(0, 40, (7, 3, 2)), rng.normal(0, 40, (7, 3, 2))
    np.testing.assert_array_equal(
        gospa_history(x, y, 50.0), [gospa(a, b, 50.0) for a, b in zip(x, y, strict=True)]
    )
    assert gospa_cutoff(100.0) == 50.0


def test_the_ellipse_rule_is_the_chi_square_quantile():
    assert ELLIPSE_CHI2 == pytest.approx(9.210340371976184, rel=1e-15)  # chi2.ppf(0.99, 2)
    # Sigma = [[4, 1], [1, 1]]: e = k (1, 1) has d2 = k^2 (Sigma^-1 = [[1, -1], [-1, 4]] / 3)
    cov = np.array([[[4.0, 1.0], [1.0, 1.0]]] * 2)
    r = math.sqrt(ELLIPSE_CHI2)
    truths = np.array([[1.0, 1.0], [1.0, 1.0]]) * np.array([[r - 1e-6], [r + 1e-6]])
    assert outside_ellipse(np.zeros((2, 2)), cov, truths).tolist() == [False, True]


def test_track_loss_counts_lost_and_swapped_tracks():
    c = 50.0
    wide = np.array([np.eye(2) * 1e6] * 2)
    # truths swapped between two close beliefs: inside both ellipses, but swapped
    assert track_lost([[0, 0], [20, 0]], wide, [[20, 0], [0, 0]], c).tolist() == [True, True]
    # far beliefs with wide ellipses are neither lost nor swapped (no pair closer than c)
    assert track_lost([[0, 0], [500, 0]], wide, [[300, 300], [900, 900]], c).tolist() == [
        False,
        False,
    ]
    # a tight belief 10 m off is lost; one exactly on its truth is kept
    tight = np.array([np.eye(2)] * 2)
    assert track_lost([[0, 0], [200, 0]], tight, [[10, 0], [200, 0]], c).tolist() == [True, False]
    assert never_detected(np.array([[True, False, False], [False, False, True]])) == 1


def test_the_record_keeps_the_means_at_every_step_whatever_the_stride(tmp_path):
    scenario = random_scenario(3, seed=4)
    every = run_episode(scenario, GreedyPlanner())
    sparse = run_episode(scenario, GreedyPlanner(), belief_stride=scenario.n_steps)
    assert sparse.uncertainty == every.uncertainty
    assert every.mean_positions.shape == (scenario.n_steps + 1, 3, 2)
    np.testing.assert_array_equal(every.mean_positions, every.belief_means[..., :2])
    np.testing.assert_array_equal(sparse.mean_positions, every.mean_positions)
    steps, values = every.gospa_history()
    np.testing.assert_array_equal(steps, np.arange(scenario.n_steps + 1))
    truth = every.true_states[..., :2]
    assert values[0] == gospa(every.mean_positions[0], truth[0], 50.0)
    assert values[-1] == gospa(every.mean_positions[-1], truth[-1], 50.0)
    metrics = every.metrics()
    assert metrics == sparse.metrics()
    assert metrics["gospa_mean"] == pytest.approx(values.mean(), rel=1e-15)
    assert metrics["gospa_end"] == values[-1]
    lost = track_lost(
        every.belief_means[-1, :, :2], every.belief_covariances[-1, :, :2, :2], truth[-1], 50.0
    )
    assert metrics["track_loss"] == int(lost.sum())
    assert metrics["targets_never_detected"] == int((~every.detections.any(axis=0)).sum())
    summary = every.summary()
    assert {k: summary[k] for k in metrics} == metrics
    sparse.save(tmp_path / "r.npz")
    loaded = EpisodeRecord.load(tmp_path / "r.npz")
    np.testing.assert_array_equal(loaded.mean_positions, every.mean_positions)
    assert loaded.metrics() == metrics


def test_a_record_without_the_means_per_step_uses_its_stored_beliefs(tmp_path):
    record = run_episode(random_scenario(2, seed=6), GreedyPlanner(), belief_stride=600)
    record.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        arrays = {k: data[k] for k in data.files if k != "mean_positions"}
    np.savez_compressed(tmp_path / "old.npz", **arrays)  # as an older hptrack wrote it
    old = EpisodeRecord.load(tmp_path / "old.npz")
    assert old.mean_positions is None
    steps, values = old.gospa_history()
    np.testing.assert_array_equal(steps, [0, 600, 1200, 1800])
    truth = record.true_states[steps, :, :2]
    np.testing.assert_array_equal(values, gospa_history(record.mean_positions[steps], truth, 50.0))
    assert old.metrics()["gospa_end"] == record.metrics()["gospa_end"]
    # a record without the truth (a flight's) has none of the truth's metrics
    old.true_states = np.full_like(old.true_states, np.nan)
    blind = old.metrics()
    assert blind["gospa_mean"] is None and blind["track_loss"] is None
    assert blind["targets_never_detected"] == record.metrics()["targets_never_detected"]
