"""The compiled loop of twin.view.row_cuts.line_rows, in a module of its own: the project's numba cache is
stamped with every kernel module's source (estimators.kernel_cache), so the recordings' other code can change without
recompiling every kernel."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def line_kernel(t, y, tol, must, lo, hi, start, final):
    """Rows of (t, y) to draw a line through so that every row left out lies within tol[j] of it in each column j
    (greedy: each segment from the last kept row is as long as the slopes allow, the swinging door of process
    historians); the first row, the last (when `final`) and the rows marked `must` are kept; NaN values constrain
    nothing.

    Resumable, for a series given in blocks (twin.view.row_cuts.LineCut): row 0 is the anchor of the segment in
    progress and rows 1 .. start - 1 were scanned from it already, narrowing the slope bounds lo, hi (start 1: a fresh
    anchor). Without `final` the scan stops at the last row without keeping it; lo and hi are left as they are then.
    Returns (keep (n,) bool, anchor, last row scanned from it): the rows to pass back as rows 0 (and 1) with the
    series' next rows."""
    n, m = y.shape
    keep = np.zeros(n, np.bool_)
    if n == 0:
        return keep, 0, 0
    keep[0] = True
    if final:
        keep[n - 1] = True
    a, k0 = 0, start
    while a < n - 1:
        if k0 == a + 1:
            lo[:] = -np.inf
            hi[:] = np.inf
        end, k = k0 - 1, k0
        while k < n:
            dt = t[k] - t[a]
            if k > a + 1:  # the line from a to k must pass within tol of the rows between
                if dt <= 0.0:
                    break
                ok = True
                for j in range(m):
                    if not (np.isnan(y[k, j]) or np.isnan(y[a, j])):
                        s = (y[k, j] - y[a, j]) / dt
                        if s < lo[j] or s > hi[j]:
                            ok = False
                            break
                if not ok:
                    break
            end = k
            if must[k] or dt <= 0.0:
                break
            for j in range(m):
                if not (np.isnan(y[k, j]) or np.isnan(y[a, j])):
                    lo[j] = max(lo[j], (y[k, j] - tol[j] - y[a, j]) / dt)
                    hi[j] = min(hi[j], (y[k, j] + tol[j] - y[a, j]) / dt)
            k += 1
        if k == n and not final:  # the segment goes on in the next block
            return keep, a, end
        keep[end] = True
        a, k0 = end, end + 1
    return keep, a, a
