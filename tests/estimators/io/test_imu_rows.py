"""The IMU stream read a window at a time (estimators.io.log.ImuFile): the rows of any window as the whole file's,
the file checked row group by row group on open with the file's own row numbers."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.io.log import ImuArrays, ImuFile
from estimators.io.logformat import IMU, ROW_GROUP_ROWS, LogError, write_stream


def _imu(n: int, seed: int = 1) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    cols = {"t": 10.0 + np.arange(n) * 0.005}
    for a in "xyz":
        cols[f"dtheta_{a}"] = rng.normal(0.0, 1e-4, n)
        cols[f"dv_{a}"] = rng.normal(0.0, 1e-3, n)
    return cols


def test_any_window_of_the_file_is_those_rows_of_the_whole(tmp_path):
    n = 2 * ROW_GROUP_ROWS + 1234  # three row groups, the last short
    cols = _imu(n)
    write_stream(tmp_path, IMU, cols)
    imu = ImuFile.open(tmp_path / IMU.filename)
    whole = ImuArrays(cols["t"], np.column_stack([cols[f"dtheta_{a}"] for a in "xyz"]),
                      np.column_stack([cols[f"dv_{a}"] for a in "xyz"]))
    assert imu.size == n and imu.period() == whole.period()
    edges = [(0, 1), (0, 10), (ROW_GROUP_ROWS - 3, ROW_GROUP_ROWS + 3), (5, n), (n - 2, n + 50),
             (ROW_GROUP_ROWS, 2 * ROW_GROUP_ROWS), (100, 100)]
    for i0, i1 in edges:
        for got, want in zip(imu.read(i0, i1), whole.read(i0, i1)):
            assert np.array_equal(got, want), (i0, i1)
    rows = np.array([0, 7, ROW_GROUP_ROWS - 1, ROW_GROUP_ROWS, n - 1])
    assert np.array_equal(imu.times_at(rows), cols["t"][rows])
    assert np.array_equal(whole.times_at(rows), cols["t"][rows])


@pytest.mark.parametrize("column, row, value, words", [
    ("dv_y", ROW_GROUP_ROWS + 17, np.nan, "column 'dv_y' row {row}: not a finite number"),
    ("t", 2 * ROW_GROUP_ROWS, 0.0, "column 't' row {row}: time goes from"),
    ("t", ROW_GROUP_ROWS + 5, 0.0, "column 't' row {row}: time goes from"),
])
def test_a_bad_row_in_a_later_row_group_is_named_by_its_row_in_the_file(tmp_path, column, row, value, words):
    cols = _imu(2 * ROW_GROUP_ROWS + 100)
    cols[column][row] = value
    write_stream(tmp_path, IMU, cols)
    with pytest.raises(LogError, match=words.format(row=row)) as err:
        ImuFile.open(tmp_path / IMU.filename)
    assert "\n" not in str(err.value)
