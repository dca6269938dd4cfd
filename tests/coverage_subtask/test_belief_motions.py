"""The coverage sub-task under beliefs that do not move at constant velocity: the intercept meets
the predicted mean's path, the spiral follows the predicted mean, the estimator grows the
model's covariance and, under random walk and Ornstein-Uhlenbeck, its ``p_max`` stays below its
limit ``1 - exp(-v_a w / (2 pi D))``; a Monte Carlo of the sub-task agrees with the estimate."""

import math
from dataclasses import replace

import numpy as np
import pytest

from hptrack.coverage.estimator import estimate_coverage
from hptrack.coverage.subtask import CoverageSubtask
from hptrack.experiments.coverage_validation import ValidationConfig, case_rows, draw_case
from hptrack.interface import MissionSpec
from hptrack.models.belief_motion import (
    ConstantAccelerationMotion,
    OrnsteinUhlenbeckMotion,
    RandomWalkMotion,
    SingerMotion,
    extended_prior,
)
from hptrack.scenario.model import (
    ConstantAccelerationSpec,
    OrnsteinUhlenbeckSpec,
    RandomWalkSpec,
    SingerSpec,
)

TAU, SPEED, W = 0.5, 30.0, 100.0
MEAN = np.array([700.0, -400.0, 12.0, 9.0])
COV = np.diag([1500.0, 900.0, 0.4, 0.3])
COV[0, 1] = COV[1, 0] = 400.0
MOTIONS = [
    OrnsteinUhlenbeckMotion(0.02),
    RandomWalkMotion(20.0),
    SingerMotion(0.05, 0.05),
    ConstantAccelerationMotion(1e-6, 0.01),
]


def mission(motion) -> MissionSpec:
    return MissionSpec(process_noise=np.array([3e-3]), target_ids=("a",), belief_motion=motion)


def prior(motion):
    """`MEAN`, `COV` as a state of ``motion`` (with a small acceleration under a 6-D one, so
    that the mean path curves)."""
    mean, cov = extended_prior(motion, MEAN, COV)
    if mean.shape[0] == 6:
        mean = mean.copy()
        mean[4:] = [0.03, -0.02]
    return mean, cov


@pytest.mark.parametrize("motion", MOTIONS)
def test_the_intercept_meets_the_predicted_mean(motion):
    """At the exact intercept time the agent, flying straight at ``v_a``, is where the predicted
    mean is; the flight's end is the mean after the whole steps."""
    spec = mission(motion)
    mean, cov = prior(motion)
    subtask = CoverageSubtask(np.zeros(2), mean, cov, 3e-3, spec, 900.0)
    t = subtask.intercept.time
    reached = spec.motion.mean_positions(mean, [t])[0]
    assert np.hypot(*reached) == pytest.approx(SPEED * t, rel=1e-12)
    n = subtask.intercept.steps
    assert n == math.ceil(t / TAU - 1e-9)
    np.testing.assert_array_equal(
        subtask.intercept.start, spec.motion.mean_positions(mean, [n * TAU])[0]
    )
    straight = CoverageSubtask(
        np.zeros(2),
        MEAN,
        COV,
        3e-3,
        MissionSpec(process_noise=np.array([3e-3]), target_ids=("a",)),
        900.0,
    )
    if isinstance(motion, OrnsteinUhlenbeckMotion):  # a decaying velocity is met sooner
        assert t < straight.intercept.time


@pytest.mark.parametrize("motion", MOTIONS)
def test_the_spiral_follows_the_predicted_mean(motion):
    """Every spiral step is ``v_a tau`` long, and the spiral less the predicted mean's path is
    Eq. (3)'s spiral in the start ellipse's frame (``r = b theta``)."""
    spec = mission(motion)
    mean, cov = prior(motion)
    subtask = CoverageSubtask(np.zeros(2), mean, cov, 3e-3, spec, 900.0)
    spiral, n = subtask.spiral, subtask.intercept.steps
    k = np.arange(600)
    path = spiral.positions(600)
    np.testing.assert_allclose(np.hypot(*np.diff(path, axis=0).T), SPEED * TAU, rtol=1e-6)
    mean_path = spec.motion.mean_positions(mean, (n + k) * TAU)
    frame = (path - mean_path) @ spiral.rotation
    theta = spiral.phases(600)
    r = spiral.pitch * theta
    np.testing.assert_allclose(frame[:, 0], r * spiral.semi_a * np.cos(theta), atol=1e-6)
    np.testing.assert_allclose(frame[:, 1], r * spiral.semi_b * np.sin(theta), atol=1e-6)
    for j in (0, 7, 599):
        np.testing.assert_allclose(spiral.position(j), path[j], rtol=0, atol=1e-9)


def test_under_a_random_walk_p_max_stays_below_its_limit():
    """``S_cover / sqrt(det)`` rises towards ``v_a w / D``: no ``t_cutoff`` comes before the
    budget, and ``P_cdf`` stays below ``1 - exp(-v_a w / (2 pi D))`` and approaches it."""
    diffusion = 2000.0
    spec = mission(RandomWalkMotion(diffusion))
    limit = -math.expm1(-SPEED * W / (2.0 * math.pi * diffusion))
    wide = np.diag([1e6, 8e5, 1.0, 1.0])  # S_cover / sqrt(det) starts below its limit
    estimate = estimate_coverage(wide, 3e-3, spec, 200_000.0)
    assert estimate.budget_limited
    assert np.all(np.diff(estimate.cdf) > 0.0)
    assert estimate.p_find < limit
    assert estimate.p_find == pytest.approx(limit, rel=2e-3)
    with pytest.raises(ValueError, match="does not grow"):
        estimate_coverage(wide, 3e-3, spec, None)


@pytest.mark.parametrize(
    "motion",
    [
        OrnsteinUhlenbeckSpec(model="ornstein_uhlenbeck"),
        RandomWalkSpec(model="random_walk"),
        SingerSpec(model="singer"),
        ConstantAccelerationSpec(model="constant_acceleration"),
    ],
)
def test_the_estimate_agrees_with_simulated_trajectories_of_the_same_model(motion):
    """Three random cases, 2000 runs each, truth moving by the beliefs' own model: the estimate
    of ``P_find`` within 0.03 of the simulated one; the paper's estimator under random walk and
    Ornstein-Uhlenbeck, the sharp one under the accelerating models, whose fast-growing
    variance the paper's underestimates by 0.05 to 0.15 (the full experiment:
    docs/results/coverage-validation-motions)."""
    config = ValidationConfig(cases=3, runs=2000, seed=11, motion=motion, budget=900.0)
    assert config.mission.record.motion == motion.belief(TAU, "continuous")
    accelerating = motion.state_size == 6
    for case in range(3):
        for row in case_rows(draw_case(case, 11), config)[0]:
            estimate = row["sharp_p_find"] if accelerating else row["est_p_find"]
            assert abs(estimate - row["emp_p_find"]) <= 0.03, row
            if accelerating:  # the paper's: below the truth, never above it
                assert row["est_p_find"] <= row["emp_p_find"] + 0.01, row


def test_the_validation_needs_a_delay_before_its_budget():
    with pytest.raises(ValueError, match="not before the budget"):
        ValidationConfig(
            delays=(0.0, 200.0), budget=150.0, motion=RandomWalkSpec(model="random_walk")
        )
    assert replace(ValidationConfig(), cases=2).identity() == ValidationConfig().identity()
