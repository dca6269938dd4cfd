import numpy as np
import pytest
from textbook import joseph_update, random_spd, step_noise, transition

from hptrack.models.riccati import WORK_SLOTS, measured_covariance, riccati_table

TAU = 0.5
C_PER_STEP = {"continuous": TAU, "paper_text": 1.0}
FULL_R = np.array([[12.0, 5.0], [5.0, 7.0]])


def measured_step_by_step(predicted, q, form, noise, js):
    """``update(T^j(predicted))`` for each ``j`` in ``js``, with ``T(X) = F update(X) F' + Q``:
    the filter measuring at every step, one predict and one update at a time."""
    f, qq = transition(TAU), step_noise(q, TAU, form)
    out, x = {}, predicted
    for j in range(max(js) + 1):
        if j in js:
            out[j] = joseph_update(x, noise)
        x = f @ joseph_update(x, noise) @ f.T + qq
    return out


def composed(table, j, predicted, noise):
    maps_a, maps_g, maps_h, length = table
    out = np.full((4, 4), np.nan)
    work = np.empty((WORK_SLOTS, 4, 4))
    before = predicted.copy()
    measured_covariance(maps_a, maps_g, maps_h, length, j, predicted, noise, out, work)
    np.testing.assert_array_equal(predicted, before)  # the input is left alone
    return out


@pytest.mark.parametrize(
    ("form", "q"),
    [("continuous", 5e-4), ("paper_text", 5e-4), ("continuous", 0.05), ("paper_text", 0.05)],
)
def test_measured_covariance_follows_the_filter_also_past_the_converged_table(form, q):
    max_steps = 600
    table = riccati_table(q, TAU, C_PER_STEP[form], FULL_R, max_steps)
    length = table[3]
    assert 2 < length <= max_steps  # converged before the cap
    predicted = random_spd(np.random.default_rng(3))
    js = [0, 1, 2, 5, 40, length - 2, length - 1, length, length + 7, max_steps + 50]
    expected = measured_step_by_step(predicted, q, form, FULL_R, js)
    for j in js:
        got = composed(table, j, predicted, FULL_R)
        np.testing.assert_allclose(
            got, expected[j], rtol=1e-11, atol=1e-11 * np.max(np.abs(expected[j])), err_msg=f"j={j}"
        )


def test_unconverged_table_is_exact_up_to_its_cap():
    q, max_steps = 1e-4, 30
    table = riccati_table(q, TAU, TAU, FULL_R, max_steps)
    assert table[3] == max_steps + 1  # stopped by the cap, not converged
    predicted = random_spd(np.random.default_rng(9), scales=(60.0, 40.0, 1.0, 0.8))
    js = [0, 1, 3, 11, 29, 30]
    expected = measured_step_by_step(predicted, q, "continuous", FULL_R, js)
    for j in js:
        got = composed(table, j, predicted, FULL_R)
        np.testing.assert_allclose(
            got, expected[j], rtol=1e-11, atol=1e-11 * np.max(np.abs(expected[j])), err_msg=f"j={j}"
        )
