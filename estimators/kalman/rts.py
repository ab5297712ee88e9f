"""Rauch-Tung-Striebel fixed-interval smoother (001 eqs. 28-31), the backward pass as a numba kernel.

Forward filtering stores, at every epoch k of the interval, the posterior x_k, P_k, the prediction x_{k+1,k},
P_{k+1,k} and the transition Phi_{k+1,k}; the backward pass starts from the last posterior (eq. 29) and runs

    A_k      = P_k Phi_{k+1,k}^T P_{k+1,k}^-1                      (eq. 31)
    x_rts,k  = x_k + A_k (x_rts,k+1 - x_{k+1,k})                    (eq. 30)
    P_rts,k  = P_k + A_k (P_rts,k+1 - P_{k+1,k}) A_k^T

For a closed-loop error-state filter (estimators.shearer.odometer_filter) the prediction is zero after every reset and x_k is
the update fed back at k, so x_rts,k is the smoothed error relative to the prior solution at k and
x_rts,k - x_k the correction to apply to the posterior solution at k.

A long interval's matrices (3 n^2 floats an epoch: 0.25 GB for a pass of 001's 21-state filter along a 360 m face)
need not be in memory at once: the forward filter appends them to a StoredInterval on disk a block at a time, and
rts_stored runs the same backward pass over it a block at a time from its end, bit for bit the result of rts_backward
over the whole interval.
"""

from __future__ import annotations

import os
import tempfile
import weakref

import numba as nb
import numpy as np

from estimators.arrays import put
from estimators.kalman.lapack import solve_matrix


@nb.njit(cache=True)
def rts_backward(x_post, p_post, x_pred, p_pred, phi, x_s, p_s):
    """Smooth epochs 0..N-1 in place into (x_s, p_s); row k+1 of x_pred, p_pred, phi is the step k -> k+1."""
    n = x_post.shape[0]
    put(x_s[n - 1], x_post[n - 1])
    put(p_s[n - 1], p_post[n - 1])
    for k in range(n - 2, -1, -1):
        # A_k = P_k Phi^T P_pred^-1, via a solve with the symmetric P_pred: A^T = P_pred^-1 Phi P_k.
        a = solve_matrix(p_pred[k + 1], phi[k + 1] @ p_post[k]).T
        put(x_s[k], x_post[k] + a @ (x_s[k + 1] - x_pred[k + 1]))
        put(p_s[k], p_post[k] + a @ (p_s[k + 1] - p_pred[k + 1]) @ a.T)


def one_sigma(p: np.ndarray) -> np.ndarray:
    """One-sigma of every state from covariances (..., n, n) (a variance rounded below zero gives 0)."""
    return np.sqrt(np.maximum(np.diagonal(p, axis1=-2, axis2=-1), 0.0))


def rts_smooth(x_post: np.ndarray, p_post: np.ndarray, x_pred: np.ndarray, p_pred: np.ndarray,
               phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed states (N, n) and covariances (N, n, n) of a stored forward pass (see module docstring)."""
    x_s, p_s = np.empty_like(x_post), np.empty_like(p_post)
    rts_backward(np.ascontiguousarray(x_post), np.ascontiguousarray(p_post), np.ascontiguousarray(x_pred),
                 np.ascontiguousarray(p_pred), np.ascontiguousarray(phi), x_s, p_s)
    return x_s, p_s


class StoredInterval:
    """The smoother's per-epoch matrices of one interval on disk: rows k = 0..N-1 of P_k (the posterior), P_{k,k-1}
    and Phi_{k,k-1} (row 0 of the last two: the interval's start, unused), appended in blocks as the forward filter
    makes them (`append`, then `close`) and read back a block at a time (`read`). A file per matrix in the system's
    temporary folder, removed when the object goes; the files are closed once written, so a run may keep many."""

    KINDS = ("p_post", "p_pred", "phi")

    def __init__(self, n_states: int):
        self.n, self.rows = n_states, 0
        self._files, self.paths = {}, {}
        for kind in self.KINDS:
            fd, path = tempfile.mkstemp(prefix="longwall-rts-", suffix=f"-{kind}.bin")
            self._files[kind], self.paths[kind] = os.fdopen(fd, "wb"), path
        self._remove = weakref.finalize(self, _remove_files, list(self._files.values()), list(self.paths.values()))

    def append(self, p_post: np.ndarray, p_pred: np.ndarray, phi: np.ndarray) -> None:
        """The next rows (r, n, n) of each matrix."""
        for kind, rows in zip(self.KINDS, (p_post, p_pred, phi)):
            np.ascontiguousarray(rows, np.float64).tofile(self._files[kind])
        self.rows += p_post.shape[0]

    def close(self) -> None:
        """The interval is complete: its files are written out and closed for reading."""
        for f in self._files.values():
            f.close()

    def read(self, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rows r0..r1-1 of P_k, P_{k,k-1} and Phi_{k,k-1}, fresh arrays (r1 - r0, n, n)."""
        per_row = self.n * self.n
        return tuple(np.fromfile(self.paths[kind], np.float64, (r1 - r0) * per_row, offset=r0 * per_row * 8)
                     .reshape(r1 - r0, self.n, self.n) for kind in self.KINDS)


def _remove_files(files, paths) -> None:
    for f in files:
        f.close()
    for path in paths:
        try:
            os.remove(path)
        except FileNotFoundError:
            pass


BLOCK = 2048
"""Epochs of an interval's matrices in memory at a time, as the forward filter makes them and in rts_stored (3 x 441
floats an epoch for 001's filter: 22 MB; a pass along a 360 m face is about 0.25 GB of them)."""


def rts_stored(stored: StoredInterval, x_post: np.ndarray, known: tuple[np.ndarray, np.ndarray] | None = None,
               keep: slice = slice(0, 0), block: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """rts_backward over a stored interval with a zero prediction (the closed-loop error state of the module
    docstring), `block` epochs (default BLOCK) at a time from its end: x_post (N, n) the updates; `known` the smoothed state and
    covariance at the last epoch (a later interval's smoother), else the forward ones. Returns the smoothed states
    (N, n), their one-sigma (N, n), P_rts[:, keep, keep] and P_rts at epoch 0."""
    n_rows, n = x_post.shape
    block = block or BLOCK
    if stored.rows != n_rows:
        raise ValueError(f"rts_stored: {stored.rows} stored epochs for {n_rows} updates")
    x_s, sd = np.empty_like(x_post), np.empty_like(x_post)
    idx = np.arange(n)[keep]
    p_keep = np.empty((n_rows, idx.size, idx.size))
    r1 = n_rows - 1
    x_s[r1], p_last = known if known is not None else (x_post[r1], stored.read(r1, r1 + 1)[0][0])

    def smoothed_rows(r0: int, r1: int, p: np.ndarray) -> None:
        sd[r0:r1] = one_sigma(p)
        p_keep[r0:r1] = p[:, idx[:, None], idx]

    smoothed_rows(r1, r1 + 1, p_last[None])
    while r1 > 0:
        r0 = max(r1 - block, 0)
        p_post, p_pred, phi = stored.read(r0, r1 + 1)
        x_run = x_post[r0:r1 + 1].copy()
        x_run[-1], p_post[-1] = x_s[r1], p_last
        x_blk = np.empty_like(x_run)
        rts_backward(x_run, p_post, np.zeros_like(x_run), p_pred, phi, x_blk, p_post)  # P smoothed in place
        x_s[r0:r1] = x_blk[:-1]
        smoothed_rows(r0, r1, p_post[:-1])
        p_last, r1 = p_post[0].copy(), r0
    return x_s, sd, p_keep, p_last
