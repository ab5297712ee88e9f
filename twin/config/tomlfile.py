"""The one TOML reader of every kind of scenario file, and a file's kind.

Every failure is a one-line `ScenarioError` naming the file: not found, not accessible, not a regular file
(a FIFO, a device or a directory is refused from its status, never opened), larger than MAX_BYTES, unreadable,
not UTF-8 text, or the TOML syntax error with its line and column.
"""

from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path

from twin.config.section import ScenarioError

MAX_BYTES = 1 << 20
"""Largest scenario file read [bytes]: the largest shipped one is 4 kB, a 400-pan bend list 4 kB more; a bigger
file is not a scenario (and is not read into memory)."""


def read_toml(path: str | Path) -> dict:
    """The TOML file at `path` as a dict."""
    path = Path(path)
    try:
        status = os.stat(path)
    except FileNotFoundError:
        raise ScenarioError(f"{path}: scenario file not found") from None
    except OSError as err:
        raise ScenarioError(f"{path}: cannot access the file: {err.strerror}") from None
    _check_regular(path, status)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # never blocks, should it now be a FIFO
        with os.fdopen(fd, "rb") as f:
            _check_regular(path, os.fstat(f.fileno()))
            data = f.read(MAX_BYTES + 1)
    except OSError as err:
        raise ScenarioError(f"{path}: cannot read the file: {err.strerror}") from None
    if len(data) > MAX_BYTES:  # grown since the stat
        raise ScenarioError(f"{path}: larger than {MAX_BYTES} bytes; not a scenario file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as err:
        raise ScenarioError(f"{path}: not valid TOML: not UTF-8 text (byte {err.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{path}: not valid TOML: {err}") from None


def _check_regular(path: Path, status: os.stat_result) -> None:
    if not stat.S_ISREG(status.st_mode):
        raise ScenarioError(f"{path}: not a regular file (a scenario is a TOML file)")
    if status.st_size > MAX_BYTES:
        raise ScenarioError(f"{path}: {status.st_size} bytes, larger than {MAX_BYTES}; not a scenario file")


def read_scenario(path: str | Path, seed: int | None = None) -> dict:
    """A scenario file's data, with `seed` (when given) in place of the file's seed."""
    data = read_toml(path)
    if seed is not None:
        data["seed"] = seed
    return data


def file_kind(path: str | Path) -> str | None:
    """The top-level `kind` of a scenario file (None when absent: a face scenario, or when unreadable)."""
    try:
        return read_toml(path).get("kind")
    except ScenarioError:
        return None
