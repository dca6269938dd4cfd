import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hptrack.models.motion import ConstantVelocityModel, noise_blocks, position_covariance_after
from hptrack.scenario.random import random_prior


def step_by_step(model, cov, q, k):
    f, qq = model.transition(1), model.process_noise(q, 1)
    for _ in range(k):
        cov = f @ cov @ f.T + qq
    return cov


@pytest.mark.parametrize("form", ["continuous", "paper_text"])
@pytest.mark.parametrize("k", [0, 1, 2, 7, 100, 1800])
def test_closed_form_equals_step_by_step(form, k):
    model = ConstantVelocityModel(0.5, form)
    cov, q = random_prior(np.random.default_rng(k))
    expected = step_by_step(model, cov, q, k)
    _, got = model.predict(np.zeros((1, 4)), cov[None], q, k)
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
    expected = [q * (k * tau**3 / 3 + tau**3 * s1 + tau**2 * s2), q * (k * tau**2 / 2 + tau * s1),
                q * k]
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
    got_m, got_c = model.predict(means, covs, qs, np.array(steps, dtype=float))
    for i, k in enumerate(steps):
        np.testing.assert_allclose(got_c[i], step_by_step(model, covs[i], qs[i], k), rtol=1e-9)
        np.testing.assert_allclose(got_m[i], np.linalg.matrix_power(model.transition(1), k)
                                   @ means[i], rtol=1e-12)


def test_sampled_motion_has_model_covariance():
    model = ConstantVelocityModel()
    q = np.full(200_000, 4e-4)
    states = model.sample_motion(np.zeros((q.size, 4)), q, np.random.default_rng(0))
    np.testing.assert_allclose(np.cov(states.T), model.process_noise(4e-4), rtol=0.02, atol=2e-6)
