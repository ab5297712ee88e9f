"""Run directories, written atomically.

Everything is written into a hidden sibling `.NAME.partial-XXXX` and renamed to NAME only when complete, so
a crash or an interrupt never leaves a directory that looks like a finished run. An existing non-empty
directory is refused unless `force`, and then replaced only after the new run is complete.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


class RunDirError(ValueError):
    """The run directory cannot be written; one line saying why and how to fix it."""


def check_target(path: Path, force: bool) -> None:
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise RunDirError(f"{path}: exists and is not a directory; choose another --out")
    if path.is_dir() and any(path.iterdir()) and not force:
        raise RunDirError(f"{path}: directory exists and is not empty; use --force to replace it or choose "
                          f"another --out")


@contextmanager
def atomic_run_dir(path: Path, force: bool = False) -> Iterator[Path]:
    """Yield a staging directory; on success it becomes `path` (replacing it when `force`)."""
    path = Path(path)
    check_target(path, force)
    path.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.partial-", dir=path.parent))
    try:
        yield staging
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    if path.exists():
        trash = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=path.parent))
        path.rename(trash / path.name)
        staging.rename(path)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        staging.rename(path)
