"""The kernels the shearer methods (estimators.shearer.methods) call from Python, with the argument types of those
calls, for estimators.precompile: a first run compiles them in the background while the twin runs.

Each with the methods that call it (None: every method, through estimators.shearer.prepare), the longest to compile
first. The kernels they call are compiled with them. A change of a listed call's argument types must be made here
too, or the call compiles again (tests/estimators/shearer/test_precompiled.py fails).
"""

from __future__ import annotations

from collections.abc import Iterable

from estimators.precompile import Kernel

_FILTER = ("kf", "kf_rts", "kf_cpoem", "kf_cpoem_rts", "rts_offline", "dr_compensated")
"""The methods that run 001's filter (odometer_filter.run_filter)."""
_SMOOTHED = ("kf_rts", "kf_cpoem_rts", "rts_offline", "dr_compensated")

KERNELS: tuple[tuple[Kernel, tuple[str, ...] | None], ...] = (
    (Kernel("estimators.shearer.odometer_filter", "run_filter",
            "i8, i8, i8, f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], i1[::1], i8[::1], f8[:, ::1], f8[:, :, ::1], "
            "f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[::1], f8[:, ::1], f8[:, ::1], f8[:, ::1], "
            "f8[:, :, ::1], f8[:, :, ::1], f8[:, :, ::1], i4[::1], f8[::1], f8[:, ::1]"), _FILTER),
    (Kernel("estimators.sins.fine_alignment", "_ekf_kernel",
            "f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8, f8[::1], f8[:, ::1], f8[::1], f8, f8[::1], "
            "f8[:, ::1], f8, f8, b1, f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[::1]"), None),
    (Kernel("estimators.sins.strapdown", "_mechanize_kernel",
            "f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], b1, i8"),
     ("dr", "dr_compensated")),
    (Kernel("estimators.kalman.rts", "rts_backward",
            "f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1]"),
     _SMOOTHED),
    (Kernel("estimators.nav.rotation_kernels", "rotvec_mat", "f8[::1]"), None),
    (Kernel("estimators.nav.rotations", "_quat_to_mat_rows", "f8[:, ::1], f8[:, :, ::1]"), None),
    (Kernel("estimators.shearer.positioning", "_apply_rows", "f8[:, ::1], f8[:, ::1], f8[:, ::1]"), _SMOOTHED),
    (Kernel("estimators.faults.ram_levels", "swings", "f8[::1], f8"), ("kf_cpoem", "kf_cpoem_rts", "rts_offline",
                                                                     "dr_compensated")),
    (Kernel("estimators.shearer.odometer_filter", "nonorth_matrix", "f8[::1]"), _FILTER),
)


def method_kernels(methods: Iterable[str]) -> tuple[Kernel, ...]:
    """The kernels `methods` call (none for no method), the longest to compile first."""
    methods = set(methods)
    if not methods:
        return ()
    return tuple(k for k, users in KERNELS if users is None or methods & set(users))
