"""Innovation-based estimation of the measurement noise over a sliding window (003 section 4.2).

For a consistent filter the innovation v_k = z_k - H_k x_k|k-1 has covariance H_k P_k|k-1 H_k^T + R, so over
the last N steps

    R_k = (1/N) sum_j v_j v_j^T - (1/N) sum_j H_j P_j|j-1 H_j^T.

003 writes the second term at the current step; the window mean is the same when H P H^T is steady and stays
unbiased while P shrinks (after a reset, during convergence). The estimate is symmetrised and kept positive
definite: its eigenvalues are raised to at least min(r_min), then each diagonal element to at least r_min.
Before `min_samples` innovations are in the window the nominal R is returned.

The window is a ring buffer of the per-step differences D_j = v_j v_j^T - H_j P_j H_j^T, shape (N, m, m), so
one call per measurement is O(N m^2). The numba functions `window_push` and `window_r` work inside a filter
kernel; `InnovationNoiseEstimator` wraps them for Python loops, `estimate_r` does one window in one call.
"""

from __future__ import annotations

import numba as nb
import numpy as np

__all__ = ["InnovationNoiseEstimator", "estimate_r", "window_push", "window_r"]


@nb.njit(cache=True)
def window_push(buf, count, v, hph):
    """Store D = v v^T - H P H^T in the ring buffer buf (N, m, m) after `count` pushes; returns count + 1."""
    m = v.shape[0]
    slot = count % buf.shape[0]
    for i in range(m):
        for j in range(m):
            buf[slot, i, j] = v[i] * v[j] - hph[i, j]
    return count + 1


@nb.njit(cache=True)
def window_r(buf, count, r_nominal, r_min, min_samples):
    """R (m, m) from the ring buffer after `count` pushes (003 section 4.2), positive definite.

    r_nominal (m, m) is returned until min_samples innovations are in; r_min (m,) are the variance floors.
    """
    n = min(count, buf.shape[0])
    if n < max(min_samples, 1):
        return r_nominal.copy()
    m = buf.shape[1]
    r = np.zeros((m, m))
    for k in range(n):
        r += buf[k]
    r = 0.5 * (r + r.T) / n
    w, vec = np.linalg.eigh(r)
    w = np.maximum(w, r_min.min())
    r = (vec * w) @ vec.T
    for i in range(m):
        r[i, i] = max(r[i, i], r_min[i])
    return r


def _as_matrix(a, m: int, what: str) -> np.ndarray:
    a = np.asarray(a, float)
    if a.ndim == 0:
        a = a * np.eye(m) if m > 1 else a.reshape(1, 1)
    if a.shape != (m, m):
        raise ValueError(f"{what}: shape {a.shape}, expected ({m}, {m})")
    return a


def _floors(r_min, m: int) -> np.ndarray:
    floors = np.broadcast_to(np.asarray(r_min, float), (m,)).copy()
    if not np.all(floors > 0):
        raise ValueError("r_min: variance floors must be positive (R is kept positive definite)")
    return floors


def estimate_r(innovations, hph, r_min) -> np.ndarray:
    """R from one window: innovations (N, m) or (N,), hph (m, m) or per step (N, m, m), floors r_min (m,)."""
    v = np.asarray(innovations, float)
    v = v[:, None] if v.ndim == 1 else v
    n, m = v.shape
    hph = np.asarray(hph, float)
    hph = np.broadcast_to(hph.reshape(m, m) if hph.ndim < 3 else hph, (n, m, m))
    buf = np.zeros((n, m, m))
    count = 0
    for k in range(n):
        count = window_push(buf, count, v[k], hph[k])
    floors = _floors(r_min, m)
    return window_r(buf, count, np.diag(floors), floors, 1)


class InnovationNoiseEstimator:
    """Sliding-window estimate of a measurement's R from its innovations (003 section 4.2).

    `window` innovations, `r_nominal` (m, m) (or a scalar variance) until `min_samples` are in, variance floors
    `r_min` (m,) or scalar. Call `update(v, hph)` with each innovation and the H P H^T it was formed with; it
    returns the R to use for the next update (003 replaces R by it).
    """

    def __init__(self, window: int, r_nominal, r_min, min_samples: int | None = None):
        if window < 1:
            raise ValueError(f"window: {window}, need at least 1 innovation")
        r_nominal = np.asarray(r_nominal, float)
        self.m = 1 if r_nominal.ndim == 0 else r_nominal.shape[0]
        self.r_nominal = _as_matrix(r_nominal, self.m, "r_nominal")
        self.r_min = _floors(r_min, self.m)
        self.min_samples = window if min_samples is None else int(min_samples)
        self.buf = np.zeros((window, self.m, self.m))
        self.count = 0
        self.r = self.r_nominal.copy()

    def update(self, v, hph) -> np.ndarray:
        """Push one innovation (m,) with its H P H^T (m, m); the new R (m, m). Non-finite innovations are skipped."""
        v = np.atleast_1d(np.asarray(v, float))
        hph = _as_matrix(hph, self.m, "hph")
        if np.all(np.isfinite(v)) and np.all(np.isfinite(hph)):
            self.count = window_push(self.buf, self.count, v, hph)
            self.r = window_r(self.buf, self.count, self.r_nominal, self.r_min, self.min_samples)
        return self.r
