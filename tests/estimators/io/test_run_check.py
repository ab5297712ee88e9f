"""Damaged run directories and logs that disagree with their scenario: one LogError naming the file and the fix
(estimators.io.logformat read paths, estimators.io.run_check, estimators.io.log, estimators.io.plausible)."""

from __future__ import annotations

import json
import tracemalloc

import numpy as np
import pyarrow as pa
import pytest

from estimators.io.log import load_log
from estimators.io.logformat import (
    ESTIMATE,
    IMU,
    ODOMETER,
    PUSHRAM,
    SUPPORT_IMU,
    SURVEY,
    LogError,
    estimate_path,
    make_table,
    read_estimate,
    read_schema,
    read_stream,
    stream_writer,
    write_estimate,
    write_stream,
)
from estimators.io.run_check import Expected, LogLayout, check_layout, read_metrics

MPP = 0.002


def _zeros(stream, n, **cols):
    return {**{c.name: np.zeros(n, dtype=c.dtype if c.dtype != "str" else object) for c in stream.columns}, **cols}


@pytest.fixture
def log_dir(tmp_path):
    """A small log: imu 200 Hz, odometer 50 Hz, push rams of supports 0-4 at 1 Hz, canopy units on 3 and 7."""
    run = tmp_path / "run"
    run.mkdir()
    write_stream(run, IMU, _zeros(IMU, 400, t=np.arange(1, 401) * 0.005))
    pulses = np.arange(100) * 10
    write_stream(run, ODOMETER, _zeros(ODOMETER, 100, t=np.arange(100) * 0.02, pulses=pulses, distance=pulses * MPP,
                                       direction=np.ones(100)))
    t, sup = np.meshgrid(np.arange(3.0), np.arange(5), indexing="ij")
    write_stream(run, PUSHRAM, _zeros(PUSHRAM, t.size, t=t.ravel(), support=sup.ravel(), extension=np.ones(t.size),
                                      valid=np.ones(t.size)))
    t, sup = np.meshgrid(np.arange(10) * 0.02, [3, 7], indexing="ij")
    write_stream(run, SUPPORT_IMU, _zeros(SUPPORT_IMU, t.size, t=t.ravel(), support=sup.ravel()))
    write_stream(run, SURVEY, _zeros(SURVEY, 1, lat=np.array([0.6]), lon=np.array([2.0])))
    return run


def _layout(**changes) -> LogLayout:
    base = {"rates_hz": {"imu": Expected(200.0, "[sensors.imu] rate_hz"),
                         "odometer": Expected(50.0, "[sensors.odometer] rate_hz"),
                         "pushram": Expected(1.0, "[sensors.pushram] rate_hz")},
            "ram_supports": Expected(5, "[face] pan_count / [supports] pans_per_support"),
            "imu_supports": Expected((3, 7), "[sensors.support_imu] supports"),
            "metres_per_pulse": Expected(MPP, "[sensors.odometer] metres_per_pulse")}
    return LogLayout(**{**base, **changes})


def _refused(call, *needles) -> str:
    with pytest.raises(LogError) as err:
        call()
    msg = str(err.value)
    assert "\n" not in msg
    for needle in needles:
        assert needle in msg, (needle, msg)
    return msg


# ------------------------------------------------------------------------------------------ layout vs scenario


def test_layout_as_described_passes(log_dir):
    check_layout(log_dir, _layout())


def test_rate_disagreeing_with_the_log(log_dir):
    rates = {**_layout().rates_hz, "imu": Expected(100.0, "[sensors.imu] rate_hz")}
    _refused(lambda: check_layout(log_dir, _layout(rates_hz=rates)), "imu.parquet", "0.005 s", "200 Hz",
             "[sensors.imu] rate_hz = 100", "set [sensors.imu] rate_hz = 200")


@pytest.mark.parametrize("n, needle", [(3, "rows for supports 3-4"), (8, "no rows for supports 5-7")])
def test_supports_disagreeing_with_the_push_rams(log_dir, n, needle):
    layout = _layout(ram_supports=Expected(n, "[face] pan_count / [supports] pans_per_support"))
    _refused(lambda: check_layout(log_dir, layout), "pushram.parquet", needle, f"{n} supports", "pans_per_support")


def test_canopy_units_disagreeing_with_the_scenario(log_dir):
    layout = _layout(imu_supports=Expected((3,), "[sensors.support_imu] supports"))
    _refused(lambda: check_layout(log_dir, layout), "support_imu.parquet", "rows for supports 7",
             "[sensors.support_imu] supports")


def test_pulse_length_disagreeing_with_the_odometer(log_dir):
    layout = _layout(metres_per_pulse=Expected(0.001, "[sensors.odometer] metres_per_pulse"))
    _refused(lambda: check_layout(log_dir, layout), "odometer.parquet", "row 1", "0.002 m per pulse",
             "metres_per_pulse = 0.001")


def _in_row_groups(path, stream, columns, rows_per_group):
    """Write `columns` to `path` as `stream`'s file in row groups of `rows_per_group`."""
    table = make_table(stream, columns)
    with stream_writer(path, table.schema) as writer:
        writer.write_table(table, row_group_size=rows_per_group)


def _odometer(n, bad_row=None):
    """n odometer rows at 50 Hz with steps of 0.0198 and 0.0202 s; the pulse length off by 1e-5 at `bad_row`."""
    t = np.arange(1, n + 1) * 0.02
    t[::2] += 0.0002
    pulses = np.arange(n) * 10
    distance = pulses * MPP
    if bad_row is not None:
        distance[bad_row] *= 1.00001
    return _zeros(ODOMETER, n, t=t, pulses=pulses, distance=distance, direction=np.ones(n))


def test_checks_read_the_log_a_row_group_at_a_time(log_dir, monkeypatch):
    """A log in many row groups: the interval's median across the groups' joins, a support seen only in a later group
    and a bad pulse count in one are found as in one group (the pulse by its row in the file), and the check's
    traced memory does not grow with the log (the whole-file check held the time column and its differences)."""
    monkeypatch.setattr("estimators.io.stream_median.IN_MEMORY", 1_000)
    monkeypatch.setattr("estimators.io.stream_median.READ_VALUES", 1_000)
    peaks = []
    for n in (50_000, 200_000):
        _in_row_groups(log_dir / ODOMETER.filename, ODOMETER, _odometer(n), 1_000)
        tracemalloc.start()
        check_layout(log_dir, _layout())
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < peaks[0] + 100_000, peaks  # 150,000 more rows: 1.2 MB a whole column
    median = np.median(np.diff(_odometer(n)["t"]))
    _refused(lambda: check_layout(log_dir, _layout(rates_hz={"odometer": Expected(40.0, "[sensors.odometer] rate_hz")})),
             f"samples every {median:.6g} s")
    sup = np.repeat(np.arange(5), 3)  # supports 0-4, support 4 only in the last of five groups
    _in_row_groups(log_dir / PUSHRAM.filename, PUSHRAM,
                   _zeros(PUSHRAM, sup.size, t=np.arange(sup.size, dtype=float), support=sup,
                          extension=np.ones(sup.size), valid=np.ones(sup.size)), 3)
    _refused(lambda: check_layout(log_dir, _layout(ram_supports=Expected(4, "[face] pan_count"))),
             "rows for supports 4")
    _in_row_groups(log_dir / ODOMETER.filename, ODOMETER, _odometer(n, bad_row=150_001), 1_000)
    _refused(lambda: check_layout(log_dir, _layout()), "odometer.parquet", "row 150001: distance")


# ------------------------------------------------------------------------------------------ damaged files


@pytest.mark.parametrize("damage", ["truncated", "zeroed footer", "empty", "text"])
def test_damaged_parquet_is_a_log_error_with_the_fix(log_dir, damage):
    path = log_dir / IMU.filename
    data = path.read_bytes()
    path.write_bytes({"truncated": data[: len(data) // 2], "zeroed footer": data[:-8] + bytes(8), "empty": b"",
                      "text": b"t,dtheta_x\n0.1,0.0\n"}[damage])
    _refused(lambda: read_stream(log_dir, IMU), "imu.parquet", "not a readable Parquet file", "import the recording")
    _refused(lambda: load_log(log_dir), "imu.parquet")


def test_damaged_estimate_names_longwall_estimate(log_dir):
    rng = np.random.default_rng(0)
    write_estimate(log_dir, "kf", {c.name: rng.random(3) if c.dtype == "f8" else np.zeros(3) for c in ESTIMATE.columns}
                   | {"t": np.arange(3.0)})
    path = estimate_path(log_dir, "kf")
    path.write_bytes(path.read_bytes()[:-100])
    _refused(lambda: read_estimate(log_dir, "kf"), "kf.parquet", f"run `longwall estimate {log_dir}` again")
    _refused(lambda: read_schema(path), "kf.parquet", "longwall estimate")


def test_column_of_the_wrong_type(log_dir):
    table = read_stream(log_dir, ODOMETER)
    table = table.set_column(2, table.schema.field("pulses").with_type(pa.string()),
                             table.column("pulses").cast(pa.string()))
    write_stream(log_dir, ODOMETER, table)
    _refused(lambda: read_stream(log_dir, ODOMETER), "odometer.parquet", "'pulses'", "type string", "i8")


def test_absurd_value_in_a_parquet_log(log_dir):
    data = _zeros(IMU, 400, t=np.arange(1, 401) * 0.005)
    data["dv_x"][17] = 1e300
    write_stream(log_dir, IMU, make_table(IMU, data))
    _refused(lambda: read_stream(log_dir, IMU), "imu.parquet", "'dv_x' row 17", "acceleration")


@pytest.mark.parametrize("stream, rows", [(IMU, 1), (ODOMETER, 0), (SURVEY, 0)])
def test_too_few_rows_for_the_positioning(log_dir, stream, rows):
    table = read_stream(log_dir, stream).slice(0, rows)
    write_stream(log_dir, stream, table)
    _refused(lambda: load_log(log_dir), stream.filename, f"{rows} rows", "at least")


# ------------------------------------------------------------------------------------------ metrics.json


@pytest.mark.parametrize("text, why", [("garbage{", "not valid JSON"), ("[1, 2]", "not a JSON object"),
                                       ("\udcff", "not valid JSON")])
def test_damaged_metrics_json(tmp_path, text, why):
    (tmp_path / "metrics.json").write_bytes(text.encode("utf-8", "surrogateescape"))
    _refused(lambda: read_metrics(tmp_path), "metrics.json", why, "move the damaged file away")


def test_metrics_json_read(tmp_path):
    assert read_metrics(tmp_path) == {}
    (tmp_path / "metrics.json").write_text(json.dumps({"twin": {"cycles": 2}}))
    assert read_metrics(tmp_path) == {"twin": {"cycles": 2}}
