"""Allocation-free ``d x d`` linear algebra for the compiled kernels (state covariances are
``d x d``, ``d`` the motion's state size)."""

from __future__ import annotations

import numba


@numba.njit(cache=True)
def matmul_square(a, b, out, transpose_b):
    """``out = a b`` (or ``a b'``) for ``d x d`` arrays; ``out`` must not alias ``a`` or ``b``."""
    d = a.shape[0]
    for i in range(d):
        for j in range(d):
            acc = 0.0
            for k in range(d):
                acc += a[i, k] * (b[j, k] if transpose_b else b[k, j])
            out[i, j] = acc


@numba.njit(cache=True)
def solve_square(m, x, out):
    """``out = m^-1 x`` for a ``d x d`` ``m`` and a ``d``-row ``x`` (Gaussian elimination with
    partial pivoting); ``m`` and ``x`` are overwritten."""
    d = m.shape[0]
    cols = x.shape[1]
    for col in range(d):
        piv = col
        for r in range(col + 1, d):
            if abs(m[r, col]) > abs(m[piv, col]):
                piv = r
        if piv != col:
            for c in range(d):
                m[col, c], m[piv, c] = m[piv, c], m[col, c]
            for c in range(cols):
                x[col, c], x[piv, c] = x[piv, c], x[col, c]
        for r in range(col + 1, d):
            f = m[r, col] / m[col, col]
            for c in range(col, d):
                m[r, c] -= f * m[col, c]
            for c in range(cols):
                x[r, c] -= f * x[col, c]
    for col in range(d - 1, -1, -1):
        for c in range(cols):
            acc = x[col, c]
            for k in range(col + 1, d):
                acc -= m[col, k] * out[k, c]
            out[col, c] = acc / m[col, col]
