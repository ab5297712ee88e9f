"""The kernels the shearer methods call, listed with their calls' argument types (estimators.shearer.precompiled): a
first run compiles them ahead, so a listed type that no longer matches the call would compile them twice."""

from __future__ import annotations

import dataclasses

import pytest
from numba.core.compiler import run_frontend
from numba.core.registry import cpu_target
from numba.core.typed_passes import type_inference_stage

from estimators.shearer.methods import METHODS, estimate
from estimators.shearer.precompiled import FILTER_CALLS, KERNELS, RUN_FILTER, method_kernels
from tests.estimators.shearer.test_independent_trajectories import NOISY, trajectory

pytestmark = pytest.mark.slow  # runs every method (over 3 s with the kernels in the cache)


def test_each_listed_kernel_is_called_with_the_listed_argument_types():
    traj = trajectory("az45_eq")
    errors = dataclasses.replace(NOISY, seed=7)
    listed = tuple(m for m in METHODS if any(users and m in users for _, users in KERNELS))
    estimate(traj.log(errors), traj.config(errors), listed, workers=1)
    for kernel, _ in KERNELS:
        if kernel not in FILTER_CALLS:  # called by run_filter, which the methods may load from the cache
            assert kernel.signature() in kernel.dispatcher().signatures, kernel


def test_run_filter_calls_the_listed_kernels_with_the_listed_argument_types():
    run_filter = RUN_FILTER
    # Typed afresh (as its first compile does, not loaded from the cache), run_filter compiles or loads the
    # kernels it calls for the argument types of its calls.
    typing, target = cpu_target.typing_context, cpu_target.target_context
    type_inference_stage(typing, target, run_frontend(run_filter.dispatcher().py_func), run_filter.signature(), None)
    for kernel in FILTER_CALLS:
        assert kernel.signature() in kernel.dispatcher().signatures, kernel


def test_the_methods_kernels():
    assert method_kernels(()) == ()
    dr = method_kernels(["dr"])
    assert {k.name for k in dr} == {"_ekf_kernel", "_mechanize_kernel", "_compensate_kernel", "rotvec_mat",
                                    "_quat_to_mat_rows"}
    every = method_kernels(METHODS)
    assert len(every) == len(KERNELS)
    # run_filter after the kernels it calls (each compiled once, then loaded by it from the cache).
    assert every.index(RUN_FILTER) == len(FILTER_CALLS) and set(every[:len(FILTER_CALLS)]) == set(FILTER_CALLS)
