"""The kernels the shearer methods (estimators.shearer.methods) call from Python, with the argument types of those
calls, for estimators.precompile: a first run compiles them in the background while the twin runs.

Each with the methods that call it (None: every method, through estimators.shearer.prepare), the longest to compile
first. The kernels they call are compiled with them, but for run_filter's longest (FILTER_CALLS), which are listed
on their own, before it, so that two processes share its compile. A change of a listed call's argument types must
be made here too, or the call compiles again (tests/estimators/shearer/test_precompiled.py fails).
"""

from __future__ import annotations

from collections.abc import Iterable

from estimators.kalman.error_state import N_STATES
from estimators.precompile import F8_1D, F8_2D, Kernel

_FILTER = ("kf", "kf_rts", "kf_cpoem", "kf_cpoem_rts", "rts_offline", "dr_compensated")
"""The methods that run 001's filter (odometer_filter.run_filter)."""
_SMOOTHED = ("kf_rts", "kf_cpoem_rts", "rts_offline", "dr_compensated")

FILTER_CALLS = (
    Kernel("estimators.kalman.update", "gated_update", f"{F8_1D}, {F8_2D}, {F8_1D}, {F8_2D}, {F8_2D}, f8"),
    Kernel("estimators.kalman.measurements", "odometer_velocity",
           f"{F8_1D}, {F8_1D}, {F8_1D}, {F8_1D}, {F8_1D}, f8, f8, {F8_1D}, {F8_2D}, f8, i8"),
    Kernel("estimators.sins.error_model", "navigation_block", f"{F8_2D}, {F8_1D}, {F8_1D}"),
    Kernel("estimators.sins.error_model", "feed_back_navigation", f"{F8_1D}, {F8_1D}"),
    Kernel("estimators.kalman.measurements", "zero_rate", f"{F8_1D}, {F8_1D}, f8, f8, i8"),
    Kernel("estimators.kalman.measurements", "position_fix",
           f"{F8_1D}, {F8_1D}, {F8_1D}, {F8_2D}, IntegerLiteral({N_STATES})"),
    Kernel("estimators.sins.error_model", "bias_blocks", f"{F8_2D}, {F8_2D}"),
    Kernel("estimators.kalman.measurements", "zero_velocity", f"{F8_1D}, f8, {F8_1D}, f8, i8"),
    Kernel("estimators.kalman.update", "joseph_update", f"{F8_1D}, {F8_2D}, {F8_1D}, {F8_2D}, {F8_2D}"),
)
"""The kernels run_filter calls with the argument types of its calls, the longest first (but joseph_update,
which gated_update calls: the cache has it when it comes up). Listed before run_filter,
the two processes of a first run compile them between them (about 7 s each), then run_filter on one (loading them
from the cache) beside the fine alignment's EKF on the other, each about 13 s: each kernel is compiled about once.
(With run_filter listed first, its process compiled most of them itself while the other compiled them too, and
listed after the EKF, run_filter waited for the callees the EKF shares.)
IntegerLiteral: N_STATES, a global constant, which numba types as a literal."""

RUN_FILTER = Kernel("estimators.shearer.odometer_filter", "run_filter",
                    "i8, i8, i8, i8, f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], i1[::1], i8[::1], f8[:, ::1], "
                    "f8[:, :, ::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[::1], f8[:, ::1], "
                    "f8[:, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, :, ::1], f8[:, :, ::1], i4[::1], f8[::1], f8[:, ::1]")
"""001's filter (estimators.shearer.odometer_filter), the longest compile of a first run."""

KERNELS: tuple[tuple[Kernel, tuple[str, ...] | None], ...] = (
    *((kernel, _FILTER) for kernel in FILTER_CALLS),
    (RUN_FILTER, _FILTER),
    (Kernel("estimators.sins.fine_alignment", "_ekf_kernel",
            "f8[:, ::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8, f8[::1], f8[:, ::1], f8[::1], f8, f8[::1], "
            "f8[:, ::1], f8, f8, b1, f8[:, :, ::1], f8[:, ::1], f8[:, ::1], f8[::1]"), None),
    (Kernel("estimators.sins.strapdown", "_mechanize_kernel",
            "f8[::1], f8[:, ::1], f8[:, ::1], f8[::1], f8[::1], f8[::1], f8[:, ::1], f8[:, ::1], b1, i8"),
     ("dr", "dr_compensated")),
    (Kernel("estimators.kalman.rts", "rts_backward",
            "f8[:, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1], f8[:, :, ::1], f8[:, ::1], f8[:, :, ::1]"),
     _SMOOTHED),
    (Kernel("estimators.sins.strapdown", "_compensate_kernel", f"{F8_2D}, {F8_2D}, {F8_1D}, {F8_2D}, {F8_2D}"), None),
    (Kernel("estimators.nav.rotation_kernels", "rotvec_mat", "f8[::1]"), None),
    (Kernel("estimators.nav.rotations", "_quat_to_mat_rows", "f8[:, ::1], f8[:, :, ::1]"), None),
    (Kernel("estimators.shearer.positioning", "_apply_rows", "f8[:, ::1], f8[:, ::1], f8[:, ::1]"), _SMOOTHED),
    (Kernel("estimators.faults.ram_levels", "swings", "f8[::1], f8"), ("kf_cpoem", "kf_cpoem_rts", "rts_offline",
                                                                     "dr_compensated")),
    (Kernel("estimators.shearer.odometer_filter", "nonorth_matrix", "f8[::1]"), _FILTER),
)
"""Each kernel with the methods that call it, in the order a pool of processes takes them up."""


def method_kernels(methods: Iterable[str]) -> tuple[Kernel, ...]:
    """The kernels `methods` call (none for no method), in KERNELS' order."""
    methods = set(methods)
    if not methods:
        return ()
    return tuple(k for k, users in KERNELS if users is None or methods & set(users))
