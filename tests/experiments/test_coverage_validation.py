import csv
import json
import math

import numpy as np
import pytest

from hptrack.experiments.coverage_validation import (
    CASES_FILE,
    ValidationConfig,
    draw_case,
    first_detections,
    plan_coverage,
    read_rows,
    run_validation,
    summarise,
)
from hptrack.interface import MissionSpec
from hptrack.models.truth_motion import ConstantVelocityTruth, sample_truth


def test_command_runs_end_to_end_and_resumes(cli, tmp_path):
    out = tmp_path / "val"
    args = [
        "validate-coverage",
        "--cases",
        "3",
        "--runs",
        "300",
        "--delays",
        "0,100",
        "--seed",
        "5",
        "--out",
        str(out),
        "--json",
        str(tmp_path / "mape.json"),
    ]
    result = cli(*args)
    assert result.code == 0, result.out + result.err
    assert "MAPE" in result.out and "3.58" in result.out  # the paper's figure alongside
    mape = json.loads((tmp_path / "mape.json").read_text())
    assert set(mape) == {"0", "100"}
    for values in mape.values():
        assert set(values) == {"mape_p_find", "mape_expected_time"}
        assert all(math.isfinite(v) and v >= 0 for v in values.values())
    assert (out / "cdf-case-0.png").read_bytes()[:4] == b"\x89PNG"
    assert "| 100 | 3 |" in (out / "mape.md").read_text()
    first = read_rows(out / CASES_FILE)
    assert sorted((r["case"], r["delay"]) for r in first) == [
        (c, d) for c in range(3) for d in (0.0, 100.0)
    ]
    # Resume with more cases: the three done are kept as they are, one case is added.
    result = cli(*args[:2] + ["4"] + args[3:])
    assert result.code == 0, result.out + result.err
    rows = read_rows(out / CASES_FILE)
    assert len(rows) == 8 and rows[:6] == first
    # Another configuration in the same folder is refused.
    result = cli(*args[:4] + ["301"] + args[5:])
    assert result.code == 2 and "another configuration" in (result.out + result.err)


def test_bad_options_exit_with_one_line(cli, tmp_path):
    result = cli(*["validate-coverage", "--delays", "0,0.3", "--out", str(tmp_path)])
    assert result.code == 2 and "whole number" in (result.out + result.err)
    result = cli(*["validate-coverage", "--delays", "a,b", "--out", str(tmp_path)])
    assert result.code == 2 and "--delays" in (result.out + result.err)


def test_rows_do_not_depend_on_workers_or_order(tmp_path):
    config = ValidationConfig(cases=3, runs=200, delays=(0.0, 200.0), seed=9)
    one = run_validation(config, tmp_path / "one", workers=1)
    two = run_validation(config, tmp_path / "two", workers=2)
    assert one == two
    with (tmp_path / "one" / CASES_FILE).open() as f:
        assert len(list(csv.DictReader(f))) == 6


def test_detection_in_the_intercept_flight_counts_at_coverage_time_zero():
    settings = MissionSpec()
    case = draw_case(0, 0)
    plan = plan_coverage(case, 0, settings)
    n = plan.intercept_steps
    first_any, first_spiral = first_detections(
        plan, case.q, settings, 3000, np.random.default_rng(1)
    )
    in_flight = (first_any >= 0) & (first_any < n)
    assert in_flight.mean() > 0.3  # the flight ends on the belief mean
    # a run found in flight is followed on to its first detection on the spiral
    assert np.all((first_spiral[in_flight] >= n) | (first_spiral[in_flight] == -1))
    assert np.all(
        first_spiral[~in_flight & (first_any >= 0)] == first_any[~in_flight & (first_any >= 0)]
    )
    assert first_any.max() <= n + plan.estimate.cutoff_steps


def test_simulated_detections_match_an_independent_step_by_step_simulation():
    settings = MissionSpec()
    case = draw_case(3, 0)
    plan = plan_coverage(case, 100 * 2, settings)
    first_any, _ = first_detections(plan, case.q, settings, 4000, np.random.default_rng(2))
    # Reference: the simulator's sampler, one step at a time, 4000 runs at once.
    rng = np.random.default_rng(3)
    states = rng.multivariate_normal(plan.mean, plan.covariance, size=4000)
    found = np.zeros(4000, dtype=bool)
    for j in range(plan.path.shape[0]):
        if j:
            states = sample_truth(
                ConstantVelocityTruth(), settings.record, states, np.full(4000, case.q), rng
            )
        found |= np.hypot(*(states[:, :2] - plan.path[j]).T) <= 50.0
    assert np.mean(first_any >= 0) == pytest.approx(found.mean(), abs=0.03)


def test_mape_is_mean_absolute_percentage_error_against_the_empirical_value():
    rows = [
        dict(
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
        ),
        dict(
            delay=0.0,
            est_p_find=0.6,
            emp_p_find=0.5,
            est_expected_time=3.0,
            emp_expected_time=0.0,
            emp_p_find_spiral_only=0.5,
            emp_expected_time_spiral_only=math.nan,
            est_time_from_departure=10.0,
            emp_time_from_departure=10.0,
            emp_found_in_flight=0.1,
        ),
    ]
    s = summarise(rows, [0.0])["0"]
    assert s["mape_p_find"] == pytest.approx((10.0 + 20.0) / 2)
    assert s["mape_expected_time"] == pytest.approx(50.0)  # emp = 0 is left out
    assert s["mape_time_from_departure"] == pytest.approx(12.5)


def test_the_terminal_table_names_the_papers_published_table(capsys, monkeypatch):
    from hptrack.cli import coverage as coverage_cli
    from hptrack.cli.common import console

    monkeypatch.setattr(console, "width", 300)  # no header wraps
    cells = ("mape_p_find", "sharp_mape_p_find", "mape_expected_time", "sharp_mape_expected_time")
    summary = {
        "0": {"cases": 3, **dict(zip(cells, (1.0, 2.0, 4.0, 5.0), strict=True))},
        "300": {"cases": 3, **dict(zip(cells, (1.5, 2.5, 4.5, 5.5), strict=True))},
    }
    capsys.readouterr()
    coverage_cli._print_table(summary, 12.0)
    lines = capsys.readouterr().out.splitlines()
    header = next(line for line in lines if "t_d (s)" in line)
    columns = [c.strip() for c in header.strip("┃ ").split("┃")]
    # each estimate, then the paper's own numbers, named so that neither reads as the other
    assert columns[2::3] == ["P_find: paper's estimator", "E[T_find]: paper's estimator"]
    assert columns[4::3] == ["paper's Table I (published)"] * 2
    assert "paper" not in columns
    rows = [[c.strip() for c in line.strip("│ ").split("│")] for line in lines if "│" in line]
    # the paper's Table I at t_d = 0 (3.58 %, 5.18 %); it has no 300 s row
    assert rows == [
        ["0", "3", "1.00", "2.00", "3.58", "4.00", "5.00", "5.18"],
        ["300", "3", "1.50", "2.50", "-", "4.50", "5.50", "-"],
    ]


def test_an_accelerating_motion_runs_with_its_parameters_in_the_identity(cli, tmp_path):
    out = tmp_path / "singer"
    args = ["validate-coverage", "--cases", "2", "--runs", "100", "--delays", "0,100"]
    args += ["--motion", "singer", "--damping", "0.05", "--acceleration-std", "0.003"]
    result = cli(*args, "--budget", "600", "--out", str(out))
    assert result.code == 0, result.out + result.err
    config = json.loads((out / "config.json").read_text())
    assert config["motion"] == {"model": "singer", "damping": 0.05, "acceleration_std": 0.003}


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        (["--motion", "singer"], "needs a --budget"),
        (["--motion", "singer", "--diffusion", "5", "--budget", "900"], "--diffusion is not"),
        (["--damping", "0.1"], "--damping is not a parameter of --motion constant_velocity"),
        (["--motion", "singer", "--damping", "-1", "--budget", "900"], "--damping:"),
        (
            ["--motion", "constant_acceleration", "--jerk-intensity", "2", "--budget", "900"],
            "--jerk-intensity:",
        ),
    ],
)
def test_bad_motion_options_exit_with_one_line(cli, tmp_path, extra, said):
    result = cli(*["validate-coverage", "--cases", "2", "--out", str(tmp_path / "x"), *extra])
    text = (result.out + result.err).strip()
    assert result.code == 2 and said in text and "\n" not in text, text
