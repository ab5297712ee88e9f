"""The compiled loop of twin.view.rerun_columns.line_rows, in a module of its own: the project's numba cache is
stamped with every kernel module's source (estimators.kernel_cache), so the recordings' other code can change without
recompiling every kernel."""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def line_kernel(t, y, tol, must):
    """Rows of (t, y) to draw a line through so that every row left out lies within tol[j] of it in each column j
    (greedy: each segment from the last kept row is as long as the slopes allow, the swinging door of process
    historians); the first and last rows and the rows marked `must` are kept; NaN values constrain nothing."""
    n, m = y.shape
    keep = np.zeros(n, np.bool_)
    if n == 0:
        return keep
    keep[0] = keep[n - 1] = True
    lo, hi = np.empty(m), np.empty(m)
    a = 0
    while a < n - 1:
        lo[:] = -np.inf
        hi[:] = np.inf
        end, k = a + 1, a + 1
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
        keep[end] = True
        a = end
    return keep
