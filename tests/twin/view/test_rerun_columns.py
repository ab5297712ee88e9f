"""twin.view.rerun_columns and twin.view.record_rate: the rows a recording keeps of a series, a path, a moving marker
(at most the record rate, without what a person cannot tell apart), and the record rate as the command line spells
it."""

from __future__ import annotations

import numpy as np
import pytest

from twin.view.record_rate import FULL, parse_record_rate, rate_label
from twin.view.row_cuts import (
    MARKER_STEP_M,
    PATH_TOLERANCE_M,
    line_rows,
    marker_rows,
    path_strips,
)
from twin.view.visible_cut import (
    BAND_ROWS,
    LINE_TOLERANCE,
    visible_rows,
)


def _off_line(t, y, rows) -> np.ndarray:
    """Per column, the largest distance of a row from the line drawn through `rows`."""
    return np.array([np.abs(np.interp(t, t[rows], y[rows, j]) - y[:, j]).max() for j in range(y.shape[1])])


def test_line_rows_keep_every_left_out_row_within_the_tolerance():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(0, 100, 5000))
    y = np.column_stack([np.cumsum(rng.normal(size=t.size)), np.sin(t / 7), 3 * t])
    tol = np.array([2.0, 1e-3, 1e-9])
    rows = line_rows(t, y, tol)
    assert rows[0] == 0 and rows[-1] == t.size - 1 and rows.size < t.size / 2
    assert (_off_line(t, y, rows) <= tol * (1 + 1e-9)).all()
    straight = line_rows(t, 3 * t, 1e-9)  # a straight line: its ends
    np.testing.assert_array_equal(straight, [0, t.size - 1])
    must = np.zeros(t.size, bool)
    must[[10, 2000]] = True
    assert {10, 2000} <= set(line_rows(t, 3 * t, 1e-9, must))


def test_line_rows_keep_where_a_value_turns_nan_and_back():
    t = np.arange(100.0)
    y = np.ones(100)
    y[40:50] = np.nan
    assert {39, 40, 49, 50} <= set(line_rows(t, y, 1e-3))


def test_visible_rows_of_a_column_without_values():
    """A column NaN throughout (e.g. a yaw innovation of a filter that never used the magnetometer) beside another."""
    t = np.arange(600) / 10.0
    y = np.column_stack([np.full(t.size, np.nan), np.random.default_rng(2).normal(size=t.size)])
    rows = visible_rows(t, y, 10.0)
    assert rows[0] == 0 and rows[-1] == t.size - 1
    np.testing.assert_array_equal(visible_rows(t, y[:, :1], 10.0), [0, t.size - 1])


def test_visible_rows_every_row_at_full_rate_at_most_the_rate_otherwise():
    t = np.arange(20000) / 200.0  # 100 s at 200 Hz
    y = np.random.default_rng(0).normal(size=(t.size, 2))
    np.testing.assert_array_equal(visible_rows(t, y, FULL), np.arange(t.size))
    for rate in (10.0, 2.0):
        rows = visible_rows(t, y, rate)
        bins = np.floor(t[rows[:-1]] * rate + 1e-9)
        assert np.all(np.diff(bins) > 0)  # at most one row per 1/rate interval (and the last sample)


def test_visible_rows_of_a_smooth_series_stay_within_a_pixel():
    t = np.arange(36000) / 10.0  # an hour at 10 Hz
    y = np.column_stack([np.sin(t / 60), 0.01 * t + np.cos(t / 300)])
    rows = visible_rows(t, y, 10.0)
    assert rows.size < t.size / 10
    assert (_off_line(t, y, rows) <= LINE_TOLERANCE * np.ptp(y) * (1 + 1e-9)).all()


def test_visible_rows_of_noise_keep_each_intervals_band():
    """Noise is drawn by its band: each interval's lowest and highest row (BAND_ROWS rows at the rate), fewer rows."""
    t = np.arange(6000) / 10.0
    y = 0.01 * t + np.random.default_rng(1).normal(size=t.size)
    rows = visible_rows(t, y, 10.0)
    assert rows.size < 0.5 * t.size
    interval = np.floor(t * 10.0 / BAND_ROWS + 1e-9).astype(int)
    for k in range(interval.max() + 1):
        inside = np.flatnonzero(interval == k)
        assert {inside[np.argmax(y[inside])], inside[np.argmin(y[inside])]} <= set(rows)


def test_a_brief_flag_keeps_its_edges():
    t = np.arange(3000) / 10.0
    flags = np.zeros(t.size)
    flags[1234] = 1.0  # one sample
    flags[2000:2400] = 1.0  # a window
    rows = visible_rows(t, flags[:, None], 10.0, band=False)
    assert {1233, 1234, 1235, 1999, 2000, 2399, 2400} <= set(rows) and rows.size < 12
    np.testing.assert_array_equal(np.interp(t, t[rows], flags[rows]), flags)


def test_marker_rows_follow_the_travel():
    t = np.arange(6000) / 100.0  # 60 s at 100 Hz: 20 s at 0.2 m/s, a 20 s stop, 20 s back
    s = np.interp(t, [0, 20, 40, 60], [0, 4, 4, 0])
    p = np.column_stack([np.zeros(t.size), s, np.zeros(t.size)])
    rows = marker_rows(t, p, 10.0)
    assert rows.size <= 8 / MARKER_STEP_M + 2
    lag = np.abs(s - s[rows][np.searchsorted(rows, np.arange(t.size), side="right") - 1])
    assert lag.max() <= MARKER_STEP_M + 0.2 / 10.0 + 1e-9  # a step and a frame at most
    np.testing.assert_array_equal(marker_rows(t, p, FULL), np.arange(t.size))


def test_marker_rows_of_a_body_turning_in_place():
    """A 10 m body turning at 1 deg/s without moving its centre: logged as its ends move MARKER_STEP_M."""
    t = np.arange(1000) / 100.0
    yaw = np.radians(t)
    end = 5.0 * np.column_stack([np.sin(yaw), np.cos(yaw), np.zeros(t.size)])
    rows = marker_rows(t, np.hstack([-end, end]), 10.0)
    arc = 5.0 * np.radians(10.0)
    assert arc / (MARKER_STEP_M + 0.01) <= rows.size <= arc / MARKER_STEP_M + 2


def test_path_strips_keep_cycle_ends_stops_and_the_shape():
    t = np.arange(8000) / 100.0
    s = np.interp(t, [0, 20, 30, 50, 80], [0, 4, 4, 0, 6])  # along the face, a stop, back, and on in cycle 1
    p = np.column_stack([0.02 * np.sin(s), s, 0.01 * np.cos(3 * s)])
    cycle = (t >= 50).astype(int)
    strips = path_strips(t, p, cycle, 10.0)
    assert len(strips) == 2 and sum(len(x) for x in strips) < t.size / 20
    for strip, rows in zip(strips, (cycle == 0, cycle == 1)):
        np.testing.assert_allclose(strip[[0, -1]], p[rows][[0, -1]], atol=1e-6)  # the cycle's ends
    on = [np.flatnonzero(np.all(np.abs(p - q) < 1e-6, axis=1)) for q in strips[0]]
    kept = t[np.concatenate(on)]
    assert np.isclose(kept, 20.0).any() and np.isclose(kept, 30.0).any()  # the stop's start and end
    rows = np.flatnonzero(cycle == 0)
    idx = np.concatenate(on)
    idx = idx[np.isin(idx, rows)]
    assert (_off_line(t[rows], p[rows], np.searchsorted(rows, np.unique(idx))) <= PATH_TOLERANCE_M + 1e-6).all()
    assert [len(x) for x in path_strips(t, p, cycle, FULL)] == [5000, 3000]


@pytest.mark.parametrize("text, rate", [("10", 10.0), ("2.5", 2.5), ("full", FULL), ("FULL", FULL), ("1e3", 1000.0)])
def test_parse_record_rate(text, rate):
    assert parse_record_rate(text) == rate
    assert rate_label(rate) == ("full" if rate is FULL else rate)


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf", "ten", "", "10Hz"])
def test_a_bad_record_rate_is_one_line(text):
    with pytest.raises(ValueError, match="not a record rate") as err:
        parse_record_rate(text)
    assert "\n" not in str(err.value)
