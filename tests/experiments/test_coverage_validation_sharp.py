import json
import math

import pytest

from hptrack.experiments.coverage_validation import CASES_FILE, read_rows, summarise


def test_one_run_reports_both_estimators_on_the_same_runs(cli, tmp_path):
    out = tmp_path / "val"
    result = cli(
        "validate-coverage", "--cases", "2", "--runs", "200", "--delays", "0,200", "--out", out
    )
    assert result.code == 0, result.out + result.err
    assert "sharp" in result.out and "3.58" in result.out
    both = json.loads((out / "mape-both.json").read_text())
    assert set(both) == {"paper", "sharp"}
    for estimator in both.values():
        assert set(estimator) == {"0", "200"}
        for values in estimator.values():
            assert set(values) == {"mape_p_find", "mape_expected_time"}
            assert all(math.isfinite(v) and v >= 0 for v in values.values())
    table = (out / "mape.md").read_text()
    assert "sharp" in table and "| 200 | 2 |" in table
    rows = read_rows(out / CASES_FILE)
    for r in rows:
        assert 0.0 < r["sharp_p_find"] <= 1.0
        # the sharp time is a duration from departure: at least the flight when found in it
        assert r["sharp_expected_time"] > 0.0
    summary = summarise(rows, (0.0, 200.0))
    assert summary["200"]["sharp_mape_p_find"] == pytest.approx(
        100
        * sum(
            abs(r["sharp_p_find"] - r["emp_p_find"]) / r["emp_p_find"]
            for r in rows
            if r["delay"] == 200.0
        )
        / 2
    )


def test_the_sharp_time_is_scored_against_the_time_from_departure():
    base = dict(
        delay=0.0,
        est_p_find=0.9,
        emp_p_find=1.0,
        est_expected_time=2.0,
        emp_expected_time=4.0,
        emp_p_find_spiral_only=1.0,
        emp_expected_time_spiral_only=4.0,
        est_time_from_departure=10.0,
        emp_time_from_departure=8.0,
        emp_found_in_flight=0.5,
    )
    rows = [
        dict(base, sharp_p_find=0.95, sharp_expected_time=10.0),
        dict(base, sharp_p_find=1.0, sharp_expected_time=8.0),
    ]
    s = summarise(rows, [0.0])["0"]
    assert s["sharp_mape_p_find"] == pytest.approx(2.5)
    assert s["sharp_mape_expected_time"] == pytest.approx(12.5)
    assert s["mean_emp_time_from_departure"] == pytest.approx(8.0)
    # rows without the sharp columns give NaN for its figures, the paper's are unchanged
    old = summarise([base], [0.0])["0"]
    assert math.isnan(old["sharp_mape_p_find"]) and old["mape_p_find"] == pytest.approx(10.0)
