"""The one TOML reader of scenario files (twin.config.tomlfile): every failure is one line naming the file."""

from __future__ import annotations

import os

import pytest

from tests.conftest import SCENARIO_DIR
from twin.cli import main
from twin.config.scenario import ScenarioError
from twin.config.tomlfile import file_kind, read_scenario, read_toml


def bad_files(tmp_path) -> dict:
    """One file per failure of the reader, with the words its error names."""
    syntax = tmp_path / "syntax.toml"
    syntax.write_text('name = "x"\ncycles = \n')
    latin = tmp_path / "latin.toml"
    latin.write_bytes('name = "Förderer"\n'.encode("latin-1"))
    folder = tmp_path / "folder.toml"
    folder.mkdir()
    files = {"missing": (tmp_path / "missing.toml", "scenario file not found"),
             "syntax": (syntax, "not valid TOML: Invalid value (at line 2"),
             "latin": (latin, "not valid TOML: not UTF-8 text"),
             "folder": (folder, "not a regular file")}
    if hasattr(os, "mkfifo"):
        fifo = tmp_path / "fifo.toml"
        os.mkfifo(fifo)
        files["fifo"] = (fifo, "not a regular file")
    return files


@pytest.mark.parametrize("case", ["missing", "syntax", "latin", "folder", "fifo"])
def test_every_failure_is_one_line_naming_the_file(tmp_path, capsys, case):
    files = bad_files(tmp_path)
    if case not in files:
        pytest.skip("no FIFOs here")
    path, words = files[case]
    with pytest.raises(ScenarioError) as err:
        read_toml(path)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"{path}: ") and words in message, message
    assert file_kind(path) is None
    assert main(["run", str(path), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    out = capsys.readouterr().err
    assert out.count("\n") == 1 and words in out, out
    assert not (tmp_path / "run").exists()


def test_kind_and_seed():
    assert file_kind(SCENARIO_DIR / "default.toml") is None
    assert file_kind(SCENARIO_DIR / "seed000_coning.toml") == "sins_experiment"
    assert file_kind(SCENARIO_DIR / "seed002_turntable.toml") == "support_turntable"
    assert read_scenario(SCENARIO_DIR / "default.toml", seed=9)["seed"] == 9
