"""The one TOML reader of every kind of scenario file, and a file's kind.

Every failure is a one-line `ScenarioError` naming the file: not found, not a regular file, unreadable, not
UTF-8 text, or the TOML syntax error with its line and column.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

from twin.config.section import ScenarioError


def read_toml(path: str | Path) -> dict:
    """The TOML file at `path` as a dict."""
    path = Path(path)
    if not path.exists():
        raise ScenarioError(f"{path}: scenario file not found")
    if not path.is_file():
        raise ScenarioError(f"{path}: not a regular file (a scenario is a TOML file)")
    try:
        text = path.read_bytes().decode("utf-8")
    except OSError as err:
        raise ScenarioError(f"{path}: cannot read the file: {err.strerror}") from None
    except UnicodeDecodeError as err:
        raise ScenarioError(f"{path}: not valid TOML: not UTF-8 text (byte {err.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{path}: not valid TOML: {err}") from None


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
