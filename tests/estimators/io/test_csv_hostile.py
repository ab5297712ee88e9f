"""Hostile CSV logs through `longwall import` (estimators.io.csv_import's policy): malformed directories made from one
exported default run are refused in one line with nothing written, or imported with the flag in the summary; the
reader's memory does not grow with the file."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv
import pytest

from estimators.io.csvio import header_name
from estimators.io.logformat import IMU, MARKER, make_table, stream_writer
from estimators.io.time_steps import time_steps
from twin.cli import main
from twin.pipeline.rundir import check_target

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


@pytest.fixture(scope="module")
def exported(short_default_run, tmp_path_factory) -> Path:
    """The short default run exported with `longwall export` (truth files left out: a real recording's layout)."""
    out = tmp_path_factory.mktemp("exported") / "csv"
    assert main(["export", str(short_default_run), "--csv", str(out)]) == 0
    for p in out.glob("truth_*.csv"):
        p.unlink()
    return out


def _lines(d: Path, name: str) -> list[str]:
    return (d / name).read_text().splitlines()


def _put(d: Path, name: str, lines: list[str], end: str = "\n") -> None:
    (d / name).write_text("\n".join(lines) + end)


def _field(d: Path, name: str, row: int, column: str, value: str) -> None:
    """Set `column` of data row `row` (1-based) of `name`."""
    lines = _lines(d, name)
    index = [h.split("[")[0] for h in lines[0].split(",")].index(column)
    fields = lines[row].split(",")
    fields[index] = value
    lines[row] = ",".join(fields)
    _put(d, name, lines)


def _swap(d: Path, name: str, row: int) -> None:
    lines = _lines(d, name)
    lines[row], lines[row + 1] = lines[row + 1], lines[row]
    _put(d, name, lines)


def _fifo(d: Path) -> None:
    (d / "odometer.csv").unlink()
    os.mkfifo(d / "odometer.csv")


def _directory(d: Path) -> None:
    (d / "imu.csv").unlink()
    (d / "imu.csv").mkdir()


REJECTED: dict[str, Callable[[Path], None]] = {
    "imu header only": lambda d: _put(d, "imu.csv", _lines(d, "imu.csv")[:1]),
    "odometer header only": lambda d: _put(d, "odometer.csv", _lines(d, "odometer.csv")[:1]),
    "empty file": lambda d: (d / "imu.csv").write_bytes(b""),
    "blank file": lambda d: (d / "mag.csv").write_text("\n\n"),
    "1e300 gyro increment": lambda d: _field(d, "imu.csv", 5, "dtheta_x", "1e300"),
    "1e300 accel increment": lambda d: _field(d, "imu.csv", 7, "dv_z", "-1e300"),
    "accel 2000 m/s^2": lambda d: _field(d, "imu.csv", 9, "dv_y", "10.0"),
    "odometer 1e300": lambda d: _field(d, "odometer.csv", 3, "distance", "1e300"),
    "odometer jump": lambda d: _field(d, "odometer.csv", 100, "distance", "12345.0"),
    "odometer direction 5": lambda d: _field(d, "odometer.csv", 4, "direction", "5"),
    "mag 5 T": lambda d: _field(d, "mag.csv", 2, "b_x", "5.0"),
    "ram extension 1e6 m": lambda d: _field(d, "pushram.csv", 3, "extension", "1e6"),
    "ram valid 7": lambda d: _field(d, "pushram.csv", 3, "valid", "7"),
    "negative support": lambda d: _field(d, "pushram.csv", 3, "support", "-4"),
    "survey latitude 4 rad": lambda d: _field(d, "survey.csv", 1, "lat", "4.0"),
    "survey sigma 1e12 m": lambda d: _field(d, "survey.csv", 1, "sd_horizontal", "1e12"),
    "face survey u 1e9 m": lambda d: _field(d, "face_survey.csv", 2, "u", "1e9"),
    "cut-off last number": lambda d: (d / "imu.csv").write_text((d / "imu.csv").read_text().rstrip("\n")[:-4]),
    "cut-off last row": lambda d: (d / "odometer.csv").write_text((d / "odometer.csv").read_text().rstrip("\n")[:-3]),
    "ragged row": lambda d: _field(d, "mag.csv", 20, "b_y", "1e-5,2e-5"),
    "missing column": lambda d: _put(d, "mag.csv", [",".join(r.split(",")[:3]) for r in _lines(d, "mag.csv")]),
    "extra column, rows short": lambda d: _put(d, "mag.csv", [_lines(d, "mag.csv")[0] + ",note[1]",
                                                                *_lines(d, "mag.csv")[1:]]),
    "bare header": lambda d: _put(d, "imu.csv", ["t" + _lines(d, "imu.csv")[0][4:], *_lines(d, "imu.csv")[1:]]),
    "time in ms": lambda d: _put(d, "imu.csv", ["t[ms]" + _lines(d, "imu.csv")[0][4:], *_lines(d, "imu.csv")[1:]]),
    "gyro in deg": lambda d: _put(d, "imu.csv", [_lines(d, "imu.csv")[0].replace("dtheta_x[rad]", "dtheta_x[deg]"),
                                                 *_lines(d, "imu.csv")[1:]]),
    "column twice": lambda d: _put(d, "odometer.csv", [r + "," + r.split(",")[1] for r in _lines(d, "odometer.csv")]),
    "imu time backwards": lambda d: _swap(d, "imu.csv", 10),
    "ram time backwards": lambda d: _swap(d, "pushram.csv", 44),
    "imu time repeats": lambda d: _field(d, "imu.csv", 11, "t", _lines(d, "imu.csv")[10].split(",")[0]),
    "absolute clock time": lambda d: _field(d, "mag.csv", _lines(d, "mag.csv").__len__() - 1, "t", "1.7e9"),
    "latin-1 value": lambda d: (d / "odometer.csv").write_bytes((d / "odometer.csv").read_bytes()
                                                               .replace(b"\n0.1,", b"\n0.1\xe9,", 1)),
    "latin-1 header": lambda d: (d / "mag.csv").write_bytes(b"t[s\xb5]" + (d / "mag.csv").read_bytes()[4:]),
    "utf-16 file": lambda d: (d / "survey.csv").write_text((d / "survey.csv").read_text(), encoding="utf-16"),
    "binary garbage": lambda d: (d / "imu.csv").write_bytes(np.random.default_rng(0).bytes(5000)),
    "directory named imu.csv": _directory,
    "fifo named odometer.csv": _fifo,
    "unknown stream name": lambda d: shutil.copyfile(d / "mag.csv", d / "magnetometer.csv"),
    "text in a number column": lambda d: _field(d, "imu.csv", 3, "dv_x", "abc"),
    "fraction in an integer column": lambda d: _field(d, "odometer.csv", 3, "pulses", "1.5"),
    "int8 out of range": lambda d: _field(d, "odometer.csv", 3, "direction", "300"),
    "every row NaN": lambda d: _put(d, "mag.csv", [_lines(d, "mag.csv")[0]]
                                    + [r.split(",")[0] + ",nan,0,0" for r in _lines(d, "mag.csv")[1:]]),
}


def _import(csv_dir: Path, out: Path, capsys) -> tuple[int, str, str]:
    rc = main(["import", str(csv_dir), "--out", str(out)])
    captured = capsys.readouterr()
    return rc, captured.out, captured.err


@pytest.mark.parametrize("case", sorted(REJECTED))
def test_malformed_csv_is_refused_in_one_line(case, exported, tmp_path, capsys):
    csv_dir = tmp_path / "csv"
    shutil.copytree(exported, csv_dir)
    REJECTED[case](csv_dir)
    rc, out, err = _import(csv_dir, tmp_path / "run", capsys)
    assert rc == 2, (case, out)
    assert err.startswith("longwall: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["csv"], "nothing written, no temporary directory left"


FLAGGED: dict[str, tuple[Callable[[Path], None], str]] = {
    "NaN increment": (lambda d: _field(d, "imu.csv", 5, "dv_x", "nan"), "imu: 999 rows, 1 skipped (empty/NaN: dv_x 1"),
    "inf field": (lambda d: _field(d, "mag.csv", 5, "b_z", "-inf"), "mag: 250 rows, 1 skipped (empty/NaN: b_z 1)"),
    "empty distance": (lambda d: _field(d, "odometer.csv", 5, "distance", ""), "odometer: 250 rows, 1 skipped"),
    "extra column": (lambda d: _put(d, "mag.csv", [r + (",note[1]" if i == 0 else ",x")
                                                  for i, r in enumerate(_lines(d, "mag.csv"))]),
                     "ignored columns note[1]"),
    "gap": (lambda d: _put(d, "imu.csv", _lines(d, "imu.csv")[:400] + _lines(d, "imu.csv")[500:]),
            "imu: 900 rows, 1 gaps > 3 x median dt 0.005 s"),
}


@pytest.mark.parametrize("case", sorted(FLAGGED))
def test_flagged_defects_are_imported_and_shown(case, exported, tmp_path, capsys):
    csv_dir = tmp_path / "csv"
    shutil.copytree(exported, csv_dir)
    mutate, flag = FLAGGED[case]
    mutate(csv_dir)
    rc, out, err = _import(csv_dir, tmp_path / "run", capsys)
    assert rc == 0, err
    assert flag in out, out
    assert (tmp_path / "run" / "import_report.json").is_file()


def test_the_exported_run_imports_clean(exported, tmp_path, capsys):
    """...as a run directory the project made: `longwall run --force` may replace it (and only such a one)."""
    rc, out, err = _import(exported, tmp_path / "run", capsys)
    assert rc == 0, err
    assert "skipped" not in out and "gaps" not in out, out
    assert (tmp_path / "run" / MARKER).is_file()
    check_target(tmp_path / "run", force=True)  # refuses (RunDirError) a directory without the marker


# ------------------------------------------------------------------------------------------ bounded memory


def _imu_csv(path: Path, rows: int) -> int:
    """An IMU CSV of `rows` plausible rows; returns its size in bytes."""
    rng = np.random.default_rng(1)
    data = {"t": np.arange(1, rows + 1) * 0.005, **{c.name: rng.standard_normal(rows) * 1e-3 for c in IMU.columns[1:]}}
    table = make_table(IMU, data)
    with pa.OSFile(str(path), "wb") as sink:
        sink.write((",".join(header_name(c) for c in IMU.columns) + "\n").encode())
        pacsv.write_csv(table, sink, pacsv.WriteOptions(include_header=False))
    return path.stat().st_size


_PEAK_SCRIPT = """
import os, sys, tracemalloc
import pyarrow as pa
from estimators.io.csv_import import import_csv
block, pools = int(sys.argv[1]), []
for i, csv_dir in enumerate(sys.argv[2:]):
    pools.append(pa.proxy_memory_pool(pa.default_memory_pool()))
    pa.set_memory_pool(pools[-1])
    tracemalloc.start()
    import_csv(csv_dir, f"{csv_dir}.run{i}", block_bytes=block)
    print(pools[-1].max_memory() + tracemalloc.get_traced_memory()[1], flush=True)
    tracemalloc.stop()
os._exit(0)  # a proxy pool must outlive every buffer it gave out
"""


def test_import_memory_does_not_grow_with_the_file(tmp_path):
    """A 4x larger CSV read in 32 KiB blocks peaks at the same memory (Arrow-pool plus Python/numpy allocation, in a
    fresh interpreter): 13 MB more file, under 1.3 MB more memory (a whole-file reader takes the file's size)."""
    block = 1 << 15
    dirs, sizes = [], []
    for k, rows in enumerate((30_000, 120_000)):
        dirs.append(tmp_path / f"csv{k}")
        dirs[-1].mkdir()
        sizes.append(_imu_csv(dirs[-1] / "imu.csv", rows))
    done = subprocess.run([sys.executable, "-c", _PEAK_SCRIPT, str(block), *map(str, [dirs[0], *dirs])],
                          capture_output=True, text=True, check=True, cwd=Path(__file__).resolve().parents[3])
    peaks = [int(line) for line in done.stdout.split()][1:]  # the first import warms up (lazy imports)
    print(f"\nimport peak memory: {sizes[0] / 1e6:.0f} MB file {peaks[0] / 1e6:.1f} MB, {sizes[1] / 1e6:.0f} MB file "
          f"{peaks[1] / 1e6:.1f} MB")
    assert sizes[0] > 40 * block and sizes[1] > 4 * sizes[0] - 1e6
    assert peaks[1] - peaks[0] < 0.1 * (sizes[1] - sizes[0]), (sizes, peaks)


def test_time_steps_exact_over_row_groups(tmp_path):
    """The streamed median and gaps equal numpy's over the whole column, across row-group boundaries."""
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.random(5001) * 0.01 + 1e-4)
    t[2500:] += 1.0
    table = make_table(IMU, {"t": t, **{c.name: np.zeros(t.size) for c in IMU.columns[1:]}})
    with stream_writer(tmp_path / "imu.parquet", table.schema) as writer:
        for start in range(0, t.size, 1000):
            writer.write_table(table.slice(start, 1000))
    steps = time_steps(tmp_path / "imu.parquet", 3.0, 10)
    assert steps.median == np.median(np.diff(t))
    assert steps.gap_count == 1 and steps.gaps == [(t[2499], t[2500])]
