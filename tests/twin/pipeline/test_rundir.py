"""Run directories: safe names, the marker --force needs, the lock, atomic writes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from estimators.io.logformat import MARKER, LogError
from twin.pipeline.rundir import (
    MAX_NAME,
    RunDirError,
    atomic_run_dir,
    check_target,
    default_run_dir,
    run_lock,
    safe_name,
    staged_update,
)


@pytest.mark.parametrize("name", ["../../etc/passwd", "a/b", "a\\b", "..", ".hidden", "x\x00y", "tab\there",
                                  "esc\x1b[31m", "new\nline", "x" * 1000, "", "/", "ü-umlaut", "C:evil"])
def test_a_scenario_name_becomes_one_safe_directory_under_runs(name):
    path = default_run_dir(name, 3)
    assert path.parent == Path("runs") and path.name.endswith("-seed3")
    part = safe_name(name)
    assert part and len(part) <= MAX_NAME and not part.startswith(".")
    assert set(part) <= set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-")


def test_safe_names_keep_plain_names_and_never_merge_two_names():
    assert safe_name("seed001_interference") == "seed001_interference"
    assert len({safe_name(n) for n in ("a/b", "a_b", "a\\b", "a b")}) == 4


def test_force_refuses_a_directory_that_is_not_a_run_directory(tmp_path):
    home = tmp_path / "home"
    home.mkdir()
    (home / "thesis.tex").write_text("years of work")
    with pytest.raises(RunDirError, match=MARKER):
        check_target(home, force=True)
    with pytest.raises(RunDirError, match=MARKER), atomic_run_dir(home, force=True) as staging:
        (staging / "x").write_text("new")
    assert [p.name for p in home.iterdir()] == ["thesis.tex"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["home"]  # no staging, no lock left


def test_force_replaces_a_marked_run_directory(tmp_path):
    out = tmp_path / "run"
    with atomic_run_dir(out) as staging:
        (staging / "old").write_text("1")
    assert (out / MARKER).is_file()
    with atomic_run_dir(out, force=True) as staging:
        (staging / "new").write_text("2")
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, "new"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_a_failed_write_leaves_neither_directory_nor_lock(tmp_path):
    with pytest.raises(KeyboardInterrupt), atomic_run_dir(tmp_path / "run") as staging:
        (staging / "half").write_text("x")
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


def test_a_second_writer_is_refused_while_the_first_holds_the_lock(tmp_path):
    out = tmp_path / "run"
    with run_lock(out):
        with pytest.raises(RunDirError, match=f"pid {os.getpid()}"), run_lock(out):
            pass
        with pytest.raises(RunDirError, match="another longwall process"), atomic_run_dir(out):
            pass
    with run_lock(out):  # released
        pass


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    out = tmp_path / "run"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    (tmp_path / ".run.lock").write_text(f"{dead.pid}\n")
    with atomic_run_dir(out) as staging:
        assert (tmp_path / ".run.lock").read_text().strip() == str(os.getpid())
        (staging / "x").write_text("1")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]


def test_an_error_in_a_staged_update_names_the_run_directory_not_the_copy(tmp_path):
    """A one-line error about a file of the staging copy (a bad row of a stream the estimators read) names the file
    where the user has it; the run directory is left as it was."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "imu.parquet").write_text("x")
    with pytest.raises(LogError) as err:
        with staged_update(run, fresh=(), copied=()) as staging:
            raise LogError(f"{staging / 'imu.parquet'}: column 'dv_y' row 7: not a finite number")
    assert str(err.value) == f"{run / 'imu.parquet'}: column 'dv_y' row 7: not a finite number"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"] and (run / "imu.parquet").read_text() == "x"
