"""The kernels the shearer methods call, listed with their calls' argument types (estimators.shearer.precompiled): a
first run compiles them ahead, so a listed type that no longer matches the call would compile them twice."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys

import pytest

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


_FIRST_COMPILE = """
from estimators.shearer.precompiled import FILTER_CALLS, RUN_FILTER
RUN_FILTER.dispatcher().compile(RUN_FILTER.signature())
print([k.name for k in FILTER_CALLS if k.signature() not in k.dispatcher().signatures])
"""


def test_run_filter_calls_the_listed_kernels_with_the_listed_argument_types(tmp_path):
    # run_filter's first compile, in a process of its own with an empty cache: loaded from a cache, a kernel
    # compiles none of the kernels it calls, so only a first compile shows the types of their calls.
    done = subprocess.run([sys.executable, "-c", _FIRST_COMPILE], capture_output=True, text=True, check=True,
                          env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)})
    assert done.stdout.strip() == "[]", f"not compiled for their listed types: {done.stdout}"


def test_the_methods_kernels():
    assert method_kernels(()) == ()
    dr = method_kernels(["dr"])
    assert {k.name for k in dr} == {"_ekf_kernel", "_mechanize_kernel", "_compensate_kernel", "rotvec_mat",
                                    "_quat_to_mat_rows"}
    every = method_kernels(METHODS)
    assert len(every) == len(KERNELS)
    # run_filter after the kernels it calls (each compiled once, then loaded by it from the cache).
    assert every.index(RUN_FILTER) == len(FILTER_CALLS) and set(every[:len(FILTER_CALLS)]) == set(FILTER_CALLS)
