"""`longwall` output safety: usage errors, --force on foreign directories, scenario names as paths, the run
directory lock, SIGTERM."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

from estimators.io.logformat import MARKER, MARKER_TEXT
from tests.conftest import SCENARIO_DIR
from twin.cli import EXIT_SIGTERM, main
from twin.pipeline import api


def short(tmp_path, name: str = "default"):
    """The default face, one cycle, named `name` (a TOML basic string is a JSON string)."""
    text = (SCENARIO_DIR / "default.toml").read_text().replace("cycles = 2", "cycles = 1")
    path = tmp_path / "short.toml"
    path.write_text(text.replace('name = "default"', f"name = {json.dumps(name)}"))
    return path


@pytest.mark.parametrize("argv", [["run", "--bogus"], ["run", "--seed", "x"], [], ["estimate"], ["frobnicate"],
                                  ["import", "somewhere"]])
def test_a_usage_error_is_one_line_exit_2(capsys, argv):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and captured.err.startswith("longwall: error: ")
    assert "--help" in captured.err


def test_help_still_prints_the_usage(capsys):
    assert main(["run", "--help"]) == 0
    assert "--force" in capsys.readouterr().out


def test_force_never_replaces_a_directory_that_holds_no_run(tmp_path, capsys):
    home = tmp_path / "home"
    (home / "photos").mkdir(parents=True)
    (home / "notes.txt").write_text("mine")
    assert main(["run", str(short(tmp_path)), "--out", str(home), "--force", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not a run directory" in err
    assert sorted(p.name for p in home.iterdir()) == ["notes.txt", "photos"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["home", "short.toml"]


@pytest.mark.parametrize("name", ["../../escaped", "a/b", "..", "x" * 300, "bell\x07", "tab\tnew\nline"])
def test_a_scenario_name_never_leads_the_run_directory_out_of_runs(tmp_path, monkeypatch, name):
    outs = []
    monkeypatch.setattr(api, "_run_face", lambda scn, source, out, *args: outs.append(out))
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(short(tmp_path, name)), "--quiet"]) == 0
    [out] = outs
    assert out.parent.as_posix() == "runs" and (tmp_path / out).resolve().parent == tmp_path / "runs"


def test_a_run_directory_being_written_is_refused_to_a_second_run_and_estimate(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "scenario.toml").write_text((SCENARIO_DIR / "default.toml").read_text())
    (out / MARKER).write_text(MARKER_TEXT)
    (tmp_path / ".out.lock").write_text(f"{os.getpid()}\n")  # a live writer
    for argv in (["run", str(short(tmp_path)), "--out", str(out), "--force", "--quiet"], ["estimate", str(out)]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "another longwall process" in err
    assert sorted(p.name for p in out.iterdir()) == sorted([MARKER, "scenario.toml"])


def test_sigterm_stops_a_run_with_one_line_exit_143_and_no_directory(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "run", str(short(tmp_path)), "--out", str(out),
                             "--quiet"], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".out.partial-*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert proc.poll() is None, proc.stderr.read()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_SIGTERM, err
    assert err.count("\n") == 1 and "SIGTERM" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]


def test_sigterm_to_estimate_and_its_workers_at_once_leaves_no_scratch_files(short_default_run, tmp_path):
    """`longwall estimate` stopped while the smoother keeps its passes on disk, SIGTERM sent to the command and its
    worker processes at once (as `pkill` or a stopped job does): exit 143, and nothing of the estimators is left in
    the temporary directory (a worker killed before its own cleanup leaves its folder to the command's)."""
    import shutil

    run, tmp = tmp_path / "run", tmp_path / "tmp"
    shutil.copytree(short_default_run, run)
    tmp.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "twin.cli", "estimate", str(run)], stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "TMPDIR": str(tmp)}, start_new_session=True)
    deadline = time.monotonic() + 120
    while not list(tmp.rglob("forward_*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert proc.poll() is None, proc.stderr.read()
    os.killpg(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXIT_SIGTERM, err
    assert list(tmp.glob("longwall-rts-*")) == []


def test_a_worker_the_system_killed_is_one_line_exit_1(short_default_run, tmp_path, monkeypatch, capsys):
    import shutil

    import twin.pipeline.estimate as estimate_module
    from estimators.workers import WorkerLost

    run = tmp_path / "run"
    shutil.copytree(short_default_run, run)

    def killed(run_dir, scn, **settings):
        raise WorkerLost("a worker process (task 1 of 4) ended without its result (SIGKILL: the system may have run "
                         "out of memory)")

    monkeypatch.setattr(estimate_module, "run_estimators", killed)
    assert main(["estimate", str(run)]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("longwall: error: a worker process (task 1 of 4)"), err


def _tree(path):
    """Every file under `path` (relative path -> bytes)."""
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def test_an_interrupted_estimate_leaves_the_run_directory_as_it_was(short_default_run, tmp_path, monkeypatch):
    """`longwall estimate` writes beside a copy of the run (estimates/, estimates.rrd, metrics.json, timing.json
    anew): interrupted half-way (Ctrl-C, or SIGTERM, which the CLI turns into the same), the run directory holds
    every file it held, byte for byte, and no staging copy is left beside it. Finished, the inputs are the same
    files (hard links), not copies."""
    import shutil

    import twin.pipeline.estimate as estimate_module

    run = tmp_path / "run"
    shutil.copytree(short_default_run, run)
    api.estimate(run)
    before = _tree(run)

    def interrupted(run_dir, scn, recording=True, **settings):
        (run_dir / "estimates").mkdir()
        (run_dir / "estimates" / "kf.parquet").write_bytes(b"half")
        raise KeyboardInterrupt

    monkeypatch.setattr(estimate_module, "run_estimators", interrupted)
    with pytest.raises(KeyboardInterrupt):
        api.estimate(run)
    assert _tree(run) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]
    monkeypatch.undo()
    inode = (run / "imu.parquet").stat().st_ino
    api.estimate(run)
    assert (run / "imu.parquet").stat().st_ino == inode and _tree(run).keys() == before.keys()


def test_cycles_overrides_the_scenario_and_names_the_run(tmp_path, monkeypatch, capsys):
    """`longwall run --cycles N`: the scenario with N cutting cycles, validated as the file's would be, into
    runs/NAME-Ncycles-seedN; an experiment, a count the schema or the panel refuses: one line, exit 2."""
    ran = []
    monkeypatch.setattr(api, "_run_face", lambda scn, source, out, *args: ran.append((scn, out)))
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(short(tmp_path)), "--cycles", "3", "--quiet"]) == 0
    [(scn, out)] = ran
    assert scn.cycles == 3 and out.as_posix() == "runs/default-3cycles-seed1"
    for argv, says in ((["--cycles", "0"], "greater than or equal to 1"), (["--cycles", "13"], "panel_length_m"),
                       ([str(SCENARIO_DIR / "seed000_coning.toml"), "--cycles", "2"], "no cutting cycles")):
        assert main(["run", *argv, "--quiet"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and says in err, err
    assert len(ran) == 1
