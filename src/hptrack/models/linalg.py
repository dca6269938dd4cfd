"""Allocation-free 4x4 linear algebra for the compiled kernels (state covariances are 4x4)."""

from __future__ import annotations

import numba


@numba.njit(cache=True)
def matmul4(a, b, out, transpose_b):
    """``out = a b`` (or ``a b'``) for 4x4 arrays; ``out`` must not alias ``a`` or ``b``."""
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += a[i, k] * (b[j, k] if transpose_b else b[k, j])
            out[i, j] = acc


@numba.njit(cache=True)
def solve4(m, x, out):
    """``out = m^-1 x`` for a 4x4 ``m`` and a 4-row ``x`` (Gaussian elimination with partial
    pivoting); ``m`` and ``x`` are overwritten."""
    cols = x.shape[1]
    for col in range(4):
        piv = col
        for r in range(col + 1, 4):
            if abs(m[r, col]) > abs(m[piv, col]):
                piv = r
        if piv != col:
            for c in range(4):
                m[col, c], m[piv, c] = m[piv, c], m[col, c]
            for c in range(cols):
                x[col, c], x[piv, c] = x[piv, c], x[col, c]
        for r in range(col + 1, 4):
            f = m[r, col] / m[col, col]
            for c in range(col, 4):
                m[r, c] -= f * m[col, c]
            for c in range(cols):
                x[r, c] -= f * x[col, c]
    for col in range(3, -1, -1):
        for c in range(cols):
            acc = x[col, c]
            for k in range(col + 1, 4):
                acc -= m[col, k] * out[k, c]
            out[col, c] = acc / m[col, col]
