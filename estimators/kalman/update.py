"""The Kalman measurement update, written once for every error-state filter of the package (numba).

Each measurement model returns (z, H, R): the innovation's reference z, its sensitivity H to the error state
and its noise covariance R. The update is the Joseph form (001 eq. 28; 000 eqs. 28-30),

    K = P H^T S^-1,  S = H P H^T + R,  x <- x + K (z - H x),  P <- (I - K H) P (I - K H)^T + K R K^T,

which keeps P symmetric and positive semi-definite whatever the gain's round-off, and returns the normalized
innovation squared y^T S^-1 y (y = z - H x) the fault detectors and consistency checks read.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.arrays import put
from estimators.kalman.lapack import inv, solve_vector


@nb.njit(cache=True)
def joseph_update(x, p, z, h, r):
    """Kalman update of (x, P) with (z, H, R) in Joseph form, in place; returns the normalized innovation squared."""
    y = z - h @ x
    s = h @ p @ h.T + r
    s_inv = inv(s)
    k = p @ h.T @ s_inv
    x += k @ y
    ikh = np.eye(x.size) - k @ h
    put(p, ikh @ p @ ikh.T + k @ r @ k.T)
    return y @ s_inv @ y


@nb.njit(cache=True)
def nis(x, p, z, h, r):
    """Normalized innovation squared of (z, H, R) at (x, P), without updating."""
    y = z - h @ x
    return y @ solve_vector(h @ p @ h.T + r, y)


@nb.njit(cache=True)
def gated_update(x, p, z, h, r, gate):
    """Joseph update of (x, P) only if the normalized innovation squared is at most `gate` (a chi-square bound;
    np.inf for none); returns (normalized innovation squared, applied)."""
    gamma = nis(x, p, z, h, r)
    if gamma <= gate:
        joseph_update(x, p, z, h, r)
        return gamma, True
    return gamma, False
