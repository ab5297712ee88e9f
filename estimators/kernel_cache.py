"""numba's on-disk cache of the project's kernels, invalidated by a change in any kernel's source, not only its own.

numba stamps a cached function with a hash of the one file that defines it (numba.core.caching), but a compiled
kernel holds the code of every kernel it calls, inlined at the LLVM level: after an edit of
estimators/kalman/update.py, a cached estimators/shearer/rail_fix_update.py kernel would run the old update,
silently. Here every kernel of the project (a function in a module of `estimators` or `twin` that uses numba) is
stamped with one hash over the sources of all of them, so any change to any kernel recompiles them all on the next
run; kernels of other packages keep numba's own stamp. The cache stays where numba puts it (NUMBA_CACHE_DIR if
set, else __pycache__ beside the source, else the user-wide directory).

`install` registers the locators; the packages' __init__ call it before any kernel is defined. It only sets the
locator classes numba reads when a kernel is defined (NUMBA_CACHE_LOCATOR_CLASSES), so it costs no numba import;
a value the user set is kept.
"""

from __future__ import annotations

import functools
import hashlib
import os
import sys
from pathlib import Path

PACKAGES = ("estimators", "twin")
"""The packages whose kernels share one stamp (twin's sensor kernels call estimators' rotation kernels)."""
_ROOTS = tuple(Path(__file__).resolve().parent.parent / p for p in PACKAGES)
LOCATORS = ("estimators.kernel_cache.ProjectUserProvidedLocator", "estimators.kernel_cache.ProjectInTreeLocator",
            "estimators.kernel_cache.ProjectUserWideLocator", "UserProvidedCacheLocator", "InTreeCacheLocator",
            "UserWideCacheLocator", "IPythonCacheLocator", "ZipCacheLocator")
"""The project's locators first (each declines a function outside the project), then numba's own, in its order."""


@functools.lru_cache(maxsize=8)
def kernel_sources(roots: tuple[Path, ...] = _ROOTS) -> tuple[Path, ...]:
    """The modules of `roots` that use numba, sorted (found once per process)."""
    return tuple(sorted(p for root in roots for p in root.rglob("*.py") if b"numba" in p.read_bytes()))


@functools.lru_cache(maxsize=8)
def _cached_stamp(files: tuple[tuple[str, float, int], ...], parent: str) -> str:
    digest = hashlib.sha256()
    for rel, _, _ in files:
        digest.update(rel.encode() + b"\0" + (Path(parent) / rel).read_bytes() + b"\0")
    return digest.hexdigest()


def project_stamp(roots: tuple[Path, ...] = _ROOTS) -> str:
    """One hash over the contents of every kernel module (kernel_sources) and their paths relative to the packages'
    parent; recomputed when a file's modification time or size changes."""
    parent = roots[0].parent
    files = tuple((os.path.relpath(p, parent), p.stat().st_mtime, p.stat().st_size) for p in kernel_sources(roots))
    return _cached_stamp(files, str(parent))


def in_project(py_file: str) -> bool:
    path = Path(py_file).resolve()
    return any(path.is_relative_to(root) for root in _ROOTS)


class _ProjectStamp:
    """Mixin over a numba locator: the project's stamp for the project's kernels; declines other functions."""

    def get_source_stamp(self):
        return project_stamp()

    @classmethod
    def from_function(cls, py_func, py_file):
        if not in_project(py_file):
            return None
        return super().from_function(py_func, py_file)


def _locator(name: str):
    from numba.core import caching

    return type(f"Project{name.removesuffix('CacheLocator')}Locator", (_ProjectStamp, getattr(caching, name)), {})


def __getattr__(name: str):
    """The locator classes, made on first use (numba imports this module by name when it defines a kernel)."""
    base = {"ProjectUserProvidedLocator": "UserProvidedCacheLocator", "ProjectInTreeLocator": "InTreeCacheLocator",
            "ProjectUserWideLocator": "UserWideCacheLocator"}.get(name)
    if base is None:
        raise AttributeError(f"module 'estimators.kernel_cache' has no attribute '{name}'")
    cls = _locator(base)
    globals()[name] = cls
    return cls


def install() -> None:
    """Have numba use the project's locators (LOCATORS) for kernels defined from now on."""
    if os.environ.get("NUMBA_CACHE_LOCATOR_CLASSES"):
        return  # the user's choice
    value = ",".join(LOCATORS)
    if "numba" in sys.modules:
        from numba.core import config

        if not config.CACHE_LOCATOR_CLASSES:
            config.CACHE_LOCATOR_CLASSES = value
    else:
        os.environ["NUMBA_CACHE_LOCATOR_CLASSES"] = value
