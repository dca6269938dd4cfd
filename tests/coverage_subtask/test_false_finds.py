"""False finds: the take region against the tracker's own decisions on uniform false alarms,
and the find / miss / false find split against a Monte Carlo of the competing streams."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.coverage.false_finds import GATE, false_find_split, take_rate
from hptrack.interface import MissionSpec
from hptrack.models.association import gate_threshold
from hptrack.models.sensor import FootprintSensor
from hptrack.models.tracking import GATE_PROBABILITY, Tracker, new_track_covariance

R = np.diag([10.0, 10.0])
RADIUS = 50.0


def test_the_gate_is_the_trackers():
    assert GATE == pytest.approx(gate_threshold(GATE_PROBABILITY), rel=1e-12)


def _taken_share(sigma: float, density: float, looks: int, seed: int) -> float:
    """The share of false alarms, one a look uniform over a footprint centred on a belief of
    std ``sigma`` m, that the tracker (GNN, no target report) takes for that belief."""
    tracker = Tracker(
        MissionSpec().motion,
        FootprintSensor(2 * RADIUS, R),
        R,
        density,
        "gnn",
        (3, 5),
        1e-4,
        new_track_covariance(R, np.array([np.diag([900.0, 900.0, 0.3, 0.3])])),
    )
    rng = np.random.default_rng(seed)
    radius = RADIUS * np.sqrt(rng.uniform(size=looks))
    angle = rng.uniform(0.0, 2 * math.pi, size=looks)
    reports = np.column_stack([radius * np.cos(angle), radius * np.sin(angle)])
    taken = 0
    for z in reports:
        tracker.tentative = []
        means = np.zeros((1, 4))
        covs = np.diag([sigma**2, sigma**2, 0.3, 0.3])[None].copy()
        taken += int(tracker.look(np.zeros(2), means, covs, z[None]).belief_of[0] == 0)
    return taken / looks


@pytest.mark.parametrize(
    ("sigma", "density"),
    [(5.0, 1e-6), (8.0, 1e-6), (300.0, 1e-6), (3000.0, 1e-6), (400.0, 1e-6)],
)
def test_the_take_rate_is_the_share_the_tracker_takes(sigma, density):
    """Narrow beliefs take what falls in their gate (a disc smaller than the footprint), wide
    ones everything, very wide ones nothing (their density never beats the clutter's)."""
    expected = take_rate(density, RADIUS, sigma**2, 0.0, sigma**2, 10.0, 0.0, 10.0) / (
        density * math.pi * RADIUS**2
    )
    looks = 3000
    share = _taken_share(sigma, density, looks, seed=int(sigma))
    assert abs(share - expected) <= 4 * math.sqrt(max(expected * (1 - expected), 1e-4) / looks)
    if sigma == 5.0:
        assert expected == pytest.approx(GATE * (25.0 + 10.0) / RADIUS**2, rel=1e-12)


def test_no_clutter_no_take():
    assert take_rate(0.0, RADIUS, 100.0, 0.0, 100.0, 10.0, 0.0, 10.0) == 0.0
    assert false_find_split(0.8, 40.0, 90.0, 0.0) == (0.8, pytest.approx(0.2), 0.0, 0.0)


@pytest.mark.parametrize(
    ("p", "find_looks", "miss_looks", "rate"), [(0.8, 40, 90, 0.005), (0.3, 10, 200, 0.02)]
)
def test_the_split_is_the_monte_carlo_of_competing_streams(p, find_looks, miss_looks, rate):
    rng = np.random.default_rng(11)
    size = 400_000
    found = rng.uniform(size=size) < p
    end = np.where(found, find_looks, miss_looks)
    take = rng.exponential(1.0 / rate, size=size)
    false = take < end
    p_true, p_miss, p_false, looks = false_find_split(p, find_looks, miss_looks, rate)
    assert p_true + p_miss + p_false == pytest.approx(1.0, abs=1e-15)
    se = math.sqrt(0.25 / size)
    assert abs(np.mean(found & ~false) - p_true) < 4 * se
    assert abs(np.mean(~found & ~false) - p_miss) < 4 * se
    assert abs(np.mean(false) - p_false) < 4 * se
    assert abs(np.mean(take[false]) - looks) < 4 * np.std(take[false]) / math.sqrt(false.sum())
