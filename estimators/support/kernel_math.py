"""What the batched support kernels share beyond rotations (estimators.nav.rotations_scalar): their fast-math
flags and the small dense solves of their updates, in place on arrays the kernel allocated once."""

from __future__ import annotations

import numba as nb
import numpy as np

FASTMATH = {"nsz", "arcp", "contract", "afn"}
"""LLVM fast-math flags of the support kernels: contraction (FMA) and reciprocals, but no reassociation and no
finite-math assumption (nnan, ninf). A prange kernel's loop body is compiled once on its own, and the copy linked
into the kernel is optimised again: the process that compiles runs the first, the on-disk cache holds the second.
Reassociation lets that second pass reorder the sums, so a cached kernel's numbers would differ from a fresh one's
(~1e-16 to 1e-11); without it both copies do the same arithmetic and give the same bytes
(tests/estimators/support/test_compile_determinism.py)."""


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def chol4(a, out):
    """Lower Cholesky factor of a symmetric 4x4 matrix (its lower triangle is read) into out, which may be a;
    non-positive pivots are floored."""
    for j in range(4):
        s = a[j, j]
        for m in range(j):
            s -= out[j, m] * out[j, m]
        d = np.sqrt(s) if s > 1e-30 else 1e-15
        out[j, j] = d
        for i in range(j + 1, 4):
            s = a[i, j]
            for m in range(j):
                s -= out[i, m] * out[j, m]
            out[i, j] = s / d
        for i in range(j):
            out[i, j] = 0.0


@nb.njit(cache=True, inline="always", fastmath=FASTMATH)
def inv3(a, out):
    """Inverse of a 3x3 matrix (cofactors) into out."""
    out[0, 0] = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    out[0, 1] = a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]
    out[0, 2] = a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]
    out[1, 0] = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    out[1, 1] = a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]
    out[1, 2] = a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]
    out[2, 0] = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    out[2, 1] = a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]
    out[2, 2] = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    det = a[0, 0] * out[0, 0] + a[0, 1] * out[1, 0] + a[0, 2] * out[2, 0]
    for i in range(3):
        for j in range(3):
            out[i, j] /= det
