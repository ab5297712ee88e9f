"""Cholesky factor of a covariance's correlation matrix, for the numba filter kernels: the positive-definiteness
test, whitening (quadratic forms v^T S^-1 v) and the inverse of a symmetric positive definite matrix.

A covariance S is factored as S = D^-1/2 L L^T D^-1/2 with D = diag(S) and L the lower Cholesky factor of the
correlation matrix C = D^-1/2 S D^-1/2, so error states of very different scales (metres and 1e-5 rad/s) keep
their precision. L's squared pivots are the variances of each correlation-scaled state given the states before
it; S counts as positive definite when every one exceeds PD_RTOL (a state that the others determine to within a
correlation of 1 - 1e-12 is as good as singular).

A factor and two triangular sweeps cost about a tenth of an eigen-decomposition at the filters' 22 states.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["PD_RTOL", "SYMMETRY_RTOL", "correlation_cholesky", "spd_inverse", "whiten"]

PD_RTOL = 1e-12
"""Smallest squared Cholesky pivot of the correlation matrix D^-1/2 S D^-1/2 for S to count as positive definite."""
SYMMETRY_RTOL = 1e-8
"""Largest |S - S^T| relative to the diagonal scale (sqrt(S_ii S_jj)) for S to count as symmetric."""


@nb.njit(cache=True)
def correlation_cholesky(s):
    """(L, d, ok): s ~ D^1/2 L L^T D^1/2 with d = diag(s)^-1/2 and L the lower Cholesky factor of the correlation
    matrix of the symmetrised s; ok False when s is not finite or not positive definite to PD_RTOL."""
    m = s.shape[0]
    chol = np.zeros((m, m))
    d = np.zeros(m)
    for i in range(m):
        for j in range(m):
            if not np.isfinite(s[i, j]):
                return chol, d, False
    for i in range(m):
        if not s[i, i] > 0.0:
            return chol, d, False
        d[i] = 1.0 / math.sqrt(s[i, i])
    for j in range(m):
        acc = 1.0
        for p in range(j):
            acc -= chol[j, p] * chol[j, p]
        if not acc > PD_RTOL:
            return chol, d, False
        chol[j, j] = math.sqrt(acc)
        for i in range(j + 1, m):
            acc = 0.5 * (s[i, j] + s[j, i]) * d[i] * d[j]
            for p in range(j):
                acc -= chol[i, p] * chol[j, p]
            chol[i, j] = acc / chol[j, j]
    return chol, d, True


@nb.njit(cache=True)
def whiten(chol, d, v):
    """y with y^T y = v^T S^-1 v: y = L^-1 D^-1/2 v (forward substitution)."""
    m = v.shape[0]
    y = np.empty(m)
    for i in range(m):
        acc = v[i] * d[i]
        for p in range(i):
            acc -= chol[i, p] * y[p]
        y[i] = acc / chol[i, i]
    return y


@nb.njit(cache=True)
def spd_inverse(p):
    """(P^-1, ok): the inverse of a symmetric positive definite P, exactly symmetric; ok False (and P^-1 zero) when
    P is not finite, not symmetric to SYMMETRY_RTOL or not positive definite to PD_RTOL.

    P^-1 = D^1/2 M^T M D^1/2 with M = L^-1 (correlation_cholesky)."""
    n = p.shape[0]
    inv = np.zeros((n, n))
    chol, d, ok = correlation_cholesky(p)
    if not ok:
        return inv, False
    for i in range(n):
        for j in range(i):
            if abs(p[i, j] - p[j, i]) * d[i] * d[j] > SYMMETRY_RTOL:
                return inv, False
    m_inv = np.zeros((n, n))  # L^-1, lower triangular, column by column
    for j in range(n):
        m_inv[j, j] = 1.0 / chol[j, j]
        for i in range(j + 1, n):
            acc = 0.0
            for k in range(j, i):
                acc -= chol[i, k] * m_inv[k, j]
            m_inv[i, j] = acc / chol[i, i]
    for i in range(n):
        for j in range(i + 1):
            acc = 0.0
            for k in range(i, n):
                acc += m_inv[k, i] * m_inv[k, j]
            inv[i, j] = inv[j, i] = acc * d[i] * d[j]
    return inv, True
