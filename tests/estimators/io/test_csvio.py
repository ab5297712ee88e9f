"""CSV export/import of run directories: exact round trip, the rejection policy, skipped rows and gaps."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from estimators.io.csv_import import REPORT_FILE, import_csv
from estimators.io.csvio import export_csv, header_name
from estimators.io.logformat import (
    FAULTS,
    IMU,
    ODOMETER,
    PUSHRAM,
    STREAMS,
    TRUTH_SHEARER,
    LogError,
    make_table,
    read_stream,
    write_stream,
)

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

SCENARIO_TEXT = 'name = "synthetic"\nseed = 7\n'


def _imu_data(n: int, rng: np.random.Generator, dt: float = 0.005) -> dict[str, np.ndarray]:
    data = {"t": np.arange(1, n + 1) * dt}
    for c in IMU.columns[1:]:
        data[c.name] = rng.standard_normal(n) * 10.0 ** rng.integers(-9, -1, n)  # within estimators.io.plausible
    return data


def _make_run(run_dir: Path) -> Path:
    """A run directory with several streams, awkward values included."""
    rng = np.random.default_rng(42)
    run_dir.mkdir(parents=True)
    imu = _imu_data(300, rng)
    awkward = [1e-3, 1 / 3e3, -0.0, 5e-324, 2.0**-1074 * 3, 1.23456789123456789e-3, 1e-300]
    imu["dv_x"][: len(awkward)] = awkward
    write_stream(run_dir, IMU, imu)

    n = 50
    pulses = (np.arange(n) * 123457 + 2**40).astype(np.int64)
    write_stream(run_dir, ODOMETER, {
        "t": np.arange(n) * 0.1 + 0.05,
        "distance": pulses * 1e-9,  # large pulse counts, a plausible distance
        "pulses": pulses,
        "direction": np.resize(np.array([1, 0, -1], np.int8), n),
    })

    times, supports = np.meshgrid(np.arange(20) * 0.5, np.arange(1, 6), indexing="ij")
    valid = (rng.random(times.size) > 0.2).astype(np.int8)
    extension = np.where(valid == 1, 0.8 + rng.random(times.size), np.nan)
    write_stream(run_dir, PUSHRAM, {"t": times.ravel(), "support": supports.ravel().astype(np.int32),
                                    "extension": extension, "valid": valid})

    write_stream(run_dir, FAULTS, {
        "kind": np.array(["ram_stuck", "ram_bias", 'odd, "quoted" kind', ""]),
        "target": np.array([3, -1, 2, 0], np.int32),
        "t_start": np.array([10.0, 5.0, 1.0, 0.0]),
        "t_end": np.array([20.0, 6.5, 2.0, 0.0]),
        "value": np.array([0.0, 0.01, -3.5, 1e-9]),
    })

    shearer = {c.name: rng.standard_normal(4) for c in TRUTH_SHEARER.columns if c.dtype == "f8"}
    shearer["t"] = np.array([0.0, 0.005, 0.01, 0.015])
    shearer["s"] = np.array([0.1, 1.7976931348623157e308, 123456789.123456789, 1 / 3])  # truth has no limits
    shearer.update(pan_rear=np.array([1, 1, 2, 2]), pan_front=np.array([3, 3, 4, 4]),
                   cycle=np.zeros(4), phase=np.array([0, 1, 1, 4]))
    write_stream(run_dir, TRUTH_SHEARER, shearer)
    (run_dir / "scenario.toml").write_text(SCENARIO_TEXT)
    return run_dir


def _assert_identical(a: pa.Table, b: pa.Table, name: str) -> None:
    """Table.equals, except that NaN equals NaN: float columns are compared bit for bit."""
    assert a.schema.equals(b.schema, check_metadata=True), name
    if a.equals(b, check_metadata=True):
        return
    for field in a.schema:
        x, y = a.column(field.name), b.column(field.name)
        if pa.types.is_floating(field.type):
            x, y = x.to_numpy().view(np.uint64), y.to_numpy().view(np.uint64)
            assert np.array_equal(x, y), (name, field.name)
        else:
            assert x.equals(y), (name, field.name)


def _write(csv_dir: Path, name: str, lines: list[str]) -> Path:
    csv_dir.mkdir(parents=True, exist_ok=True)
    path = csv_dir / name
    path.write_text("\n".join(lines) + "\n")
    return path


def _imu_header() -> str:
    return ",".join(header_name(c) for c in IMU.columns)


def _imu_rows(ts) -> list[str]:
    return [f"{float(t)!r},1e-5,2e-5,3e-5,0.001,0.002,-9.8e-3" for t in ts]


def _reject(tmp_path: Path, csv_dir: Path, *needles: str) -> str:
    run = tmp_path / "imported"
    with pytest.raises(LogError) as err:
        import_csv(csv_dir, run)
    msg = str(err.value)
    assert "\n" not in msg, msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    assert not run.exists(), "a failed import must leave nothing"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".imported")], "temporary directory left"
    return msg


# ------------------------------------------------------------------------------------------ round trip


def test_round_trip_identical(tmp_path):
    """A run directory exported to CSV and imported back gives identical streams."""
    run = _make_run(tmp_path / "run")
    written = export_csv(run, tmp_path / "csv")
    names = {p.name for p in written}
    assert names == {"imu.csv", "odometer.csv", "pushram.csv", "faults.csv", "truth_shearer.csv", "scenario.toml"}
    head = (tmp_path / "csv" / "imu.csv").read_text().splitlines()[0]
    assert head == "t[s],dtheta_x[rad],dtheta_y[rad],dtheta_z[rad],dv_x[m/s],dv_y[m/s],dv_z[m/s]"

    report = import_csv(tmp_path / "csv", tmp_path / "back")
    for name in ("imu", "odometer", "pushram", "faults", "truth_shearer"):
        stream = STREAMS[name]
        a, b = read_stream(run, stream), read_stream(tmp_path / "back", stream)
        _assert_identical(a, b, name)
        assert b.schema.field(stream.columns[0].name).metadata[b"unit"] == stream.columns[0].unit.encode()
        assert report.skipped_count[name] == 0 and report.gap_count[name] == 0
    dv_x = read_stream(tmp_path / "back", IMU).column("dv_x").to_numpy()
    assert np.signbit(dv_x[2]) and dv_x[3] == 5e-324
    assert np.isnan(read_stream(tmp_path / "back", PUSHRAM).column("extension").to_numpy()).any()
    assert (tmp_path / "back" / "scenario.toml").read_text() == SCENARIO_TEXT
    saved = json.loads((tmp_path / "back" / REPORT_FILE).read_text())
    assert saved["rows"]["imu"] == 300 and saved["scenario"] is True


def test_columns_in_any_order_and_extra_columns_listed(tmp_path):
    run = _make_run(tmp_path / "run")
    export_csv(run, tmp_path / "csv")
    path = tmp_path / "csv" / "odometer.csv"
    lines = path.read_text().splitlines()
    rows = [line.split(",") for line in lines]
    order = [3, 0, 2, 1]
    path.write_text("\n".join(",".join([r[i] for i in order] + [("comment" if k == 0 else "x")])
                              for k, r in enumerate(rows)) + "\n")
    report = import_csv(tmp_path / "csv", tmp_path / "back")
    assert read_stream(tmp_path / "back", ODOMETER).equals(read_stream(run, ODOMETER), check_metadata=True)
    assert report.extra_columns["odometer"] == ["comment"]


# ------------------------------------------------------------------------------------------ rejections


def test_missing_column(tmp_path):
    header = ",".join(header_name(c) for c in IMU.columns if c.name != "dv_z")
    _write(tmp_path / "csv", "imu.csv", [header, "0.1,1,2,3,4,5"])
    _reject(tmp_path, tmp_path / "csv", "imu.csv", "'dv_z'", "header row", "missing", "dv_z[m/s]")


@pytest.mark.parametrize("bad, column, expected", [("t[ms]", "'t'", "'s'"), ("dtheta_x[deg]", "'dtheta_x'", "'rad'")])
def test_wrong_unit(tmp_path, bad, column, expected):
    good = bad.split("[")[0] + "[" + IMU.column(bad.split("[")[0]).unit + "]"
    _write(tmp_path / "csv", "imu.csv", [_imu_header().replace(good, bad), *_imu_rows([0.1, 0.2])])
    _reject(tmp_path, tmp_path / "csv", "imu.csv", column, "header row", expected)


def test_bare_header(tmp_path):
    _write(tmp_path / "csv", "imu.csv", [_imu_header().replace("dv_y[m/s]", "dv_y"), *_imu_rows([0.1])])
    _reject(tmp_path, tmp_path / "csv", "imu.csv", "'dv_y'", "header row", "'dv_y[m/s]'")


def test_unparsable_values(tmp_path):
    rows = _imu_rows([0.1, 0.2, 0.3, 0.4])
    rows[2] = "0.3,1e-5,2e-5,3e-5,0.001,abc,-9.8e-3"
    _write(tmp_path / "csv", "imu.csv", [_imu_header(), *rows])
    _reject(tmp_path, tmp_path / "csv", "imu.csv", "'dv_y'", "row 3", "'abc'")

    odo = [",".join(header_name(c) for c in ODOMETER.columns)] + [f"{k * 0.1},{k * 0.01},{k},1" for k in range(1, 8)]
    odo[5] = "0.5,0.05,5.5,1"  # data row 5: a fraction in an integer column
    _write(tmp_path / "csv2", "odometer.csv", odo)
    _reject(tmp_path, tmp_path / "csv2", "odometer.csv", "'pulses'", "row 5", "'5.5'")

    odo[5] = "0.5,0.05,5,300"  # out of range for int8
    _write(tmp_path / "csv3", "odometer.csv", odo)
    _reject(tmp_path, tmp_path / "csv3", "odometer.csv", "'direction'", "row 5", "'300'")


def test_ragged_row(tmp_path):
    rows = _imu_rows([0.1, 0.2, 0.3])
    rows[1] = "0.2,1,2"
    _write(tmp_path / "csv", "imu.csv", [_imu_header(), *rows])
    _reject(tmp_path, tmp_path / "csv", "imu.csv", "row 2", "3 fields")


def test_time_backwards_and_duplicates(tmp_path):
    _write(tmp_path / "a", "imu.csv", [_imu_header(), *_imu_rows([0.1, 0.2, 0.3, 0.25, 0.4])])
    _reject(tmp_path, tmp_path / "a", "imu.csv", "'t'", "row 4", "backwards")

    _write(tmp_path / "b", "imu.csv", [_imu_header(), *_imu_rows([0.1, 0.2, 0.2, 0.3])])
    _reject(tmp_path, tmp_path / "b", "imu.csv", "'t'", "row 3", "repeats")

    # Row numbers count the rows of the file, skipped rows included.
    rows = _imu_rows([0.1, 0.2, 0.3, 0.15])
    rows[2] = "0.3,,2e-5,3e-5,0.001,0.002,-9.8e-3"
    _write(tmp_path / "c", "imu.csv", [_imu_header(), *rows])
    _reject(tmp_path, tmp_path / "c", "imu.csv", "'t'", "row 4", "backwards")

    head = ",".join(header_name(c) for c in PUSHRAM.columns)
    _write(tmp_path / "d", "pushram.csv", [head, "0.5,1,1.0,1", "0.5,2,1.1,1", "1.0,1,1.0,1", "0.5,2,1.0,1"])
    _reject(tmp_path, tmp_path / "d", "pushram.csv", "'t'", "row 4", "backwards")

    # Repeated times are the normal case for a stream with a row per support.
    _write(tmp_path / "e", "pushram.csv", [head, "0.5,1,1.0,1", "0.5,2,1.1,1", "1.0,1,1.0,1", "1.0,2,1.0,1"])
    assert import_csv(tmp_path / "e", tmp_path / "ok").rows["pushram"] == 4


def test_unknown_file_name(tmp_path):
    _write(tmp_path / "csv", "imu.csv", [_imu_header(), *_imu_rows([0.1])])
    _write(tmp_path / "csv", "gyro.csv", ["t[s],w[rad/s]", "0.1,0.0"])
    msg = _reject(tmp_path, tmp_path / "csv", "gyro.csv", "imu.csv", "odometer.csv", "pushram.csv")
    assert "valid names" in msg


def test_failed_import_leaves_nothing(tmp_path):
    """A good file followed by a bad one: neither the run directory nor a temporary one remains."""
    csv_dir = tmp_path / "csv"
    _write(csv_dir, "imu.csv", [_imu_header(), *_imu_rows([0.1, 0.2])])
    _write(csv_dir, "pushram.csv", ["t[s],support[1],extension[m],valid[1]", "0.1,1,1.0,1", "0.1,1,x,1"])
    _reject(tmp_path, csv_dir, "pushram.csv", "'extension'", "row 2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["csv"]


def test_refuses_non_empty_run_dir(tmp_path):
    _write(tmp_path / "csv", "imu.csv", [_imu_header(), *_imu_rows([0.1])])
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "keep.txt").write_text("x")
    with pytest.raises(LogError, match="not empty"):
        import_csv(tmp_path / "csv", tmp_path / "run")
    assert sorted(p.name for p in (tmp_path / "run").iterdir()) == ["keep.txt"]
    (tmp_path / "run" / "keep.txt").unlink()  # an empty existing directory is fine
    assert import_csv(tmp_path / "csv", tmp_path / "run").rows["imu"] == 1


# ------------------------------------------------------------------------------------------ flagged


def test_nan_rows_skipped_and_reported(tmp_path):
    rows = _imu_rows(np.arange(1, 11) * 0.01)
    rows[1] = rows[1].replace("0.002", "")    # row 2: empty value
    rows[3] = rows[3].replace("0.002", "nan")  # row 4: NaN
    rows[6] = rows[6].replace("1e-5", "inf", 1)  # row 7: infinite
    _write(tmp_path / "csv", "imu.csv", [_imu_header(), *rows])
    head = ",".join(header_name(c) for c in PUSHRAM.columns)
    # extension may be NaN (kept); valid may not be empty (row 3 skipped)
    _write(tmp_path / "csv", "pushram.csv", [head, "0.5,1,,0", "0.5,2,nan,0", "0.5,3,1.2,", "1.0,1,1.0,1"])
    report = import_csv(tmp_path / "csv", tmp_path / "run")

    assert report.skipped["imu"] == [2, 4, 7] and report.skipped_count["imu"] == 3
    assert report.skipped_columns["imu"]["dv_y"] == 2 and report.skipped_columns["imu"]["dtheta_x"] == 1
    t = read_stream(tmp_path / "run", IMU).column("t").to_numpy()
    np.testing.assert_array_equal(t, np.delete(np.arange(1, 11) * 0.01, [1, 3, 6]))
    assert report.skipped["pushram"] == [3] and report.rows["pushram"] == 3
    ext = read_stream(tmp_path / "run", PUSHRAM).column("extension").to_numpy()
    assert np.isnan(ext[:2]).all() and ext[2] == 1.0
    saved = json.loads((tmp_path / "run" / REPORT_FILE).read_text())
    assert saved["skipped"]["imu"] == [2, 4, 7] and saved["skipped_count"]["pushram"] == 1


def test_gap_reported(tmp_path):
    ts = np.concatenate([np.arange(1, 101) * 0.005, 0.5 + 0.1 + np.arange(1, 51) * 0.005])
    _write(tmp_path / "csv", "imu.csv", [_imu_header(), *_imu_rows(ts)])
    head = ",".join(header_name(c) for c in PUSHRAM.columns)
    ram_rows = [f"{k * 0.5!r},{s},1.0,1" for k in range(10) if k != 6 for s in (1, 2, 3)]
    _write(tmp_path / "csv", "pushram.csv", [head, *ram_rows])
    report = import_csv(tmp_path / "csv", tmp_path / "run")
    assert report.gap_count["imu"] == 1
    (before, after), = report.gaps["imu"]
    assert before == pytest.approx(0.5) and after == pytest.approx(0.605)
    assert report.median_dt["imu"] == pytest.approx(0.005)
    assert report.gap_count["pushram"] == 0  # 2.5 -> 3.5 is twice the median interval: not a gap
    assert report.rows["imu"] == 150  # flagged, not rejected
    saved = json.loads((tmp_path / "run" / REPORT_FILE).read_text())
    assert saved["gap_count"]["imu"] == 1 and len(saved["gaps"]["imu"][0]) == 2


# ------------------------------------------------------------------------------------------ speed


def test_speed_1e6_imu_rows(tmp_path):
    n = 1_000_000
    run = tmp_path / "run"
    run.mkdir()
    table = make_table(IMU, _imu_data(n, np.random.default_rng(0)))
    write_stream(run, IMU, table)
    t0 = time.perf_counter()
    export_csv(run, tmp_path / "csv")
    t1 = time.perf_counter()
    report = import_csv(tmp_path / "csv", tmp_path / "back")
    t2 = time.perf_counter()
    print(f"\n1e6 imu rows: export {t1 - t0:.2f} s, import {t2 - t1:.2f} s")
    assert report.rows["imu"] == n
    assert read_stream(tmp_path / "back", IMU).equals(table, check_metadata=True)
    assert t2 - t0 < 15.0
