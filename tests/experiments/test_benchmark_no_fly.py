"""``hptrack benchmark --no-fly``: the setting names it, every scenario gets random circles of
the protocol that leave the start free and the targets in sight, the open-space scenarios are
those of the plain setting, and the episodes keep out of the circles."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.experiments.benchmark import BenchmarkConfig, run_one, scenario_for
from hptrack.experiments.store import EpisodeKey
from hptrack.registry import planner_settings
from hptrack.scenario.random import NO_FLY_CIRCLES, NO_FLY_SHARE, POSITION_RANGE_M, random_scenario


def _config(no_fly: bool) -> BenchmarkConfig:
    return BenchmarkConfig(
        ("greedy",), {"greedy": planner_settings("greedy")}, (6,), 3, no_fly=no_fly
    )


def test_the_setting_names_the_fence_and_keeps_the_scenarios():
    fenced, plain = _config(True), _config(False)
    assert fenced.setting == "homogeneous+nofly" and plain.setting == "homogeneous"
    area = (POSITION_RANGE_M[1] - POSITION_RANGE_M[0]) ** 2
    for a, b in zip(fenced.keys(), plain.keys(), strict=True):
        with_fence, without = scenario_for(a), scenario_for(b)
        assert with_fence.targets == without.targets and without.fence is None
        circles = [z.circle for z in with_fence.fence.exclusions]
        assert NO_FLY_CIRCLES[0] <= len(circles) <= NO_FLY_CIRCLES[1]
        share = sum(math.pi * r * r for _, _, r in circles) / area
        assert NO_FLY_SHARE[0] <= share <= NO_FLY_SHARE[1]
    assert scenario_for(fenced.keys()[0]).fence == scenario_for(fenced.keys()[0]).fence


def test_a_fenced_episode_keeps_out_of_its_circles():
    key = EpisodeKey("greedy", 6, 1, "homogeneous+nofly", planner_settings("greedy").canonical())
    scenario = scenario_for(key)
    row = run_one(key)
    assert np.isfinite(row.uncertainty)
    from hptrack.registry import make_planner
    from hptrack.sim.episode import run_episode

    path = run_episode(scenario, make_planner("greedy"), seed=key.seed).agent_path
    for x, y, r in (z.circle for z in scenario.fence.exclusions):
        assert np.hypot(path[:, 0] - x, path[:, 1] - y).min() >= r + 10.0 - 1e-6


def test_no_fly_circles_are_refused_when_none_fit(monkeypatch):
    import hptrack.scenario.random as protocol

    assert protocol.with_no_fly(random_scenario(2, seed=0), 0).fence is not None
    monkeypatch.setattr(protocol, "NO_FLY_ATTEMPTS", 0)
    with pytest.raises(ValueError, match="no no-fly circles"):
        protocol.with_no_fly(random_scenario(2, seed=0), 0)
