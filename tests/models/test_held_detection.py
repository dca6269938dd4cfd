"""Detection draws held over consecutive looks (``sensor.detection_correlation_time``): the
looks one draw serves, the pass factor they give, a simulator and a detector whose misses come
in runs at the rate ``Pd`` says, the same streams as independent looks, one-line errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hptrack.baselines.greedy import GreedyPlanner
from hptrack.models.detector import Detector
from hptrack.models.sensor import (
    detecting_sensor,
    detection_table,
    hold_looks_of,
    pass_detection_factor,
    pass_probability,
    repeat_pass_share,
)
from hptrack.scenario import parse_scenario, random_scenario
from hptrack.scenario.io import ScenarioError, file_data
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World


def test_a_draw_serves_the_looks_within_the_correlation_time():
    assert hold_looks_of(0.0, 0.5) == 1
    assert hold_looks_of(0.3, 0.5) == 1
    assert hold_looks_of(0.5, 0.5) == 1
    assert hold_looks_of(2.0, 0.5) == 4
    assert hold_looks_of(2.1, 0.5) == 5
    assert hold_looks_of(1000.0, 0.5) == 2000


def test_a_draw_held_over_the_pass_detects_a_pass_with_pd_itself():
    table = detection_table(0.7)
    assert pass_detection_factor(*table, 100.0, 15.0, 2000) == pytest.approx(0.7, abs=1e-12)
    # held for part of a pass: between one draw and independent looks
    held = pass_detection_factor(*table, 100.0, 15.0, 4)
    assert 0.7 < held < pass_detection_factor(*table, 100.0, 15.0)
    # a range table: the pass detects when its draw lies below the largest Pd it meets
    offsets = np.array([0.0, 30.0])
    rows = detection_table([[0.0, 0.9], [20.0, 0.9], [50.0, 0.5]])
    p = pass_probability(*rows, 50.0, 15.0, offsets, 2000)
    assert p[0] == pytest.approx(0.9)
    closest = np.linspace(0.0, 7.5, 100_001)  # the nearest look, uniform within half a step
    nearest = np.interp(np.hypot(closest, 30.0), [0.0, 20.0, 50.0], [0.9, 0.9, 0.5])
    assert p[1] == pytest.approx(float(np.mean(nearest)), abs=1e-4)


def _belief(a: float, b: float, correlation: float = 0.0, velocity: float = 0.0) -> np.ndarray:
    """A belief of position axes ``a, b`` (sd, m) along x and y, velocity sd ``velocity`` (m/s)
    correlated with the position by ``correlation``."""
    cov = np.diag([a * a, b * b, velocity**2, velocity**2])
    cov[0, 2] = cov[2, 0] = correlation * a * velocity
    cov[1, 3] = cov[3, 1] = correlation * b * velocity
    return cov


def test_the_spiral_passes_a_still_round_belief_once_and_an_elongated_one_more():
    assert repeat_pass_share(0.7, _belief(200.0, 200.0), 30.0, 100.0) == pytest.approx(0.7)
    assert repeat_pass_share(1.0, _belief(400.0, 100.0), 30.0, 100.0) == pytest.approx(1.0)
    shares = [repeat_pass_share(0.7, _belief(r * 100.0, 100.0), 30.0, 100.0) for r in (1, 2, 4)]
    assert shares[0] < shares[1] < shares[2]
    # axis ratio 2: a point lies under m = sqrt(cos^2 + 4 sin^2) passes, the mean by quadrature
    theta = np.linspace(0.0, math.pi, 400_001)
    m = np.sqrt(1.0 + 3.0 * np.sin(theta) ** 2)
    whole = np.floor(m)
    exact = np.mean(1.0 - 0.3**whole * (1.0 - (m - whole) * 0.7))
    assert shares[1] == pytest.approx(exact, abs=5e-3)


def test_targets_drifting_outwards_stay_under_the_front_for_more_passes():
    still = repeat_pass_share(0.7, _belief(300.0, 300.0), 30.0, 100.0)
    outwards = repeat_pass_share(0.7, _belief(300.0, 300.0, 0.99, 3.0), 30.0, 100.0)
    inwards = repeat_pass_share(0.7, _belief(300.0, 300.0, -0.99, 3.0), 30.0, 100.0)
    assert inwards < still < outwards < 1.0


def _still(hold_s: float, pd: float = 0.6, n: int = 12, seed: int = 5) -> dict:
    """Still targets (no velocity, no noise) around the origin, the agent hovering there."""
    rng = np.random.default_rng(seed)
    points = rng.uniform(-30.0, 30.0, (n, 2))
    cov = np.diag([1.0, 1.0, 1e-6, 1e-6]).tolist()
    targets = [
        {"id": f"t{i}", "mean": [float(x), float(y), 0.0, 0.0], "covariance": cov,
         "process_noise": 0.0,
         "truth": [float(x), float(y), 0.0, 0.0]}
        for i, (x, y) in enumerate(points)
    ]  # fmt: skip
    sensor = {"detection_probability": pd}
    if hold_s:
        sensor["detection_correlation_time"] = hold_s
    return {"budget": 200.0, "seed": seed, "targets": targets, "sensor": sensor}


def test_a_hovering_look_sees_each_target_in_runs_of_the_hold_and_at_the_rate_pd():
    world = World(parse_scenario(_still(2.0)))
    assert world.mission.record.sensor.hold_looks == 4
    seen = [world.seen.copy()]
    while not world.done:
        world.step(0.0, 0.0)
        seen.append(world.seen.copy())
    seen = np.array(seen[: 4 * (len(seen) // 4)])
    blocks = seen.reshape(-1, 4, seen.shape[1])
    assert np.all(blocks == blocks[:, :1, :])  # one draw for four looks
    rate, count = float(blocks[:, 0, :].mean()), blocks[:, 0, :].size
    assert abs(rate - 0.6) < 4.0 * math.sqrt(0.24 / count), (rate, count)


def test_the_detector_without_identity_holds_its_draws_the_same_way():
    sensor = detecting_sensor(100.0, np.eye(2), 0.6, 15.0, hold_looks=3)
    detector = Detector(sensor, np.eye(2), 0.0, np.random.default_rng(2))
    positions = np.random.default_rng(3).uniform(-20.0, 20.0, (10, 2))
    looks = []
    for _ in range(300):
        found = np.zeros(10, dtype=bool)
        found[detector.look(np.zeros(2), positions).sources] = True
        looks.append(found)
    blocks = np.array(looks).reshape(100, 3, 10)
    assert np.all(blocks == blocks[:, :1, :])
    rate = float(blocks[:, 0, :].mean())
    assert abs(rate - 0.6) < 4.0 * math.sqrt(0.24 / 1000.0)
    # a target that leaves the footprint draws afresh on its return
    far = positions + 500.0
    detector.look(np.zeros(2), positions[:1])
    before = detector._held.copy()
    detector.look(np.zeros(2), far[:1])
    assert detector._held[0, 1] == 0.0 and before[0, 1] == 1.0


def test_held_draws_take_the_same_streams_as_independent_looks():
    base = file_data(random_scenario(4, seed=3, budget=120.0))
    independent = parse_scenario(base | {"sensor": {"detection_probability": 0.7}})
    held = parse_scenario(
        base | {"sensor": {"detection_probability": 0.7, "detection_correlation_time": 5.0}}
    )
    a = run_episode(independent, GreedyPlanner(), seed=3)
    b = run_episode(held, GreedyPlanner(), seed=3)
    np.testing.assert_array_equal(a.true_states[0], b.true_states[0])
    assert file_data(held)["sensor"]["detection_correlation_time"] == 5.0
    assert "detection_correlation_time" not in file_data(independent)["sensor"]


@pytest.mark.parametrize(
    ("sensor", "says"),
    [
        ({"detection_correlation_time": 2.0}, "needs a detection_probability below 1"),
        (
            {"detection_probability": 0.7, "detection_correlation_time": 2.0,
             "negative_information": True},
            "negative_information needs detection_correlation_time 0",
        ),
        ({"detection_probability": 0.7, "detection_correlation_time": -1.0}, "greater than"),
    ],
)  # fmt: skip
def test_a_bad_correlation_is_one_line_naming_the_field(sensor, says):
    data = file_data(random_scenario(2, seed=1, budget=60.0)) | {"sensor": sensor}
    with pytest.raises(ScenarioError, match=says) as err:
        parse_scenario(data)
    assert "\n" not in str(err.value)
