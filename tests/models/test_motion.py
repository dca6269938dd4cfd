import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from textbook import continuous_noise, predict_steps, random_spd, step_noise, transition

from hptrack.models.motion import (
    ConstantVelocityModel,
    advance_true_state,
    fill_process_noise,
    fill_transition,
    mean_position_at,
    motion_noise_factors,
    noise_blocks,
    position_covariance_after,
    position_polynomials,
    predict_covariance,
    predicted_positions,
)
from hptrack.scenario.random import random_prior

TAU = 0.5
C_PER_STEP = {"continuous": TAU, "paper_text": 1.0}


def step_by_step(model, cov, q, k):
    f, qq = model.transition(), model.process_noise(q)
    for _ in range(k):
        cov = f @ cov @ f.T + qq
    return cov


def close(got, expected, rtol=1e-12):
    """Entry-wise relative agreement, with an absolute floor at ``rtol`` times the largest
    entry (cross terms may cancel to near zero)."""
    np.testing.assert_allclose(
        got, expected, rtol=rtol, atol=rtol * float(np.max(np.abs(expected)))
    )


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
@pytest.mark.parametrize("k", [0, 1, 2, 7, 100, 1800])
def test_closed_form_equals_step_by_step(form, k):
    model = ConstantVelocityModel(0.5, form)
    cov, q = random_prior(np.random.default_rng(k))
    expected = step_by_step(model, cov, q, k)
    _, got = model.predict(np.zeros((1, 4)), cov[None], q, k * 0.5)
    np.testing.assert_allclose(got[0], expected, rtol=1e-10, atol=1e-9)
    sxx, sxy, syy = position_covariance_after(cov, q, float(k), 0.5, model.c_per_step)
    np.testing.assert_allclose([[sxx, sxy], [sxy, syy]], expected[:2, :2], rtol=1e-10)


def test_continuous_noise_is_continuous_time_integral():
    q, tau, k = 3e-4, 0.5, 40
    t = k * tau
    qpp, qpv, qvv = noise_blocks(q, float(k), tau, tau)
    np.testing.assert_allclose([qpp, qpv, qvv], [q * t**3 / 3, q * t**2 / 2, q * t], rtol=1e-12)


def test_paper_text_form_matches_notes_formula():
    q, tau, k = 2e-4, 0.5, 13
    s1, s2 = k * (k - 1) / 2, k * (k - 1) * (2 * k - 1) / 6
    got = noise_blocks(q, float(k), tau, 1.0)
    expected = [
        q * (k * tau**3 / 3 + tau**3 * s1 + tau**2 * s2),
        q * (k * tau**2 / 2 + tau * s1),
        q * k,
    ]
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(ConstantVelocityModel(tau, "paper_text").process_noise(q)[2, 2], q)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.lists(st.integers(0, 300), min_size=3, max_size=3))
def test_per_target_durations(seed, steps):
    model = ConstantVelocityModel()
    rng = np.random.default_rng(seed)
    priors = [random_prior(rng) for _ in steps]
    covs = np.array([c for c, _ in priors])
    qs = np.array([q for _, q in priors])
    means = rng.normal(size=(3, 4))
    got_m, got_c = model.predict(means, covs, qs, 0.5 * np.array(steps, dtype=float))
    for i, k in enumerate(steps):
        np.testing.assert_allclose(got_c[i], step_by_step(model, covs[i], qs[i], k), rtol=1e-9)
        np.testing.assert_allclose(
            got_m[i], np.linalg.matrix_power(model.transition(), k) @ means[i], rtol=1e-12
        )


def test_sampled_motion_has_model_covariance():
    model = ConstantVelocityModel()
    q = np.full(200_000, 4e-4)
    states = model.sample_motion(np.zeros((q.size, 4)), q, np.random.default_rng(0))
    np.testing.assert_allclose(np.cov(states.T), model.process_noise(4e-4), rtol=0.02, atol=2e-6)


# --- kernels against the textbook (tests/models/textbook.py) ------------------------------


@pytest.mark.parametrize("steps", [0.0, 0.37, 1.0, 2.5, 7.0, 13.8, 240.25, 1800.0])
def test_predict_covariance_is_exact_for_any_duration_in_the_continuous_form(steps):
    rng = np.random.default_rng(int(steps * 100))
    cov, q, t = random_spd(rng), 3.7e-4, steps * TAU
    expected = transition(t) @ cov @ transition(t).T + continuous_noise(q, t)
    out = np.empty((4, 4))
    predict_covariance(cov, q, steps, TAU, TAU, out)
    close(out, expected)
    # the numpy API: any duration in seconds, per target
    model = ConstantVelocityModel(TAU, "continuous")
    means = rng.normal(size=(2, 4)) * [100.0, 100.0, 2.0, 2.0]
    durations = np.array([t, 0.5 * t + 0.123])
    got_m, got_c = model.predict(means, np.stack([cov, cov]), [q, 2.0 * q], durations)
    for i, (d, qi) in enumerate(zip(durations, [q, 2.0 * q], strict=True)):
        close(got_c[i], transition(d) @ cov @ transition(d).T + continuous_noise(qi, d))
        close(got_m[i], transition(d) @ means[i])
    close(model.transition(t), transition(t))
    close(model.process_noise(q, t), continuous_noise(q, t))


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
@pytest.mark.parametrize("k", [0, 1, 2, 3, 10, 57, 600])
def test_predict_covariance_of_whole_steps_equals_the_step_by_step_sum(form, k):
    rng = np.random.default_rng(k)
    cov, q = random_spd(rng), 2.2e-4
    expected = predict_steps(cov, q, k, TAU, form)
    out = np.empty((4, 4))
    predict_covariance(cov, q, k, TAU, C_PER_STEP[form], out)
    close(out, expected, rtol=1e-10)
    model = ConstantVelocityModel(TAU, form)
    close(model.transition(), transition(TAU))
    close(model.process_noise(q), step_noise(q, TAU, form))
    close(model.predict(np.zeros((1, 4)), cov[None], q, k * TAU)[1][0], expected, rtol=1e-10)


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_predict_covariance_in_place_equals_out_of_place(form):
    cov = random_spd(np.random.default_rng(5))
    for steps in (0.6, 3.0, 41.5):
        separate = np.empty((4, 4))
        predict_covariance(cov, 4e-4, steps, TAU, C_PER_STEP[form], separate)
        aliased = cov.copy()
        predict_covariance(aliased, 4e-4, steps, TAU, C_PER_STEP[form], aliased)
        np.testing.assert_array_equal(aliased, separate)
    one = cov.copy()
    for _ in range(9):  # nine in-place steps are the nine-step prediction
        predict_covariance(one, 4e-4, 1.0, TAU, C_PER_STEP[form], one)
    close(one, predict_steps(cov, 4e-4, 9, TAU, form), rtol=1e-11)


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_position_covariance_and_its_polynomials_agree_with_the_textbook(form):
    cov, q, c = random_spd(np.random.default_rng(11)), 4.4e-4, C_PER_STEP[form]
    x0, x1, x2, y0, y1, y2, c0, c1, c2, x3 = position_polynomials(cov, q, TAU, c)
    ks = [0, 1, 4, 33, 900] if form == "paper_text" else [0, 0.4, 1, 4.75, 33, 900]
    for k in ks:
        if form == "paper_text":
            expected = predict_steps(cov, q, k, TAU, form)[:2, :2]
        else:
            t = k * TAU
            expected = (transition(t) @ cov @ transition(t).T + continuous_noise(q, t))[:2, :2]
        sxx, sxy, syy = position_covariance_after(cov, q, float(k), TAU, c)
        close([[sxx, sxy], [sxy, syy]], expected, rtol=1e-11)
        poly = [
            [x0 + k * (x1 + k * (x2 + k * x3)), c0 + k * (c1 + k * c2)],
            [c0 + k * (c1 + k * c2), y0 + k * (y1 + k * (y2 + k * x3))],
        ]
        close(poly, expected, rtol=1e-11)


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_fill_transition_and_process_noise(form):
    out = np.full((4, 4), np.nan)
    fill_transition(3.25, out)
    np.testing.assert_array_equal(out, transition(3.25))
    fill_process_noise(2e-4, 1.0, TAU, C_PER_STEP[form], out)
    close(out, step_noise(2e-4, TAU, form))
    fill_process_noise(2e-4, 6.0, TAU, C_PER_STEP[form], out)
    close(out, predict_steps(np.zeros((4, 4)), 2e-4, 6, TAU, form))
    if form == "continuous":
        fill_process_noise(2e-4, 6.3, TAU, TAU, out)
        close(out, continuous_noise(2e-4, 6.3 * TAU))


def test_mean_position_is_the_constant_velocity_prediction():
    mean = np.array([120.0, -40.0, -2.5, 1.25])
    for t in (0.0, 0.5, 3.7, 900.0):
        np.testing.assert_allclose(
            mean_position_at(mean, t), (transition(t) @ mean)[:2], rtol=1e-15
        )
    means = np.random.default_rng(2).normal(size=(3, 4))
    times = np.array([0.0, 1.5, 7.25])
    got = predicted_positions(means[None, :, :], times[:, None])
    assert got.shape == (3, 3, 2)
    for a, t in enumerate(times):
        for i in range(3):
            np.testing.assert_allclose(got[a, i], (transition(t) @ means[i])[:2], rtol=1e-15)


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
def test_true_state_step_is_f_x_plus_cholesky_of_q_times_z(form):
    rng = np.random.default_rng(7)
    states = rng.normal(size=(5, 4)) * [500.0, 500.0, 2.0, 2.0]
    z = rng.normal(size=(5, 4))
    q = rng.uniform(1e-4, 5e-4, 5)
    l11, l21, l22 = motion_noise_factors(TAU, C_PER_STEP[form])
    unit = np.linalg.cholesky(step_noise(1.0, TAU, form))
    np.testing.assert_allclose([l11, l21, l22], [unit[0, 0], unit[2, 0], unit[2, 2]], rtol=1e-14)
    got = states.copy()
    for i in range(5):
        advance_true_state(got, i, z[i], np.sqrt(q[i]), l11, l21, l22, TAU)
        factor = np.linalg.cholesky(step_noise(q[i], TAU, form))
        expected = transition(TAU) @ states[i] + factor @ z[i]
        np.testing.assert_allclose(got[i], expected, rtol=1e-13, atol=1e-13)
