"""numba's cache of the project's kernels: one stamp over every kernel module (estimators.kernel_cache)."""

from __future__ import annotations

import os
import subprocess
import sys

from estimators import kernel_cache


def make_packages(root):
    (root / "estimators" / "kalman").mkdir(parents=True)
    (root / "twin").mkdir()
    (root / "estimators" / "kalman" / "update.py").write_text("import numba\n\n@numba.njit(cache=True)\ndef f(x):\n"
                                                              "    return x + 1\n")
    (root / "estimators" / "shearer.py").write_text("import numba\nfrom estimators.kalman.update import f\n")
    (root / "twin" / "report.py").write_text("def page():\n    return 'no kernels here'\n")
    return tuple(root / p for p in kernel_cache.PACKAGES)


def test_a_change_to_any_kernel_module_changes_every_kernels_stamp(tmp_path):
    """A callee's edit (update.py) must reach its cached caller (shearer.py, unchanged): the stamp is shared."""
    roots = make_packages(tmp_path)
    assert [p.name for p in kernel_cache.kernel_sources(roots)] == ["update.py", "shearer.py"]
    before = kernel_cache.project_stamp(roots)
    assert kernel_cache.project_stamp(roots) == before  # stable
    (roots[1] / "report.py").write_text("def page():\n    return 'still no kernels'\n")
    assert kernel_cache.project_stamp(roots) == before  # a module without kernels does not count
    update = roots[0] / "kalman" / "update.py"
    update.write_text(update.read_text().replace("x + 1", "x + 2"))
    os.utime(update, (1, 1))  # another modification time as well, as an edit gives
    assert kernel_cache.project_stamp(roots) != before


def test_the_projects_kernels_use_the_project_stamp_and_others_keep_numbas(tmp_path):
    from estimators.shearer import odometer_filter
    from twin.sensors import imu

    for kernel in (odometer_filter.run_filter, imu._increments_kernel):
        locator = kernel._cache._impl.locator
        assert isinstance(locator, kernel_cache._ProjectStamp), type(locator)
        assert locator.get_source_stamp() == kernel_cache.project_stamp()
    foreign = tmp_path / "foreign.py"
    foreign.write_text("import numba\n\n@numba.njit(cache=True)\ndef g(x):\n    return x\n"
                       "print(type(g._cache._impl.locator).__name__)\n")
    code = f"import estimators, runpy; runpy.run_path({str(foreign)!r})"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # numba's own choice without a user's dir
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.strip() == "InTreeCacheLocator"


def test_the_users_locator_setting_is_kept():
    code = "import estimators, os; print(os.environ['NUMBA_CACHE_LOCATOR_CLASSES'])"
    env = {**os.environ, "NUMBA_CACHE_LOCATOR_CLASSES": "InTreeCacheLocator"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env).stdout
    assert out.strip() == "InTreeCacheLocator"
