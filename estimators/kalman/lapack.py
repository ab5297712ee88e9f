"""np.linalg.solve and np.linalg.inv for the numba kernels' small matrices, calling the same LAPACK routines
(dgesv; dgetrf and dgetri) through numba's own wrappers with the same arguments, so the results are bit for bit
those of np.linalg in numba.

Why not np.linalg itself: numba's solve copies its right-hand side into the LAPACK scratch with a slice
assignment, and numba builds a slice assignment's shape error with an f-string over the shapes (estimators.arrays);
that string formatting is linked into every kernel above a solve and optimized again at each level of the call
tree, which cost more compile time than the filters themselves. Here the copies are loops.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.core import types
from numba.np.linalg import F_INT_nptype, _LAPACK

_KIND = ord("d")  # float64
_xgesv = _LAPACK().numba_xgesv(types.float64)
_xxgetrf = _LAPACK().numba_xxgetrf(types.float64)
_xxgetri = _LAPACK().numba_ez_xxgetri(types.float64)


@nb.njit(cache=True)
def _fortran_copy(a):
    """a (n, m) copied into a new Fortran-ordered array (LAPACK's scratch); raises np.linalg.LinAlgError on a
    NaN or an infinity, as np.linalg does."""
    n, m = a.shape
    out = np.empty((m, n)).T
    for j in range(m):
        for i in range(n):
            v = a[i, j]
            if not np.isfinite(v):
                raise np.linalg.LinAlgError("Array must not contain infs or NaNs.")
            out[i, j] = v
    return out


@nb.njit(cache=True)
def _check(r):
    if r != 0:
        raise np.linalg.LinAlgError("Matrix is singular to machine precision.")


@nb.njit(cache=True)
def _keep(a, b, c):
    """Uses the scratch arrays after the LAPACK call, so that they live until it returns (as numba's
    _dummy_liveness_func)."""
    return a + b + c


@nb.njit(cache=True)
def solve_matrix(a, b):
    """np.linalg.solve(a, b) for square a (n, n) and b (n, m): the solution (n, m), Fortran-ordered as numba's."""
    n = a.shape[0]
    if a.shape[1] != n or b.shape[0] != n:
        raise np.linalg.LinAlgError("solve: a must be square and b have its rows")
    acpy = _fortran_copy(a)
    bcpy = _fortran_copy(b)
    ipiv = np.empty(n, dtype=F_INT_nptype)
    r = _xgesv(_KIND, n, b.shape[1], acpy.ctypes, n, ipiv.ctypes, bcpy.ctypes, n)
    _check(r)
    _keep(acpy.size, bcpy.size, ipiv.size)
    return bcpy


@nb.njit(cache=True)
def solve_vector(a, b):
    """np.linalg.solve(a, b) for square a (n, n) and b (n,): the solution (n,)."""
    return solve_matrix(a, b.reshape((b.size, 1)))[:, 0].copy()


@nb.njit(cache=True)
def inv(a):
    """np.linalg.inv(a) of a square a (n, n), Fortran-ordered as numba's."""
    n = a.shape[0]
    if a.shape[1] != n:
        raise np.linalg.LinAlgError("Last 2 dimensions of the array must be square.")
    acpy = _fortran_copy(a)
    ipiv = np.empty(n, dtype=F_INT_nptype)
    r = _xxgetrf(_KIND, n, n, acpy.ctypes, n, ipiv.ctypes)
    _check(r)
    r = _xxgetri(_KIND, n, acpy.ctypes, n, ipiv.ctypes)
    _check(r)
    _keep(acpy.size, ipiv.size, 0)
    return acpy
