"""Fitting ``detection_probability`` from logged looks: exact shares, the pooled non-increasing
fit and Wilson intervals on toy counts; a Monte Carlo of a known table recovered within its
intervals; ``hptrack fit-detection`` writes a fragment a scenario loads, and refuses bad logs."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from hptrack.models.detection_fit import fit_detection_probability, wilson_interval
from hptrack.models.sensor import detection_table
from hptrack.scenario import parse_scenario, random_scenario


def _looks(counts: list[tuple[float, int, int]]) -> tuple[np.ndarray, np.ndarray]:
    """Looks at the given distances: ``(distance_m, looks, hits)`` per group."""
    distances, detected = [], []
    for distance, n, hits in counts:
        distances += [distance] * n
        detected += [True] * hits + [False] * (n - hits)
    return np.array(distances), np.array(detected)


def test_wilson_interval_matches_its_closed_form():
    low, high = wilson_interval(np.array([8]), np.array([10]))
    # (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n), p = 0.8, n = 10, z = 1.96
    assert low[0] == pytest.approx(0.4901625, abs=1e-6)
    assert high[0] == pytest.approx(0.9433178, abs=1e-6)
    low, high = wilson_interval(np.array([0, 5]), np.array([5, 5]))
    assert low[0] == 0.0 and high[1] == pytest.approx(1.0)


def test_shares_per_bin_and_the_pooled_non_increasing_fit():
    distances, detected = _looks([(5.0, 10, 9), (15.0, 5, 5), (25.0, 20, 14), (45.0, 4, 1)])
    raw = fit_detection_probability(distances, detected, bin_width_m=10.0, monotone=False)
    assert raw.low_m.tolist() == [0.0, 10.0, 20.0, 40.0]  # the empty 30-40 m bin is left out
    assert raw.looks.tolist() == [10, 5, 20, 4] and raw.hits.tolist() == [9, 5, 14, 1]
    assert raw.fitted.tolist() == [0.9, 1.0, 0.7, 0.25]
    fit = fit_detection_probability(distances, detected, bin_width_m=10.0)
    # the first two bins violate the order and pool: 14 hits in 15 looks
    assert fit.fitted == pytest.approx([14 / 15, 14 / 15, 0.7, 0.25], abs=1e-12)
    assert fit.constant == pytest.approx(29 / 39)
    assert fit.rows() == [
        [0.0, pytest.approx(14 / 15)],
        [15.0, pytest.approx(14 / 15)],
        [25.0, 0.7],
        [45.0, 0.25],
    ]
    detection_table(fit.rows())  # a valid sensor table


def test_a_known_table_is_recovered_within_its_intervals():
    rng = np.random.default_rng(0)
    distances = rng.uniform(0.0, 50.0, size=200_000)
    truth = np.interp(distances, [0.0, 30.0, 50.0], [0.9, 0.8, 0.5])
    detected = rng.random(distances.size) < truth
    fit = fit_detection_probability(distances, detected, bin_width_m=5.0)
    centres = 0.5 * (fit.low_m + fit.high_m)
    expected = np.interp(centres, [0.0, 30.0, 50.0], [0.9, 0.8, 0.5])  # linear within a bin
    assert np.all(np.abs(fit.fitted - expected) < 0.01)
    covered = (fit.interval_low <= expected) & (expected <= fit.interval_high)
    assert covered.sum() >= 9  # 10 bins at 95 % each
    assert fit.constant == pytest.approx(np.mean(truth), abs=0.005)


@pytest.mark.parametrize(
    ("distances", "width", "message"),
    [
        ([], 10.0, "no looks"),
        ([-1.0], 10.0, "look 0"),
        ([1.0], 0.0, "bin width"),
        ([1.0], 1e-300, "bins"),
    ],
)
def test_bad_looks_are_refused(distances, width, message):
    with pytest.raises(ValueError, match=message):
        fit_detection_probability(np.array(distances), np.ones(len(distances), bool), width)


def test_fit_detection_writes_a_fragment_a_scenario_loads(cli, tmp_path):
    distances, detected = _looks([(5.0, 40, 36), (25.0, 40, 30), (45.0, 40, 20)])
    log = tmp_path / "looks.csv"
    rows = "".join(f"{d},{int(h)},x\n" for d, h in zip(distances, detected, strict=True))
    log.write_text("distance_m,detected,frame\n" + rows)
    fragment, out = tmp_path / "sensor.yaml", tmp_path / "fit.json"
    result = cli("fit-detection", log, "--bin-width", "10", "-o", fragment, "--json", out)
    assert result.code == 0, result.err
    assert "constant Pd = 0.717" in result.out
    sensor = yaml.safe_load(fragment.read_text())["sensor"]
    assert sensor["detection_probability"] == [[0.0, 0.9], [25.0, 0.75], [45.0, 0.5]]
    data = random_scenario(3, seed=0).model_dump(mode="json")
    scenario = parse_scenario({**data, "sensor": {**(data.get("sensor") or {}), **sensor}})
    assert scenario.sensor_spec().detection_probability == ((0.0, 0.9), (25.0, 0.75), (45.0, 0.5))
    fit = json.loads(out.read_text())
    assert [b["looks"] for b in fit["bins"]] == [40, 40, 40]


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("distance,detected\n1,1\n", ("looks.csv", "missing distance_m")),
        ("distance_m,detected\n1,1\nfar,0\n", ("line 3", "distance_m", "'far'")),
        ("distance_m,detected\n-2,1\n", ("line 2", "-2")),
        ("distance_m,detected\n2,maybe\n", ("line 2", "detected", "'maybe'")),
        ("distance_m,detected\n", ("holds no looks",)),
    ],
)
def test_fit_detection_refuses_a_bad_log_in_one_line(cli, tmp_path, text, needles):
    log = tmp_path / "looks.csv"
    log.write_text(text)
    cli("fit-detection", log).refused(*needles)


def test_fit_detection_refuses_a_missing_file_and_a_bad_width(cli, tmp_path):
    cli("fit-detection", tmp_path / "none.csv").refused("none.csv", "cannot be read")
    log = tmp_path / "looks.csv"
    log.write_text("distance_m,detected\n1,1\n")
    cli("fit-detection", log, "--bin-width", "-1").refused("--bin-width", "-1")
    cli("fit-detection", log, "--bin-width", "1e-300").refused("--bin-width", "bins")
