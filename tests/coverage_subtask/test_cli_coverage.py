import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from hptrack.cli.coverage import register
from hptrack.scenario import random_scenario, save_scenario

app = typer.Typer()
register(app)
runner = CliRunner()


def test_coverage_command_writes_a_plan_anyone_can_simulate(tmp_path):
    path = tmp_path / "s.yaml"
    save_scenario(random_scenario(2, seed=8), path)
    result = runner.invoke(app, ["coverage", str(path), "--target", "t2", "--delay", "100",
                                 "--json", str(tmp_path / "c.json"),
                                 "--plot", str(tmp_path / "c.png")])
    assert result.exit_code == 0, result.output
    assert "p_find" in result.output
    plan = json.loads((tmp_path / "c.json").read_text())
    for key in ("t_cutoff", "p_find", "expected_time", "intercept_time", "cdf", "positions",
                "belief_at_departure"):
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


def test_coverage_command_errors(tmp_path):
    path = tmp_path / "s.yaml"
    save_scenario(random_scenario(1, seed=8), path)
    result = runner.invoke(app, ["coverage", str(path), "--target", "nope"])
    assert result.exit_code == 2 and "unknown target" in result.output
    result = runner.invoke(app, ["coverage", str(path), "--target", "t1", "--delay", "0.2"])
    assert result.exit_code == 2 and "whole number" in result.output
    result = runner.invoke(app, ["coverage", str(path), "--target", "t1", "--delay", "900"])
    assert result.exit_code == 2 and "no budget" in result.output
