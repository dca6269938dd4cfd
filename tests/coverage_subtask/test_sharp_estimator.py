import math

import numba
import numpy as np
import pytest
from scipy.stats import norm

from hptrack.coverage import CoverageSubtask
from hptrack.coverage.estimator import coverage_outcome, estimate_coverage
from hptrack.coverage.sharp_estimator import (
    ellipse_perimeter,
    estimate_sharp,
    flight_detection_sum,
    sharp_coverage_outcome,
    strip_constants,
    strip_mass,
)
from hptrack.experiments.coverage_validation import draw_case, first_detections, plan_coverage
from hptrack.interface import MissionSpec
from hptrack.models.mission import approach_step_to, intercept_steps_to, predict_covariance_on

MISSION = MissionSpec()
"""The paper's constants: tau 0.5 s, v_a 30 m/s, w 100 m, continuous-form Q."""
TAU, SPEED, W, R = 0.5, 30.0, 100.0, 50.0
RECORD = MISSION.record


def start_of_coverage(case_index, delay_s, agent=(0.0, 0.0)):
    """``(covariance at the start of the coverage, q, flight steps, approach)`` of a validation
    case after waiting ``delay_s``."""
    case = draw_case(case_index, 0)
    means, covs = MISSION.motion.predict(case.mean[None], case.covariance[None], case.q, delay_s)
    m = means[0]
    n = intercept_steps_to(RECORD, agent[0], agent[1], m)
    start = MISSION.motion.predict(means, covs, case.q, n * TAU)[1][0]
    return start, case.q, n, approach_step_to(RECORD, agent[0], agent[1], m, n)


def reference_model(cov, q, n, approach, cutoff):
    """The sharp model of ``docs/coverage-validation.md`` by brute-force numerical integration:
    400 phases of the last pass, the running maximum on a 0.02-step grid, the strip mass by a
    Cartesian 4001-point rule and the flight sum term by term over an 801-point rule across the
    line. Returns ``(p_find, expected steps from departure)``."""
    k_fine = np.arange(0.0, cutoff + 1e-9, 0.02)
    pos = np.empty((k_fine.size, 2, 2))
    out = np.empty((4, 4))
    for i, k in enumerate(k_fine):
        predict_covariance_on(RECORD, cov, q, k, out)
        pos[i] = out[:2, :2]
    det = np.linalg.det(pos)
    lam = np.linalg.eigvalsh(cov[:2, :2])
    a, b = math.sqrt(lam[1]), math.sqrt(lam[0])
    per = ellipse_perimeter(a, b)
    pitch = W / (2 * math.pi * a)
    rate = 4 * math.pi * pitch * SPEED * TAU / per  # s^2 per step
    scale = np.sqrt(rate * k_fine)
    h_out = (math.pi * a * b * scale**2 + R * per * scale + math.pi * R * R) / (
        math.pi * np.sqrt(det)
    )
    h_max = np.maximum.accumulate(h_out)
    alpha = (np.arange(400) + 0.5) / 400 * 2 * math.pi
    ks = np.arange(cutoff + 1.0)
    passed = np.sqrt(rate * ks)[:, None] - pitch * alpha[None, :]
    h_found = np.interp(np.maximum(passed, 0.0) ** 2 / rate, k_fine, h_max).mean(axis=1)
    found = -np.expm1(-h_found / 2)
    flight_sum = 0.0
    if n > 0:
        d = np.asarray(approach) / np.hypot(*approach)
        perp = np.array([-d[1], d[0]])
        sigma_c = math.sqrt(perp @ cov[:2, :2] @ perp)
        y = np.linspace(-R / sigma_c, R / sigma_c, 4001)
        wy = np.full(y.size, y[1] - y[0])
        wy[[0, -1]] /= 2
        outside = np.sqrt(np.maximum(h_found[:, None] - y[None, :] ** 2, 0.0))
        found = found + np.sum(wy * norm.pdf(y) * norm.sf(outside), axis=1)
        # along the line xi = -d.e, across c = perp.e: found by flight step j if xi >= s_j - chord
        var_a, var_c = d @ cov[:2, :2] @ d, perp @ cov[:2, :2] @ perp
        cov_ac = -(d @ cov[:2, :2] @ perp)
        c = np.linspace(-R, R, 801)
        wc = np.full(c.size, c[1] - c[0])
        wc[[0, -1]] /= 2
        mu = cov_ac / var_c * c
        sd = math.sqrt(var_a - cov_ac**2 / var_c)
        chord = np.sqrt(R * R - c * c)
        step = np.hypot(*approach)
        for j in range(n):
            flight_sum += np.sum(
                wc
                * norm.pdf(c, scale=math.sqrt(var_c))
                * norm.sf(((n - j) * step - chord - mu) / sd)
            )
    p = found[-1]
    return p, ((n + cutoff) * p - flight_sum - np.sum(found[:-1])) / p


def test_a_static_round_belief_covers_the_paper_area_less_two_thirds_of_the_footprint():
    # No velocity uncertainty, no process noise: nothing moves, the spiral is a circle. After the
    # first turn every angle was last passed at a phase uniform in the last turn, and the mean of
    # the parallel bodies is v_a w t + pi r^2 / 3: S_cover(t) minus 2/3 of the start footprint
    # that the first turn covers again.
    sigma2 = 150.0**2
    cov = np.diag([sigma2, sigma2, 0.0, 0.0])
    k_steps, p, e = sharp_coverage_outcome(RECORD, cov, 0.0, 300, 0, 0.0, 0.0)
    assert k_steps == 300  # the budget, as the paper's estimator
    area = SPEED * W * 300 * TAU + math.pi * R * R / 3.0
    assert p == pytest.approx(-math.expm1(-area / (2 * math.pi * sigma2)), rel=1e-12)
    paper = coverage_outcome(RECORD, cov, 0.0, 300)
    assert paper[1] == pytest.approx(
        -math.expm1(-(area + 2 * math.pi * R * R / 3) / (2 * math.pi * sigma2)), rel=1e-12
    )
    ref_p, ref_e = reference_model(cov, 0.0, 0, (0.0, 0.0), 300)
    assert p == pytest.approx(ref_p, rel=1e-4)
    assert e == pytest.approx(ref_e, rel=2e-3)


@pytest.mark.parametrize("case, delay", [(2, 0.0), (1, 100.0), (5, 200.0)])
def test_the_kernel_computes_its_model_as_a_brute_force_integration_does(case, delay):
    cov, q, n, approach = start_of_coverage(case, delay)
    k, p, e = sharp_coverage_outcome(RECORD, cov, q, 10_000_000, n, *approach)
    assert k == coverage_outcome(RECORD, cov, q, 10_000_000)[0]
    ref_p, ref_e = reference_model(cov, q, n, approach, int(k))
    assert p == pytest.approx(ref_p, abs=1e-3)
    assert e == pytest.approx(ref_e, rel=5e-3)


@pytest.mark.parametrize(
    "h, width", [(0.5, 0.3), (3.0, 0.3), (0.5, 2.0), (4.0, 2.0), (2.0, math.sqrt(2.0))]
)
def test_strip_mass_is_the_half_strip_outside_the_disk(h, width):
    y = np.linspace(-width, width, 20001)
    wy = np.full(y.size, y[1] - y[0])
    wy[[0, -1]] /= 2
    expected = np.sum(wy * norm.pdf(y) * norm.sf(np.sqrt(np.maximum(h - y * y, 0.0))))
    assert strip_mass(h, strip_constants(width)) == pytest.approx(expected, rel=5e-3)


def test_flight_sum_counts_the_flight_steps_after_the_find_as_a_simulation_does():
    # A straight approach towards the mean, footprint stepping (n - j) |delta| before it; the
    # target does not move in the flight (the model's approximation, exact here).
    rng = np.random.default_rng(4)
    cov = np.array([[1800.0, -700.0], [-700.0, 900.0]])
    delta = np.array([9.0, -11.0])
    n = 40
    e = rng.multivariate_normal(np.zeros(2), cov, size=40000)
    j = np.arange(n)
    footprint = -(n - j)[:, None] * delta[None, :]
    hit = np.linalg.norm(e[None, :, :] - footprint[:, None, :], axis=2) <= R
    found_by = np.maximum.accumulate(hit, axis=0)
    simulated = found_by.sum(axis=0).mean()
    full = np.zeros((4, 4))
    full[:2, :2] = cov
    total, sigma_c = flight_detection_sum(full, n, delta[0], delta[1], R)
    perp = np.array([-delta[1], delta[0]]) / np.hypot(*delta)
    assert sigma_c == pytest.approx(math.sqrt(perp @ cov @ perp), rel=1e-12)
    assert total == pytest.approx(simulated, abs=0.06)  # MC standard error about 0.01


def test_the_sharp_estimate_matches_the_simulation_where_the_paper_is_conservative():
    # Case 2 after 200 s: the paper's estimator misses 0.08 of P_find.
    plan = plan_coverage(draw_case(2, 0), 400, MISSION)
    first_any, _ = first_detections(
        plan, draw_case(2, 0).q, MISSION, 3000, np.random.default_rng(11)
    )
    found = first_any >= 0
    p_emp = found.mean()  # standard error about 0.008
    t_emp = first_any[found].mean() * TAU
    assert p_emp - plan.estimate.p_find > 0.05
    assert plan.sharp.p_find == pytest.approx(p_emp, abs=0.025)
    assert plan.sharp.expected_time == pytest.approx(t_emp, rel=0.04)
    assert plan.sharp.cutoff_steps == plan.estimate.cutoff_steps


def test_the_paper_estimator_is_unchanged():
    # Values of the stored full-protocol run (docs/results/coverage-validation/cases.csv).
    plan = plan_coverage(draw_case(5, 0), 200, MISSION)
    assert plan.estimate.cutoff_time == 124.5
    assert plan.estimate.p_find == 0.9023915584449247
    assert plan.estimate.expected_time == 14.424321825128565


def test_budget_truncation_and_a_budget_that_ends_before_the_coverage():
    cov, q, n, approach = start_of_coverage(3, 100.0)
    full = sharp_coverage_outcome(RECORD, cov, q, 10_000_000, n, *approach)
    short = sharp_coverage_outcome(RECORD, cov, q, 40, n, *approach)
    assert short[0] == 40 and short[1] < full[1] and short[2] < full[2]
    assert sharp_coverage_outcome(RECORD, cov, q, -1, n, *approach) == (0.0, 0.0, 0.0)
    est = estimate_sharp(cov, q, MISSION, n, approach, remaining_time=20.0)
    assert (est.cutoff_steps, est.p_find, est.budget_limited) == (40, short[1], True)
    assert est.expected_time == pytest.approx(short[2] * TAU)
    assert est.miss_steps == n + 40
    gone = estimate_sharp(cov, q, MISSION, n, approach, remaining_time=-1.0)
    assert (gone.p_find, gone.cutoff_steps) == (0.0, 0)
    paper = estimate_coverage(cov, q, MISSION, remaining_time=20.0)
    assert paper.cutoff_steps == est.cutoff_steps


def test_without_a_flight_the_approach_is_ignored_and_nothing_is_found_in_it():
    cov, q, _, _ = start_of_coverage(6, 200.0)
    a = sharp_coverage_outcome(RECORD, cov, q, 10_000_000, 0, 0.0, 0.0)
    b = sharp_coverage_outcome(RECORD, cov, q, 10_000_000, 0, 5.0, -3.0)
    assert a == b
    k, p, e = a
    assert 0.0 < e < k and 0.0 < p < 1.0


def test_the_wrapper_refuses_bad_inputs():
    cov, q, n, approach = start_of_coverage(0, 0.0)
    with pytest.raises(ValueError, match="flight_steps"):
        estimate_sharp(cov, q, MISSION, -1, approach)
    with pytest.raises(ValueError, match="approach"):
        estimate_sharp(cov, q, MISSION, n, (0.0, 0.0))
    with pytest.raises(ValueError, match="approach"):
        estimate_sharp(cov, q, MISSION, n, (math.nan, 1.0))
    with pytest.raises(ValueError, match="process noise"):
        estimate_sharp(cov, -1.0, MISSION, n, approach)


def test_the_subtask_exposes_the_sharp_estimate_of_its_own_flight():
    case = draw_case(4, 0)
    mission = MissionSpec(process_noise=np.array([case.q]), target_ids=("a",))
    agent = np.array([100.0, -50.0])
    sub = CoverageSubtask(agent, case.mean, case.covariance, case.q, mission, 900.0)
    n = sub.intercept.steps
    direct = estimate_sharp(
        sub.start_covariance,
        case.q,
        mission,
        n,
        approach_step_to(RECORD, *agent, case.mean, n),
        900.0 - n * TAU,
    )
    assert sub.sharp_estimate == direct
    assert direct.cutoff_steps == sub.estimate.cutoff_steps


@numba.njit
def _node_expansion(mission, agent, mean, cov, q, left):
    n = intercept_steps_to(mission, agent[0], agent[1], mean)
    ax, ay = approach_step_to(mission, agent[0], agent[1], mean, n)
    start = np.empty((4, 4))
    predict_covariance_on(mission, cov, q, n, start)
    return n, sharp_coverage_outcome(mission, start, q, left - n, n, ax, ay)


def test_the_kernel_is_callable_from_numba_like_the_paper_one():
    case = draw_case(7, 0)
    n, (k, p, e) = _node_expansion(RECORD, np.zeros(2), case.mean, case.covariance, case.q, 1800)
    est = estimate_sharp(
        MISSION.motion.predict(case.mean[None], case.covariance[None], case.q, n * TAU)[1][0],
        case.q,
        MISSION,
        n,
        approach_step_to(RECORD, 0.0, 0.0, case.mean, n),
        900.0 - n * TAU,
    )
    assert (k, p) == (est.cutoff_steps, est.p_find)
    assert e == pytest.approx(est.expected_steps, rel=1e-12)
    assert e > n  # the duration counts the flight
