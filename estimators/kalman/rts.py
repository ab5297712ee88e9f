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
from pathlib import Path

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
    makes them (`append`) and read back a block at a time (`read_into`). A file per matrix: in `folder`, removed when
    the object goes, or without a folder in the system's temporary one, unlinked as soon as it is open (nothing is
    left behind however the process ends). `restart` writes the next interval over the last one: pages the system
    still caches are written again at the cost of a copy, where new ones cost several times that (this machine:
    0.05 s against 0.57 s for 0.26 GB). `close` lets a named interval's descriptors go (a run may keep many); a read
    opens them again."""

    KINDS = ("p_post", "p_pred", "phi")

    def __init__(self, n_states: int, folder: Path | None = None):
        self.n, self.rows = n_states, 0
        self.paths: list[str] | None = [] if folder is not None else None
        fds = []
        for kind in self.KINDS:
            fd, path = tempfile.mkstemp(prefix="longwall-rts-", suffix=f"-{kind}.bin", dir=folder)
            fds.append(fd)
            if folder is None:
                os.remove(path)  # the open descriptor keeps the file until it is closed
            else:
                self.paths.append(path)
        self._fds = fds  # the finalizer closes whatever is open in this list when the object goes
        self._remove = weakref.finalize(self, _remove_files, self._fds, self.paths or [])

    @property
    def row_bytes(self) -> int:
        return self.n * self.n * 8

    def restart(self) -> None:
        """An empty interval: the next rows are written over the stored ones."""
        self.rows = 0

    def append(self, p_post: np.ndarray, p_pred: np.ndarray, phi: np.ndarray) -> None:
        """The next rows (r, n, n) of each matrix (C-contiguous float64)."""
        self._open()
        for fd, rows in zip(self._fds, (p_post, p_pred, phi)):
            data, offset = memoryview(np.ascontiguousarray(rows, np.float64)).cast("B"), self.rows * self.row_bytes
            while data:
                written = os.pwrite(fd, data, offset)
                data, offset = data[written:], offset + written
        self.rows += p_post.shape[0]

    def read_into(self, r0: int, r1: int, out: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """Rows r0..r1-1 of P_k, P_{k,k-1} and Phi_{k,k-1} read into the leading rows of `out` (three C-contiguous
        float64 arrays of at least r1 - r0 rows of (n, n)); returns those rows."""
        self._open()
        views = tuple(buf[:r1 - r0] for buf in out)
        for fd, view in zip(self._fds, views):
            want = memoryview(view).cast("B")
            offset = r0 * self.row_bytes
            while want:
                got = os.preadv(fd, [want], offset)
                if got == 0:
                    raise ValueError(f"rts: a stored interval of {self.rows} rows ends before row {r1}")
                want, offset = want[got:], offset + got
        return views

    def close(self) -> None:
        """Let a named interval's file descriptors go (the files stay); an unnamed one keeps them."""
        if self.paths is None:
            return
        for k, fd in enumerate(self._fds):
            if fd is not None:
                os.close(fd)
                self._fds[k] = None

    def _open(self) -> None:
        for k, fd in enumerate(self._fds):
            if fd is None:
                self._fds[k] = os.open(self.paths[k], os.O_RDWR)


def _remove_files(fds: list, paths: list[str]) -> None:
    for fd in fds:
        if fd is not None:
            os.close(fd)
    for path in paths:
        try:
            os.remove(path)
        except FileNotFoundError:
            pass


BLOCK = 2048
"""Epochs of an interval's matrices in memory at a time, as the forward filter makes them and in rts_stored (3 x 441
floats an epoch for 001's filter: 22 MB; a pass along a 360 m face is about 0.25 GB of them)."""


def matrix_blocks(n_states: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Room for BLOCK + 1 rows of each of an interval's matrices (P_k, P_{k,k-1}, Phi_{k,k-1}): the forward filter's
    rows before they are stored, rts_stored's block read back (its last row the next block's first). Kept and used
    again from interval to interval: memory touched for the first time costs more than the work done in it."""
    return tuple(np.zeros((BLOCK + 1, n_states, n_states)) for _ in StoredInterval.KINDS)


def rts_stored(stored: StoredInterval, x_post: np.ndarray, blocks: tuple[np.ndarray, ...],
               known: tuple[np.ndarray, np.ndarray] | None = None, keep: slice = slice(0, 0)
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """rts_backward over a stored interval with a zero prediction (the closed-loop error state of the module
    docstring), a block at a time from its end (`blocks`: matrix_blocks, of any number of rows above one): x_post
    (N, n) the updates; `known` the smoothed state and covariance at the last epoch (a later interval's smoother),
    else the forward ones. Returns the smoothed states (N, n), their one-sigma (N, n), P_rts[:, keep, keep] and
    P_rts at epoch 0."""
    n_rows, n = x_post.shape
    if stored.rows != n_rows:
        raise ValueError(f"rts_stored: {stored.rows} stored epochs for {n_rows} updates")
    block = blocks[0].shape[0] - 1
    x_s, sd = np.empty_like(x_post), np.empty_like(x_post)
    kept = len(range(n)[keep])
    p_keep = np.empty((n_rows, kept, kept))
    r1 = n_rows - 1
    x_s[r1], p_last = known if known is not None else (x_post[r1], stored.read_into(r1, r1 + 1, blocks)[0][0].copy())

    def smoothed_rows(r0: int, r1: int, p: np.ndarray) -> None:
        sd[r0:r1] = one_sigma(p)
        p_keep[r0:r1] = p[:, keep, keep]

    smoothed_rows(r1, r1 + 1, p_last[None])
    x_blk = np.empty((block + 1, n))
    while r1 > 0:
        r0 = max(r1 - block, 0)
        p_post, p_pred, phi = stored.read_into(r0, r1 + 1, blocks)
        x_run = x_post[r0:r1 + 1].copy()
        x_run[-1], p_post[-1] = x_s[r1], p_last
        x_out = x_blk[:r1 + 1 - r0]
        rts_backward(x_run, p_post, np.zeros_like(x_run), p_pred, phi, x_out, p_post)  # P smoothed in place
        x_s[r0:r1] = x_out[:-1]
        smoothed_rows(r0, r1, p_post[:-1])
        p_last, r1 = p_post[0].copy(), r0
    return x_s, sd, p_keep, p_last
