"""Assignment into array blocks inside the numba kernels, elementwise: put(dst, src) is dst[...] = src, add and
sub are dst[...] += src and -= src, for 1-D and 2-D blocks of equal shape (a view such as f[DV, PHI] or p[k]).

Why not the slice assignment itself: numba (0.60 and later) builds the error of a mismatched slice assignment,
"cannot assign slice of shape (..) from input of shape (..)", with an f-string over the shapes, and every kernel
that assigns an array into a slice (including `a[s] += b`, which numba lowers as a slice assignment) links that
string formatting in and optimizes it again at each level of its call tree. It took more time to compile than the
filters themselves (the RTS smoother: 12 s of CPU of which 7.5 s were this). These loops compile to the same
copies and sums, bit for bit, and are inlined into the caller; a shape mismatch raises ValueError with a fixed
message.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.core import types
from numba.extending import overload


def put(dst, src):
    """dst[...] = src (dst a 1-D or 2-D block, src of its shape)."""
    np.copyto(dst, src)


def add(dst, src):
    """dst[...] += src."""
    dst += src


def sub(dst, src):
    """dst[...] -= src."""
    dst -= src


_SHAPE_ERROR = "array block assignment: shapes differ"


_COMBINE = {"put": nb.njit(inline="always")(lambda d, s: s), "add": nb.njit(inline="always")(lambda d, s: d + s),
            "sub": nb.njit(inline="always")(lambda d, s: d - s)}
"""What each operation makes of the destination's element d and the source's element s."""


def _loops(ndim, op):
    """The elementwise implementation of op ('put', 'add', 'sub') for dst of ndim 1 or 2."""
    combine = _COMBINE[op]
    if ndim == 1:
        def impl(dst, src):
            if dst.shape != src.shape:
                raise ValueError(_SHAPE_ERROR)
            for i in range(dst.shape[0]):
                dst[i] = combine(dst[i], src[i])
        return impl

    def impl(dst, src):
        if dst.shape != src.shape:
            raise ValueError(_SHAPE_ERROR)
        for i in range(dst.shape[0]):
            for j in range(dst.shape[1]):
                dst[i, j] = combine(dst[i, j], src[i, j])
    return impl


def _register(func, op):
    @overload(func, inline="always")
    def _ol(dst, src):
        if isinstance(dst, types.Array) and isinstance(src, types.Array) and dst.ndim == src.ndim \
                and dst.ndim in (1, 2):
            return _loops(dst.ndim, op)
        return None


_register(put, "put")
_register(add, "add")
_register(sub, "sub")
