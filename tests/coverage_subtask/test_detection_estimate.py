"""The coverage estimators with a detection probability below one: the sensor sweeps an effective
width ``eta w`` (``t_cutoff`` unchanged), the paper's sensor gives every number bit for bit, and
the find probability agrees with a Monte Carlo of the spiral that draws the detections the
simulator draws; ``validate-coverage --detection-probability`` and ``--detection-table`` run it and
record it in the results' identity."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hptrack.coverage.estimator import coverage_cdf, coverage_outcome
from hptrack.coverage.sharp_estimator import sharp_coverage_outcome
from hptrack.experiments.coverage_validation import ValidationConfig, case_rows, draw_case
from hptrack.interface import MissionSpec
from hptrack.models.sensor import DetectingFootprintSensor, FootprintSensor

TABLE = ((0.0, 0.9), (30.0, 0.8), (50.0, 0.5))


def _cases():
    """Beliefs at the start of a coverage, from small to large (4x4, m and m/s) and their q."""
    rng = np.random.default_rng(5)
    out = []
    for scale in (30.0, 120.0, 400.0):
        a = rng.normal(size=(4, 4))
        cov = a @ a.T * 0.05 + np.diag([scale**2, (0.7 * scale) ** 2, 2.0, 1.5])
        out.append((cov, float(rng.uniform(0.01, 0.5))))
    return out


def _outcomes(record):
    rows = []
    for cov, q in _cases():
        rows.append(coverage_outcome(record, cov, q, 1800))
        rows.append(sharp_coverage_outcome(record, cov, q, 1800, 12, 10.0, -8.0))
        rows.append(sharp_coverage_outcome(record, cov, q, 1800, 0, 0.0, 0.0))
        rows.append(tuple(coverage_cdf(record, cov, q, 50)))
    return rows


def test_certain_detection_gives_every_number_bit_for_bit():
    record = MissionSpec().record
    assert type(record.sensor) is FootprintSensor
    plain = _outcomes(record)
    # the detecting sensor's formulas with a factor of exactly 1 are the paper's, bit for bit
    detecting = DetectingFootprintSensor(
        record.sensor.diameter, record.sensor.measurement_noise, np.zeros(1), np.ones(1), 1.0
    )
    for a, b in zip(plain, _outcomes(record._replace(sensor=detecting)), strict=True):
        np.testing.assert_array_equal(np.array(a), np.array(b))
    # Pd = 1 written as a number or a table is the paper's sensor itself
    for value in (1.0, ((0.0, 1.0), (20.0, 1.0))):
        again = MissionSpec(detection_probability=value).record
        assert type(again.sensor) is FootprintSensor
        for a, b in zip(plain, _outcomes(again), strict=True):
            np.testing.assert_array_equal(np.array(a), np.array(b))


@pytest.mark.parametrize("value", [0.9, 0.5, TABLE])
def test_the_sensor_sweeps_eta_of_the_width(value):
    record = MissionSpec(detection_probability=value).record
    eta = record.sensor.find_factor
    assert 0.9 < eta < 1.0  # some seven looks cross a 100 m footprint at 15 m per step
    plain = MissionSpec().record
    for cov, q in _cases():
        k1, p1, e1 = coverage_outcome(plain, cov, q, 1800)
        k, p, e = coverage_outcome(record, cov, q, 1800)
        assert k == k1  # t_cutoff unchanged
        assert p == pytest.approx(1.0 - (1.0 - p1) ** eta, rel=1e-12)
        assert p < p1 and e > 0.0
        cdf, cdf1 = coverage_cdf(record, cov, q, 30), coverage_cdf(plain, cov, q, 30)
        np.testing.assert_allclose(cdf, 1.0 - (1.0 - cdf1) ** eta, rtol=1e-12)
        ks1, f1, _ = sharp_coverage_outcome(plain, cov, q, 1800, 12, 10.0, -8.0)
        ks, f, es = sharp_coverage_outcome(record, cov, q, 1800, 12, 10.0, -8.0)
        assert ks == ks1 and f == pytest.approx(1.0 - (1.0 - f1) ** eta, rel=1e-12)
        assert math.isfinite(es) and es > 0.0


def _monte_carlo(value, cases=3, runs=2000):
    mission = MissionSpec() if value == 1.0 else MissionSpec(detection_probability=value)
    config = ValidationConfig(cases=cases, runs=runs, seed=3, mission=mission)
    rows = []
    for i in range(cases):
        rows += case_rows(draw_case(i, config.seed), config)[0]
    return rows


def test_the_find_probability_agrees_with_the_monte_carlo_of_the_spiral():
    """Each case and delay: the sharp estimate within 0.03 of the simulated P_find; the paper's
    estimator (conservative by a few hundredths at Pd = 1 already, the paper's Table I) moves
    with Pd as the simulation does, within 0.03."""
    certain = _monte_carlo(1.0)
    for value in (0.9, 0.7, 0.5, TABLE):
        rows = _monte_carlo(value)
        for row, base in zip(rows, certain, strict=True):
            assert abs(row["sharp_p_find"] - row["emp_p_find"]) < 0.03, (value, row)
            moved = row["est_p_find"] - base["est_p_find"]
            simulated = row["emp_p_find"] - base["emp_p_find"]
            assert abs(moved - simulated) < 0.03, (value, row, base)
            assert row["t_cutoff"] == base["t_cutoff"]


def test_with_draws_held_over_a_pass_the_estimates_are_conservative_and_close():
    """Draws held over the pass (misses in runs): the share of covered targets one pass detects
    lowers both estimates as much as the simulation, within 0.1, never above it by more than
    0.02, and the paper's t_cutoff stays."""
    certain = _monte_carlo(1.0)
    mission = MissionSpec(detection_probability=0.7, detection_correlation_time=1000.0)
    config = ValidationConfig(cases=3, runs=2000, seed=3, mission=mission)
    rows = [row for i in range(3) for row in case_rows(draw_case(i, config.seed), config)[0]]
    for row, base in zip(rows, certain, strict=True):
        assert row["emp_p_find"] < base["emp_p_find"] - 0.05  # a pass misses with 0.3
        for column in ("sharp_p_find", "est_p_find"):
            error = row[column] - row["emp_p_find"]
            assert -0.1 < error < 0.02, (column, row)
        assert row["t_cutoff"] == base["t_cutoff"]
    assert config.identity()["detection_correlation_time"] == 1000.0


def test_the_identity_names_the_detection_probability_only_below_one():
    plain = ValidationConfig(cases=1, runs=10)
    assert "detection_probability" not in plain.identity()
    one = ValidationConfig(cases=1, runs=10, mission=MissionSpec(detection_probability=1.0))
    assert one.identity() == plain.identity()
    half = ValidationConfig(cases=1, runs=10, mission=MissionSpec(detection_probability=0.5))
    assert half.identity()["detection_probability"] == 0.5
    table = ValidationConfig(cases=1, runs=10, mission=MissionSpec(detection_probability=TABLE))
    assert table.identity()["detection_probability"] == [list(row) for row in TABLE]


def test_validate_coverage_runs_with_a_detector(cli, tmp_path):
    out = tmp_path / "pd"
    common = ["validate-coverage", "--cases", "2", "--runs", "300", "--delays", "0", "--seed", "4"]
    result = cli(*common, "--out", out, "--detection-probability", "0.7")
    assert result.code == 0, result.out + result.err
    assert json.loads((out / "config.json").read_text())["detection_probability"] == 0.7
    assert (out / "cases.csv").exists()
    table = tmp_path / "table"
    result = cli(*common, "--out", table, "--detection-table", "0:0.9,30:0.8,50:0.5")
    assert result.code == 0, result.out + result.err
    stored = json.loads((table / "config.json").read_text())["detection_probability"]
    assert stored == [list(row) for row in TABLE]
    for args, says in (
        (["--detection-probability", "1.5"], "--detection-probability"),
        (["--detection-table", "0:0.9,x"], "--detection-table"),
        (["--detection-table", "5:0.9"], "first distance"),
        (["--detection-probability", "0.5", "--detection-table", "0:0.9"], "not both"),
    ):
        result = cli(*common, "--out", tmp_path / "bad", *args)
        assert result.code == 2 and says in result.out + result.err, result.out + result.err
