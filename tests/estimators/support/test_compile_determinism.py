"""Same inputs, same bytes, however a support kernel got its machine code: compiled in a fresh process, loaded
from numba's on-disk cache, or as this process has it (estimators.support.kernel_math.FASTMATH: a prange
kernel's cached copy is optimised once more than the one its compiling process runs)."""

from __future__ import annotations

import pytest
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from estimators.support.filters_002 import kf
from tests.estimators.support.conftest import DT, exact_unit, model

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

ROOT = Path(__file__).resolve().parents[3]

RUN_KF = """
import sys
import numpy as np
from estimators.support.filters_002 import _kf_kernel
from tests.estimators.support.test_compile_determinism import run_kf
with np.load(sys.argv[1]) as d:
    np.save(sys.argv[2], run_kf(d))
print(sum(_kf_kernel.stats.cache_hits.values()))
"""
"""`run_kf` on the readings of argv[1] into argv[2]; prints how many of its kernels came from the cache."""


def run_kf(readings) -> np.ndarray:
    return kf(readings["gyro"], readings["accel"], readings["mag"], DT, model(1e-4, 1e-14), np.full(3, 3e-6))


def test_the_kf_kernel_gives_the_same_bytes_compiled_cached_and_here(tmp_path):
    rng = np.random.default_rng(7)
    _, _, w, f, m = exact_unit(100)
    readings = {"gyro": w + 1e-3 * rng.standard_normal((2,) + w.shape),
                "accel": f + 1e-2 * rng.standard_normal((2,) + f.shape),
                "mag": m + 1e-7 * rng.standard_normal((2,) + m.shape)}
    np.savez(tmp_path / "readings.npz", **readings)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    hits, runs = [], []
    for i in range(2):  # the first compiles and writes the cache, the second loads it
        out = tmp_path / f"q{i}.npy"
        r = subprocess.run([sys.executable, "-c", RUN_KF, str(tmp_path / "readings.npz"), str(out)], check=False,
                           cwd=ROOT, env=env, capture_output=True, text=True)
        assert r.returncode == 0, r.stderr[-2000:]
        hits.append(int(r.stdout.split()[-1]))
        runs.append(np.load(out))
    assert hits == [0, 1]
    here = run_kf(readings)
    for name, q in zip(("compiled", "cached"), runs):
        assert q.tobytes() == here.tobytes(), f"{name}: max |diff| {np.abs(q - here).max():.3g}"
