"""Kernels compiled ahead of their call on background processes (estimators.precompile): a later process loads them
from numba's cache without compiling."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest
from numba.core import config

from estimators.precompile import Kernel, Precompiler

pytestmark = pytest.mark.slow  # new processes that import numba and compile: over 3 s

TOY = "import numba\n\n\n@numba.njit(cache=True)\ndef scaled(x, k):\n    return x * k\n"

CALL = textwrap.dedent("""
    import numpy as np
    from numba.core import event

    compiled = []

    class Record(event.Listener):
        def on_start(self, e):
            compiled.append(e.data["dispatcher"].py_func.__name__)

        def on_end(self, e):
            pass

    event.register("numba:compile", Record())
    import toy_kernels
    toy_kernels.scaled(np.ones(3, dtype=np.{dtype}), 2)
    print(",".join(compiled))
""")


def compiled_by_a_call(tmp_path, dtype: str) -> str:
    """The kernels a new process compiles to call toy_kernels.scaled on a `dtype` array and an int."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", CALL.format(dtype=dtype)], capture_output=True, text=True,
                         check=True, env=env, cwd=tmp_path)
    return out.stdout.strip()


@pytest.fixture
def toy(tmp_path, monkeypatch):
    (tmp_path / "toy_kernels.py").write_text(TOY)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(config, "CACHE_DIR", str(tmp_path / "cache"))  # the forked processes' cache
    return tmp_path


def test_a_precompiled_kernel_loads_in_another_process_without_compiling(toy):
    with Precompiler([Kernel("toy_kernels", "scaled", "f8[::1], i8")], processes=2) as pre:
        pre.wait()
        assert not pre.compiling
    assert compiled_by_a_call(toy, "float64") == ""
    assert compiled_by_a_call(toy, "float32").startswith("scaled")  # other argument types: not in the cache


def test_a_kernel_that_does_not_compile_leaves_the_others_and_the_caller_unharmed(toy):
    kernels = [Kernel("toy_kernels", "scaled", "f8[::1], unicode_type"),  # x * "str": a typing error
               Kernel("toy_kernels", "no_such_kernel", "f8"), Kernel("toy_kernels", "scaled", "f8[::1], i8")]
    with Precompiler(kernels, processes=1) as pre:
        pre.wait()
    assert compiled_by_a_call(toy, "float64") == ""


def test_no_kernels_start_no_process():
    pre = Precompiler([], processes=2)
    assert not pre.compiling
    pre.wait()
