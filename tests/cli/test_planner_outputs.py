"""Every planner that runs without a trained model writes strict, finite JSON at n = 20 and 40:
no NaN or Infinity token, and no non-finite number spelled as a string either (the JSON form of
one, :mod:`hptrack.jsonout`) outside the planner's settings, where ``"inf"`` means no limit."""

import json
import math

import numpy as np
import pytest

from hptrack.registry import PLANNERS
from hptrack.scenario import random_scenario, save_scenario

NEED_A_MODEL = {"adfq", "sb3"}  # policies trained for n <= 6 only
EFFORT = {
    "mcts": ["--iterations", "100"],
    "arvi": ["-o", "max_nodes_per_level=200"],
    "astar": ["-o", "max_expansions=200"],
    "coverage": ["-o", "target=t1"],
}
BUDGET_S = 30.0


def _strict(text: str):
    def refuse(token):
        raise AssertionError(f"JSON token {token}")

    return json.loads(text, parse_constant=refuse)


def _non_finite(value, where=""):
    """Where ``value`` holds a non-finite number or its JSON spelling (not in settings)."""
    if isinstance(value, dict):
        return [
            bad
            for k, v in value.items()
            if k != "settings"
            for bad in _non_finite(v, f"{where}.{k}")
        ]
    if isinstance(value, list):
        return [bad for i, v in enumerate(value) for bad in _non_finite(v, f"{where}[{i}]")]
    if isinstance(value, float) and not math.isfinite(value):
        return [where]
    if isinstance(value, str) and value in ("inf", "-inf", "nan"):
        return [where]
    return []


@pytest.fixture(scope="module")
def scenarios(tmp_path_factory):
    """Homogeneous random scenarios of 20 and 40 targets, 30 s (seed 1: the 20-target one sends
    the clairvoyant reference where no target can be met before the budget's end)."""
    out = {}
    for n in (20, 40):
        path = tmp_path_factory.mktemp("scenarios") / f"n{n}.yaml"
        scenario = random_scenario(n, seed=1, homogeneous=True)
        save_scenario(scenario.model_copy(update={"budget": BUDGET_S}), path)
        out[n] = path
    return out


def test_every_planner_but_the_learned_ones_is_tested():
    assert NEED_A_MODEL <= set(PLANNERS)
    assert set(EFFORT) <= set(PLANNERS) - NEED_A_MODEL


@pytest.mark.parametrize("n", [20, 40])
@pytest.mark.parametrize("planner", sorted(set(PLANNERS) - NEED_A_MODEL))
def test_the_json_summary_and_the_record_are_strict_and_finite(
    cli, scenarios, tmp_path, planner, n
):
    out, record = tmp_path / "out.json", tmp_path / "record.npz"
    args = ["simulate", scenarios[n], "--planner", planner, "--json", out, "--record", record]
    result = cli(*args, *EFFORT.get(planner, []))
    assert result.code == 0, result.out + result.err
    summary = _strict(out.read_text())
    assert summary["planner"] == planner and len(summary["per_target_logdet"]) == n
    assert _non_finite(summary) == []
    with np.load(record) as data:
        assert _non_finite(_strict(str(data["meta"]))) == []
