"""Damaged run directories and edited scenario.toml files through `longwall estimate` and `longwall report`: one line,
exit 2, refused before any work (twin.pipeline.log_layout, estimators.io.run_check)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from estimators.io.logformat import ESTIMATES_DIR
from twin.cli import main
from twin.config.scenario import load_face_scenario
from twin.pipeline.log_layout import check_run_dir


@pytest.fixture
def run_dir(short_default_run, tmp_path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(short_default_run, out)
    return out


def _refused(argv: list[str], capsys, *needles: str) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("longwall: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, (needle, err)
    return err


def _edit(run_dir: Path, pattern: str, replacement: str) -> None:
    path = run_dir / "scenario.toml"
    text, n = re.subn(pattern, replacement, path.read_text(), count=1, flags=re.MULTILINE)
    assert n == 1, pattern
    path.write_text(text)


def test_the_short_default_run_agrees_with_its_scenario(run_dir):
    check_run_dir(run_dir, load_face_scenario(run_dir / "scenario.toml"))


def test_garbage_metrics_json_refused_before_estimating(run_dir, capsys):
    (run_dir / "metrics.json").write_text("garbage{")
    _refused(["estimate", str(run_dir), "--quiet"], capsys, "metrics.json", "not valid JSON", "move the damaged file")
    assert not (run_dir / ESTIMATES_DIR).exists(), "no work before the refusal"
    assert (run_dir / "metrics.json").read_text() == "garbage{"
    _refused(["report", str(run_dir)], capsys, "metrics.json", "not valid JSON")


def test_truncated_estimate_refused_by_report(run_dir, capsys):
    (run_dir / ESTIMATES_DIR).mkdir()
    (run_dir / ESTIMATES_DIR / "kf.parquet").write_bytes(b"PAR1" + bytes(100))
    _refused(["report", str(run_dir)], capsys, "kf.parquet", "not a readable Parquet file", "longwall estimate")


def test_truncated_stream_refused_by_estimate(run_dir, capsys):
    path = run_dir / "odometer.parquet"
    path.write_bytes(path.read_bytes()[:-50])
    _refused(["estimate", str(run_dir), "--quiet"], capsys, "odometer.parquet", "not a readable Parquet file",
             "import the recording again")


@pytest.mark.parametrize("pattern, replacement, needles", [
    (r"^pans_per_support = 1$", "pans_per_support = 2", ("pushram.parquet", "rows for supports 22-43", "22 supports")),
    (r"^(\[sensors\.imu\]\n(?:.*\n)*?)rate_hz = 200\.0$", r"\1rate_hz = 100.0",
     ("imu.parquet", "200 Hz", "[sensors.imu] rate_hz = 100")),
    (r"^(\[sensors\.odometer\]\n)rate_hz = 50\.0$", r"\1rate_hz = 10.0", ("odometer.parquet", "50 Hz")),
    (r"^(\[sensors\.pushram\]\n)rate_hz = 1\.0$", r"\1rate_hz = 2.0", ("pushram.parquet", "1 Hz")),
])
def test_edited_scenario_refused_by_estimate(run_dir, capsys, pattern, replacement, needles):
    _edit(run_dir, pattern, replacement)
    _refused(["estimate", str(run_dir), "--quiet"], capsys, *needles)
    assert not (run_dir / ESTIMATES_DIR).exists()
