"""Scenario files the reader refuses in one line naming the file, beyond test_tomlfile's: not accessible, not
readable, never opened when not a regular file, too large, line breaks a file's keys bring into the message."""

from __future__ import annotations

import errno
import os

import pytest

from tests.conftest import SCENARIO_DIR
from twin.config import tomlfile
from twin.config.scenario import ScenarioError, load_scenario
from twin.config.tomlfile import MAX_BYTES, read_toml


def one_line(path, *words) -> str:
    with pytest.raises(ScenarioError) as err:
        load_scenario(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: "), message
    for word in words:
        assert word in message, message
    return message


def denied(*_args, **_kw):
    raise PermissionError(errno.EACCES, "Permission denied")


def test_a_file_in_a_locked_directory(tmp_path, monkeypatch):
    """stat fails with EACCES (a directory without search permission; as root, simulated): one line, not a
    traceback from Path.exists."""
    path = tmp_path / "locked" / "s.toml"
    monkeypatch.setattr(os, "stat", denied)
    one_line(path, "cannot access the file", "Permission denied")


def test_an_unreadable_file(tmp_path, monkeypatch):
    path = tmp_path / "s.toml"
    path.write_bytes((SCENARIO_DIR / "default.toml").read_bytes())
    if os.geteuid() != 0:
        path.chmod(0)
        one_line(path, "cannot read the file", "Permission denied")
        path.chmod(0o644)
    monkeypatch.setattr(tomlfile.os, "open", denied)
    one_line(path, "cannot read the file", "Permission denied")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_or_a_device_is_refused_without_opening_it(tmp_path, monkeypatch):
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    opened = []
    real_open = os.open
    monkeypatch.setattr(tomlfile.os, "open", lambda p, *a: opened.append(p) or real_open(p, *a))
    for path in (fifo, "/dev/zero"):
        with pytest.raises(ScenarioError, match="not a regular file"):
            read_toml(path)
    assert opened == []


def test_a_file_too_large_to_be_a_scenario_is_not_read(tmp_path):
    big = tmp_path / "big.toml"
    big.write_bytes(b"#" * (MAX_BYTES + 1))
    one_line(big, f"larger than {MAX_BYTES}")


def test_line_breaks_in_keys_and_values_stay_on_one_line(tmp_path):
    odd = tmp_path / "odd.toml"
    odd.write_text('name = "x"\n"a\\nb" = 1\n[sensors.imu]\ngrade = "no\\nsuch"\n')
    one_line(odd, "a\\nb", "unknown key")
    odd.write_text('name = "x"\n[sensors.imu]\ngrade = "no\\nsuch"\n')
    one_line(odd, "no\\nsuch")
