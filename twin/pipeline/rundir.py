"""Run directories: named safely, marked as ours, locked while written, written atomically.

Everything is written into a hidden sibling `.NAME.partial-XXXX` and renamed to NAME only when complete, so
a crash, an interrupt or a SIGTERM never leaves a directory that looks like a finished run. Every run
directory holds the MARKER file; an existing non-empty directory is refused unless `force`, and even then
replaced only if it holds the marker (never a directory of somebody's files), and only after the new run is
complete. While a directory is written, the lock file `.NAME.lock` beside it holds the writer's pid: a second
writer is refused, a lock left by a killed process is taken over.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from estimators.io.logformat import MARKER, MARKER_TEXT

TIMING = "timing.json"
"""Wall-clock figures of a run (they differ from run to run, so they stay out of metrics.json)."""
MAX_NAME = 80
"""Longest directory name made from a scenario name (file systems allow 255 bytes)."""


class RunDirError(ValueError):
    """The run directory cannot be written; one line saying why and how to fix it."""


def safe_name(name: str) -> str:
    """`name` as one directory name: characters other than letters, digits, `.`, `_` and `-` (path separators,
    `..`, control characters) become `_`, no leading dot, at most MAX_NAME characters; a changed name gets a
    short hash of the original so that two names never meet."""
    clean = re.sub(r"[^A-Za-z0-9._-]", "_", name).lstrip(".")[:MAX_NAME] or "scenario"
    if clean == name:
        return name
    return f"{clean[:MAX_NAME - 9]}-{hashlib.sha256(name.encode()).hexdigest()[:8]}"


def default_run_dir(name: str, seed: int) -> Path:
    """runs/NAME-seedN, with the scenario name made safe (safe_name)."""
    return Path("runs") / f"{safe_name(name)}-seed{seed}"


def check_target(path: Path, force: bool) -> None:
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise RunDirError(f"{path}: exists and is not a directory; choose another --out")
    if not path.is_dir() or not any(path.iterdir()):
        return
    if not force:
        raise RunDirError(f"{path}: directory exists and is not empty; use --force to replace it or choose "
                          f"another --out")
    if not (path / MARKER).is_file():
        raise RunDirError(f"{path}: not a run directory (no {MARKER} file), so --force will not replace it; "
                          f"choose another --out or remove it yourself")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # somebody else's live process
    return True


@contextmanager
def run_lock(path: Path) -> Iterator[None]:
    """Hold the lock of run directory `path` (the file `.NAME.lock` beside it, holding our pid) while the
    block runs; RunDirError if a live process holds it. A lock whose process is gone is taken over."""
    path = Path(path)
    lock = path.parent / f".{path.name}.lock"
    for _ in range(2):
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            break
        except FileExistsError:
            try:
                pid = int(lock.read_text().strip() or 0)
            except (OSError, ValueError):
                pid = 0
            if not pid:  # being written this instant, or by a process killed in that instant
                raise RunDirError(f"{path}: locked by {lock}; remove it if no longwall process is running") from None
            if _pid_alive(pid):
                raise RunDirError(f"{path}: another longwall process (pid {pid}) is writing it; wait for it to "
                                  f"finish or choose another --out") from None
            lock.unlink(missing_ok=True)  # stale: its process is gone
        except OSError as err:
            raise RunDirError(f"{path}: cannot write there ({err.strerror}: {err.filename}); choose another "
                              f"directory") from None
    else:
        raise RunDirError(f"{path}: locked by {lock}; remove it if no longwall process is running")
    try:
        os.write(fd, f"{os.getpid()}\n".encode())
        os.close(fd)
        yield
    finally:
        lock.unlink(missing_ok=True)


@contextmanager
def atomic_run_dir(path: Path, force: bool = False) -> Iterator[Path]:
    """Yield a staging directory holding MARKER; on success it becomes `path` (replacing it when `force`
    and check_target allows). The lock on `path` is held throughout."""
    path = Path(path)
    with run_lock(path):
        check_target(path, force)
        staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.partial-", dir=path.parent))
        try:
            staging.chmod(0o777 & ~_umask())  # as mkdir makes it (mkdtemp: owner only)
            (staging / MARKER).write_text(MARKER_TEXT)
            yield staging
            check_target(path, force)  # a directory something other than longwall made meanwhile
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        _swap_in(staging, path)


@contextmanager
def staged_update(path: Path, fresh: tuple[str, ...], copied: tuple[str, ...]) -> Iterator[Path]:
    """Yield a staging copy of run directory `path` to rewrite some of it in: every file hard-linked (copied where
    the file system cannot link), but the top-level entries `fresh` left out (written anew) and `copied` copied
    (updated in place, which a link would pass through to `path`). On success the copy replaces `path`
    (_swap_in); on any exception, SIGTERM included, `path` is left as it was, and an error message naming a file of the
    copy names it in `path` (the user's directory, not a scratch one). The caller holds run_lock."""
    path = Path(path)
    staging = Path(tempfile.mkdtemp(prefix=f".{path.name}.partial-", dir=path.parent))
    try:
        staging.chmod(path.stat().st_mode & 0o7777)
        for src in sorted(path.rglob("*")):
            rel = src.relative_to(path)
            dst = staging / rel
            if rel.parts[0] in fresh:
                continue
            if src.is_dir():
                dst.mkdir(parents=True, exist_ok=True)
            elif rel.parts[0] in copied:
                shutil.copy2(src, dst)
            else:
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)
        yield staging
    except BaseException as err:
        shutil.rmtree(staging, ignore_errors=True)
        if len(err.args) == 1 and isinstance(err.args[0], str):
            err.args = (err.args[0].replace(str(staging), str(path)),)
        raise
    _swap_in(staging, path)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _swap_in(staging: Path, path: Path) -> None:
    """Rename `staging` to `path`, the old `path` out of the way first; Ctrl-C and SIGTERM wait until both
    renames are done (never the old run gone and the new one not yet there)."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        trash = None
        if path.exists():
            trash = Path(tempfile.mkdtemp(prefix=f".{path.name}.old-", dir=path.parent))
            path.rename(trash / path.name)
        staging.rename(path)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    if trash is not None:
        shutil.rmtree(trash, ignore_errors=True)


def write_timing(run_dir: Path, **figures) -> None:
    """Wall-clock figures (seconds, rates; or a section of them) into run_dir/TIMING, beside those it holds: the
    one file of a run directory that differs from run to run (metrics.json holds none)."""
    path = Path(run_dir) / TIMING
    try:
        held = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError):
        held = {}
    path.write_text(json.dumps({**(held if isinstance(held, dict) else {}), **figures}, indent=2) + "\n")
