import json

import numpy as np
import pytest

from hptrack.scenario import random_scenario, save_scenario


def test_coverage_command_writes_a_plan_anyone_can_simulate(cli, tmp_path):
    path = tmp_path / "s.yaml"
    save_scenario(random_scenario(2, seed=8), path)
    result = cli(
        "coverage",
        path,
        "--target",
        "t2",
        "--delay",
        "100",
        "--json",
        tmp_path / "c.json",
        "--plot",
        tmp_path / "c.png",
    )
    assert result.code == 0, result.err
    assert "p_find" in result.out
    plan = json.loads((tmp_path / "c.json").read_text())
    for key in (
        "t_cutoff",
        "p_find",
        "expected_time",
        "intercept_time",
        "cdf",
        "positions",
        "belief_at_departure",
    ):
        assert key in plan
    n, k = plan["intercept_steps"], plan["cutoff_steps"]
    assert plan["intercept_time"] == n * 0.5 and plan["t_cutoff"] == k * 0.5
    positions = np.array(plan["positions"])
    assert positions.shape == (n + k + 1, 2) and len(plan["cdf"]) == k + 1
    np.testing.assert_array_equal(positions[0], [0.0, 0.0])
    assert plan["p_find"] == pytest.approx(plan["cdf"][-1], rel=1e-12)
    steps = np.hypot(*np.diff(positions, axis=0).T)
    np.testing.assert_allclose(steps[n:], 15.0, rtol=1e-6)
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"


def test_coverage_command_errors(cli, tmp_path):
    path = tmp_path / "s.yaml"
    save_scenario(random_scenario(1, seed=8), path)
    for args, needle in (
        (["--target", "nope"], "'nope' is not a target"),
        (["--target", "t1", "--delay", "0.2"], "whole number"),
        (["--target", "t1", "--delay", "900"], "no budget"),
    ):
        result = cli("coverage", path, *args)
        assert result.code == 2 and needle in result.err, result.err
        assert len(result.error_lines) == 1
