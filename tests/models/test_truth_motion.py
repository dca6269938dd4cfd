"""The simulator's truth motions against exact answers: a noise-free turn closes its circle,
the Ornstein-Uhlenbeck step equals Van Loan's matrix exponential, and the sampled statistics of
every model match their closed forms (fixed seeds, tolerances of a few standard errors)."""

import copy
import math

import numpy as np
import pytest
from scipy.linalg import expm

from hptrack.models.mission import mission_record
from hptrack.models.motion import ConstantVelocityModel
from hptrack.models.truth_motion import (
    ConstantVelocityTruth,
    CoordinatedTurn,
    OrnsteinUhlenbeck,
    RandomWalk,
    ou_step_factors,
    sample_truth,
    turn_step,
)
from hptrack.scenario import ScenarioError, parse_scenario
from hptrack.sim.episode import run_episode
from hptrack.sim.step import World

TAU = 0.5
MISSION = mission_record(TAU, 900.0, 30.0, 100.0, 10.0 * np.eye(2), np.full(1, 3e-4))


def run(model, start, q, steps, seed=0):
    """``steps`` steps of ``model`` from the rows of ``start``."""
    rng = np.random.default_rng(seed)
    states = np.array(start, dtype=float)
    q = np.full(states.shape[0], q)
    for _ in range(steps):
        states = sample_truth(model, MISSION, states, q, rng)
    return states


def test_a_noise_free_turn_closes_its_circle():
    """At ``omega = 2 pi / 200`` rad/s a target at 3 m/s flies a circle of radius
    ``3 / omega`` and is back where it started after 400 steps of 0.5 s."""
    omega = 2.0 * math.pi / 200.0
    start = np.array([[100.0, -50.0, 3.0, 0.0]])
    centre = start[0, :2] + np.array([0.0, 3.0 / omega])  # counter-clockwise: centre on the left
    states = start.copy()
    radii = []
    for _ in range(400):
        states = run(CoordinatedTurn(np.array([omega])), states, 0.0, 1)
        radii.append(np.hypot(*(states[0, :2] - centre)))
    np.testing.assert_allclose(states, start, atol=1e-9)
    np.testing.assert_allclose(radii, 3.0 / omega, rtol=1e-12)
    assert turn_step(0.0, 0.0, 3.0, 4.0, 0.0, TAU) == (1.5, 2.0, 3.0, 4.0)  # no turn: straight


def test_constant_velocity_truth_is_the_paper_sampler():
    """The default truth motion draws exactly what the constant-velocity model's sampler draws."""
    start = np.array([[0.0, 0.0, 1.0, -2.0], [50.0, 20.0, 0.0, 0.5]])
    q = np.array([3e-4, 1e-3])
    ours = sample_truth(ConstantVelocityTruth(), MISSION, start, q, np.random.default_rng(4))
    paper = ConstantVelocityModel(TAU).sample_motion(start, q, np.random.default_rng(4))
    np.testing.assert_array_equal(ours, paper)


def test_ornstein_uhlenbeck_step_is_van_loans_exponential():
    """The exact step of ``dx = v dt, dv = -K v dt + dW`` (per axis, ``q = 1``) from Van Loan's
    block matrix exponential: ``Phi`` and ``Q_d`` against the closed form."""
    for damping in (1e-3, 0.01, 0.3, 5.0):
        a = np.array([[0.0, 1.0], [0.0, -damping]])
        g = np.array([[0.0, 0.0], [0.0, 1.0]])
        block = np.block([[-a, g], [np.zeros((2, 2)), a.T]]) * TAU
        e = expm(block)
        phi = e[2:, 2:].T
        qd = phi @ e[:2, 2:]
        decay, gain, l11, l21, l22 = ou_step_factors(damping, TAU)
        np.testing.assert_allclose([phi[1, 1], phi[0, 1]], [decay, gain], rtol=1e-12)
        chol = np.array([[l11, 0.0], [l21, l22]])
        np.testing.assert_allclose(chol @ chol.T, qd, rtol=1e-7, atol=1e-16)
    # little damping: the constant-velocity blocks tau^3/3, tau^2/2, tau
    *_, l11, l21, l22 = ou_step_factors(1e-3, TAU)
    np.testing.assert_allclose(
        [l11**2, l11 * l21, l21**2 + l22**2], [TAU**3 / 3, TAU**2 / 2, TAU], rtol=2e-3
    )


def test_sampled_statistics_match_each_models_closed_form():
    """20,000 targets, 100 steps (50 s) from one state: the sample means and variances against
    the models' exact moments, within 4 standard errors."""
    n, steps, t = 20_000, 100, 100 * TAU
    start = np.tile([10.0, -20.0, 2.0, 1.0], (n, 1))
    se = 4.0 / math.sqrt(n)

    walk = run(RandomWalk(5.0), start, 3e-4, steps, seed=1)
    np.testing.assert_allclose(walk[:, :2].mean(axis=0), start[0, :2], atol=se * math.sqrt(5 * t))
    np.testing.assert_allclose(walk[:, :2].var(axis=0), 5.0 * t, rtol=3 * se * math.sqrt(2))
    assert np.all(walk[:, 2:] == 0.0)

    damping, q = 0.05, 0.01
    ou = run(OrnsteinUhlenbeck(damping), start, q, steps, seed=2)
    decay = math.exp(-damping * t)
    velocity_var = q * (1.0 - decay**2) / (2.0 * damping)
    mean_x = start[0, 0] + start[0, 2] * (1.0 - decay) / damping
    assert abs(ou[:, 2].mean() - start[0, 2] * decay) < se * math.sqrt(velocity_var)
    assert abs(ou[:, 0].mean() - mean_x) < se * ou[:, 0].std()
    assert ou[:, 2].var() == pytest.approx(velocity_var, rel=3 * se * math.sqrt(2))

    omega = 0.05
    turn = run(CoordinatedTurn(np.full(n, omega)), start, 0.0, steps)
    x, y, vx, vy = start[0]
    for _ in range(steps):
        x, y, vx, vy = turn_step(x, y, vx, vy, omega, TAU)
    np.testing.assert_allclose(turn[0], [x, y, vx, vy], rtol=1e-12)
    noisy = run(CoordinatedTurn(np.full(n, omega)), start, 3e-4, steps, seed=3)
    spread = noisy[:, :2].std(axis=0)
    np.testing.assert_allclose(noisy[:, :2].mean(axis=0), [x, y], atol=float(se * spread.max()))


SCENARIO = {
    "seed": 3,
    "agent": {"position": [0.0, 0.0], "speed": 30.0, "sensor_diameter": 100.0},
    "targets": [
        {
            "id": f"t{i}",
            "mean": [300.0 * i, -200.0, 1.0, 0.5],
            "covariance": [[900, 0, 0, 0], [0, 900, 0, 0], [0, 0, 0.3, 0], [0, 0, 0, 0.3]],
            "process_noise": 3e-4,
        }
        for i in range(3)
    ],
}


def test_a_scenario_says_how_its_targets_truly_move():
    """``truth_motion`` picks the simulator's truth (default the paper's), random turn rates
    are drawn once per target after the initial states, and the beliefs are unchanged."""
    default = World(parse_scenario(SCENARIO))
    assert default.truth_motion == ConstantVelocityTruth()
    spread = {"model": "coordinated_turn", "turn_rate": 0.02, "turn_rate_sd": 0.01}
    turning = World(parse_scenario({**SCENARIO, "truth_motion": spread}))
    np.testing.assert_array_equal(turning.truth, default.truth)
    rates = turning.truth_motion.rates
    assert rates.shape == (3,) and len(set(rates)) == 3 and np.all(np.abs(rates - 0.02) < 0.05)
    known = World(parse_scenario({**SCENARIO, "truth_motion": {"model": "coordinated_turn"}}))
    np.testing.assert_array_equal(known.truth_motion.rates, 0.02)
    for world in (default, turning):
        for _ in range(40):
            world.step(0.0, 0.0)
    assert not np.allclose(turning.truth, default.truth)
    np.testing.assert_array_equal(turning.means, default.means)  # nothing measured: priors
    walk = parse_scenario({**SCENARIO, "truth_motion": {"model": "random_walk"}})
    assert run_episode(walk, _greedy()).uncertainty > 0.0


def _greedy():
    from hptrack.registry import make_planner

    return make_planner("greedy")


@pytest.mark.parametrize(
    ("truth_motion", "shown"),
    [
        (
            {"model": "coordinated_turn", "turn_rate": 5.0},
            "truth_motion.coordinated_turn.turn_rate",
        ),
        ({"model": "random_walk", "diffusion": -1.0}, "truth_motion.random_walk.diffusion"),
        (
            {"model": "ornstein_uhlenbeck", "damping": 0.0},
            "truth_motion.ornstein_uhlenbeck.damping",
        ),
        ({"model": "jerky"}, "truth_motion"),
        ({"model": "random_walk", "sigma": 1.0}, "sigma"),
    ],
)
def test_a_bad_truth_motion_is_named_in_one_line(truth_motion, shown):
    data = copy.deepcopy(SCENARIO)
    data["truth_motion"] = truth_motion
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data)
    message = str(info.value)
    assert "\n" not in message and "truth_motion" in message and shown in message
