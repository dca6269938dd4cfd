import numpy as np
import pytest

from hptrack.models.linalg import matmul_square, solve_square


@pytest.mark.parametrize("d", [4, 6])
@pytest.mark.parametrize("transpose_b", [False, True])
def test_matmul_square_is_the_matrix_product(transpose_b, d):
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(d, d)), rng.normal(size=(d, d))
    out = np.full((d, d), np.nan)
    matmul_square(a, b, out, transpose_b)
    np.testing.assert_allclose(out, a @ (b.T if transpose_b else b), rtol=1e-14, atol=1e-14)


@pytest.mark.parametrize("d", [4, 6])
@pytest.mark.parametrize("columns", [1, 4, 8])
@pytest.mark.parametrize("seed", range(3))
def test_solve_square_is_the_linear_solve(columns, seed, d):
    rng = np.random.default_rng(seed)
    m = rng.normal(size=(d, d))
    x = rng.normal(size=(d, columns))
    out = np.full((d, columns), np.nan)
    solve_square(m.copy(), x.copy(), out)
    np.testing.assert_allclose(out, np.linalg.solve(m, x), rtol=1e-11, atol=1e-12)


def test_solve_square_pivots_on_a_zero_leading_entry():
    # Without row exchanges the first elimination step would divide by m[0, 0] = 0.
    m = np.array(
        [[0.0, 2.0, 1.0, 0.0], [3.0, 1.0, 0.0, 1.0], [1.0, 0.0, 4.0, 2.0], [0.0, 1.0, 1.0, 5.0]]
    )
    x = np.arange(8.0).reshape(4, 2)
    out = np.empty((4, 2))
    solve_square(m.copy(), x.copy(), out)
    np.testing.assert_allclose(m @ out, x, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(out, np.linalg.solve(m, x), rtol=1e-13, atol=1e-13)
