"""The probability that a straight flight measures a target it passes over, against exact
cases and a Monte Carlo sweep."""

import math

import numpy as np
import pytest

from hptrack.coverage.passes import pass_probability

RADIUS = 10.0


def test_a_certain_target_on_the_path_or_off_it():
    # the agent starts 50 m west of the mean and flies 100 m east: the mean is on the path
    assert pass_probability(-50.0, 0.0, 1.0, 0.0, 100.0, 0.0, 0.0, 0.0, RADIUS) == 1.0
    # ... or passes 11 m north of it, or stops 11 m short of it
    assert pass_probability(-50.0, 11.0, 1.0, 0.0, 100.0, 0.0, 0.0, 0.0, RADIUS) == 0.0
    assert pass_probability(-50.0, 0.0, 1.0, 0.0, 39.0, 0.0, 0.0, 0.0, RADIUS) == 0.0


@pytest.mark.parametrize("angle", [0.0, 0.7, 2.0])
def test_a_long_pass_through_an_isotropic_belief_is_the_strip_probability(angle):
    """Through the mean, far past both ends: P(|N(0, s^2)| <= r) = erf(r / (s sqrt 2)),
    whatever the direction."""
    d = np.array([math.cos(angle), math.sin(angle)])
    start = -1000.0 * d
    p = pass_probability(*start, *d, 2000.0, 64.0, 0.0, 64.0, RADIUS)
    assert p == pytest.approx(math.erf(RADIUS / (8.0 * math.sqrt(2.0))), rel=1e-12)


def test_the_spread_across_the_path_is_what_counts():
    """A belief long in x and narrow in y: a pass along x finds it surely, one along y rarely."""
    along_x = pass_probability(-5000.0, 0.0, 1.0, 0.0, 10000.0, 400.0**2, 0.0, 1.0, RADIUS)
    along_y = pass_probability(0.0, -5000.0, 0.0, 1.0, 10000.0, 400.0**2, 0.0, 1.0, RADIUS)
    assert along_x == pytest.approx(1.0, abs=1e-12)
    assert along_y == pytest.approx(math.erf(RADIUS / (400.0 * math.sqrt(2.0))), rel=1e-12)


def test_against_a_monte_carlo_sweep():
    """Targets drawn from a correlated belief; measured when their distance to the flown
    segment is at most the radius. The closed form leaves out the correlation of the two
    offsets and squares the ends; with the segment's ends far out in the belief's tails it
    agrees within the sampling error."""
    rng = np.random.default_rng(3)
    cov = np.array([[60.0, 25.0], [25.0, 40.0]])
    start, d, length = np.array([-80.0, 4.0]), np.array([1.0, 0.0]), 160.0
    truth = rng.multivariate_normal(np.zeros(2), cov, 200_000)
    # closest point of the segment to each target
    s = np.clip((truth - start) @ d, 0.0, length)
    distance = np.linalg.norm(start + s[:, None] * d - truth, axis=1)
    simulated = np.mean(distance <= RADIUS)
    p = pass_probability(*start, *d, length, cov[0, 0], cov[0, 1], cov[1, 1], RADIUS)
    assert p == pytest.approx(simulated, abs=0.005)
