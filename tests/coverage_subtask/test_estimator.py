import math

import numba
import numpy as np
import pytest
from scipy.stats import chi2

from hptrack.coverage.estimator import coverage_cdf, coverage_outcome, estimate_coverage
from hptrack.interface import MissionSpec
from hptrack.models.mission import mission_record
from hptrack.models.motion import position_covariance_after
from hptrack.models.vehicle import intercept_time
from hptrack.scenario.random import random_prior

MISSION = MissionSpec()
"""The paper's constants: tau 0.5 s, v_a 30 m/s, w 100 m, continuous-form Q."""


def prior(seed, delay_s=0.0):
    """A prior of the paper's distributions propagated ``delay_s`` seconds."""
    cov, q = random_prior(np.random.default_rng(seed))
    _, covs = MISSION.motion.predict(np.zeros((1, 4)), cov[None], q, delay_s)
    return covs[0], q


@pytest.mark.parametrize("delay", [0.0, 100.0, 200.0, 600.0])
@pytest.mark.parametrize("seed", range(4))
def test_p_cdf_rises_to_t_cutoff_and_not_after(seed, delay):
    cov, q = prior(seed, delay)
    est = estimate_coverage(cov, q, MISSION)
    k = est.cutoff_steps
    long = coverage_cdf(MISSION.record, cov, q, 4 * k + 200)
    assert k > 0
    assert np.all(np.diff(long[: k + 1]) > 0)
    assert long[k + 1] <= long[k]
    assert np.max(long[k + 1 :]) <= long[k]  # t_cutoff is the global maximum
    assert est.p_find == pytest.approx(long[k], rel=1e-12)
    np.testing.assert_allclose(est.cdf, long[: k + 1], rtol=1e-12)


def test_p_cdf_is_the_chi_squared_cdf_of_the_covered_area():
    cov, q = prior(7, 100.0)
    k = 37
    sxx, sxy, syy = position_covariance_after(cov, q, float(k), 0.5, 0.5)
    area = 30.0 * 100.0 * k * 0.5 + math.pi * 50.0**2
    expected = chi2.cdf(area / (math.pi * math.sqrt(sxx * syy - sxy**2)), df=2)
    got = coverage_cdf(MISSION.record, cov, q, k + 1)[k]
    assert got == pytest.approx(expected, rel=1e-12)


def test_expected_time_is_the_conditional_mean_in_seconds():
    cov, q = prior(3, 200.0)
    est = estimate_coverage(cov, q, MISSION)
    p = est.cdf
    mass = np.diff(p, prepend=0.0)  # P(T = k tau), with P_cdf(0) at time 0
    expected = np.sum(np.arange(len(p)) * 0.5 * mass) / p[-1]
    assert est.expected_time == pytest.approx(expected, rel=1e-10)
    assert est.expected_steps == pytest.approx(expected / 0.5)
    assert 0.0 < est.expected_time < est.cutoff_time


def test_budget_ending_before_t_cutoff_truncates_the_estimate():
    cov, q = prior(1, 100.0)
    full = estimate_coverage(cov, q, MISSION)
    short = estimate_coverage(cov, q, MISSION, remaining_time=20.25)
    assert not full.budget_limited and short.budget_limited
    assert short.cutoff_steps == 40
    assert short.p_find == pytest.approx(full.cdf[40], rel=1e-12)
    assert short.expected_time < full.expected_time
    ample = estimate_coverage(cov, q, MISSION, remaining_time=full.cutoff_time + 100.0)
    assert ample.cutoff_steps == full.cutoff_steps and not ample.budget_limited
    assert ample.p_find == full.p_find


def test_budget_ending_before_the_coverage_starts_finds_nothing():
    cov, q = prior(1)
    est = estimate_coverage(cov, q, MISSION, remaining_time=-3.0)
    assert (est.p_find, est.cutoff_steps, est.expected_time) == (0.0, 0, 0.0)
    assert coverage_outcome(MISSION.record, cov, q, -1) == (0.0, 0.0, 0.0)


def test_paper_text_noise_form_grows_faster():
    cov, q = prior(2, 200.0)
    cont = estimate_coverage(cov, q, MISSION)
    text = estimate_coverage(cov, q, MissionSpec(process_noise_form="paper_text"))
    assert text.p_find < cont.p_find


@pytest.mark.parametrize(
    "cov, match",
    [
        (np.full((4, 4), np.nan), "finite 4x4"),
        (np.eye(3), "finite 4x4"),
        (np.diag([100.0, 100.0, 1.0, 1.0]) + np.triu(np.ones((4, 4)), 1), "not symmetric"),
        (np.diag([100.0, 100.0, -1.0, 1.0]), "not positive semi-definite"),
        (np.diag([100.0, 0.0, 1.0, 1.0]), "position covariance is not positive definite"),
    ],
)
def test_bad_covariances_get_clear_errors(cov, match):
    with pytest.raises(ValueError, match=match):
        estimate_coverage(cov, 1e-4, MISSION)


def test_bad_scalars_get_clear_errors():
    cov, q = prior(0)
    with pytest.raises(ValueError, match="process noise"):
        estimate_coverage(cov, -1e-4, MISSION)
    with pytest.raises(ValueError, match="NaN"):
        estimate_coverage(cov, q, MISSION, remaining_time=math.nan)
    with pytest.raises(ValueError, match="speed"):
        MissionSpec(agent_speed=-30.0)
    with pytest.raises(ValueError, match="process_noise_form"):
        MissionSpec(process_noise_form="other")


def test_a_belief_that_never_grows_is_an_error_not_an_endless_loop():
    static = np.diag([1000.0, 1000.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="does not grow"):
        estimate_coverage(static, 0.0, MISSION)
    # with a budget it is simply cut there
    est = estimate_coverage(static, 0.0, MISSION, remaining_time=50.0)
    assert est.cutoff_steps == 100 and est.budget_limited


@numba.njit
def _node_expansion(mission, agent, mean, cov, q):
    t = intercept_time(agent[0], agent[1], mean[0], mean[1], mean[2], mean[3], 30.0)
    n = math.ceil(t / 0.5 - 1e-9)
    return n, coverage_outcome(mission, cov, q, 1800 - n)


def test_kernels_are_callable_from_numba():
    cov, q = prior(5)
    mean = np.array([800.0, -300.0, 1.0, 2.0])
    n, (k, p, e) = _node_expansion(MISSION.record, np.zeros(2), mean, cov, q)
    assert n == math.ceil(intercept_time(0.0, 0.0, 800.0, -300.0, 1.0, 2.0, 30.0) / 0.5)
    assert (k, p, e) == coverage_outcome(MISSION.record, cov, q, 1800 - n)


def test_the_mission_constants_are_the_ones_estimated_with():
    cov, q = prior(4, 100.0)
    mission = MissionSpec(
        time_step=0.25, agent_speed=20.0, sensor_diameter=80.0, process_noise_form="paper_text"
    )
    est = estimate_coverage(cov, q, mission, remaining_time=400.0)
    record = mission_record(0.25, 900.0, 20.0, 80.0, 10.0 * np.eye(2), [q], False)
    k, p, e = coverage_outcome(record, cov, q, 1600)
    assert (est.cutoff_steps, est.p_find, est.expected_time) == (k, p, e * 0.25)
    assert est.p_find != estimate_coverage(cov, q, MISSION, remaining_time=400.0).p_find
