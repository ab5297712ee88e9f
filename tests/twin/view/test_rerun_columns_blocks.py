"""twin.view.rerun_columns over streams given in blocks (a long stream read a row group at a time): the carried
helpers give the whole series' rows bit for bit, however the blocks are cut (empty and one-row blocks included)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from twin.view.line_kernel import line_kernel
from twin.view.record_rate import FULL
from twin.view import rerun_columns
from twin.view.rerun_columns import (
    PlottedSeries,
    RowBatches,
    latest_frames,
    latest_rows,
    mean_rates,
    median_interval,
)
from twin.view.row_cuts import (
    PATH_TOLERANCE_M,
    IntervalReduce,
    LineCut,
    MarkerCut,
    PathStrips,
    decimate,
    decimated_blocks,
    line_rows,
    marker_rows,
    path_strips,
)
from twin.view.visible_cut import (
    BAND_ROWS,
    BAND_TURNS,
    LINE_TOLERANCE,
    SeriesRange,
    VisibleCut,
    _intervals,
    band_rows,
    visible_rows,
)
from twin.view.sensor_recording import bar_frames, pressure_extremes, sample_times


def _cuts(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """Row indices of 0..n cut into blocks anywhere: some empty, many of one to three rows."""
    tiny = np.cumsum(rng.integers(0, 4, n))
    cuts = np.sort(np.r_[rng.integers(0, n + 1, 5), tiny[tiny <= n][:: max(1, int(rng.integers(1, 4)))]])
    return np.split(np.arange(n), cuts)


def _series(rng: np.random.Generator, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """A random walk (K, m) with repeated times, flat stretches and NaN gaps."""
    t = np.cumsum(rng.choice([0.0, 0.1, 0.1, 0.3], n))
    y = np.cumsum(rng.normal(size=(n, m)) * rng.choice([0.0, 1.0, 5.0], (n, 1)), axis=0)
    y[rng.random((n, m)) < 0.05] = np.nan
    return t, y


def _whole_line(t: np.ndarray, y: np.ndarray, tol: float) -> np.ndarray:
    """The greedy line of the whole series in one call of the kernel (NaN edges marked as line_rows does)."""
    nan = np.isnan(y)
    turned = (nan[1:] != nan[:-1]).any(axis=1)
    edge = np.r_[turned, False] | np.r_[False, turned]
    m = y.shape[1]
    keep, _, _ = line_kernel(t, y, np.full(m, tol), edge, np.empty(m), np.empty(m), 1, True)
    return np.flatnonzero(keep)


@pytest.mark.parametrize("seed", range(6))
def test_line_cut_in_blocks_keeps_the_whole_series_rows(seed):
    rng = np.random.default_rng(seed)
    for _ in range(20):
        n, m = int(rng.integers(1, 300)), int(rng.integers(1, 4))
        t, y = _series(rng, n, m)
        tol = rng.uniform(0.1, 3.0)
        whole = _whole_line(t, y, tol)
        assert 2 < whole.size < n or n < 30  # a real cut: some rows left out
        line, rows, values = LineCut(tol), [], []
        for part in _cuts(rng, n) + [None]:
            got = line.finish() if part is None else line.push(t[part], y[part])
            rows.append(got[0])
            values.append(got[1])
        assert np.array_equal(np.concatenate(rows), whole)
        assert np.array_equal(np.concatenate(values), y[whole], equal_nan=True)


@pytest.mark.parametrize("rate_hz", [10.0, FULL])
def test_path_strips_in_blocks_equal_the_whole_paths(rate_hz):
    rng = np.random.default_rng(7)
    n = 3000
    t = np.arange(n) * 0.05
    # Straight runs and stops, with noise at the tolerance.
    v = np.repeat(rng.normal(scale=0.01, size=(30, 3)) * rng.choice([0.0, 1.0], (30, 1)), 100, axis=0)
    p = np.cumsum(v, axis=0) + rng.normal(scale=0.3 * PATH_TOLERANCE_M, size=(n, 3))
    cycle = np.repeat([0, 1, 2], [1000, 1500, 500])
    path = PathStrips(rate_hz)
    for part in _cuts(rng, n):
        path.push(t[part], p[part], cycle[part])
    whole = path_strips(t, p, cycle, rate_hz)
    assert [len(s) for s in whole] == [1000, 1500, 500] if rate_hz is FULL else sum(len(s) for s in whole) < n / 2
    assert all(np.array_equal(a, b) for a, b in zip(path.strips(), whole, strict=True))
    assert np.array_equal(path.start_times(), t[[0, 1000, 2500]])


def _table(rng: np.random.Generator, n: int) -> pa.Table:
    t = 3.0 + np.cumsum(rng.choice([0.005, 0.005, 0.0050001, 0.01], n))
    return pa.table({"t": t, "a": rng.normal(size=n), "b": rng.normal(size=n)})


def _blocks(rng: np.random.Generator, table: pa.Table) -> list[pa.Table]:
    return [table.take(pa.array(part, pa.int64())) for part in _cuts(rng, table.num_rows)]


@pytest.mark.parametrize("rate_hz", [10.0, 33.0, 1000.0, FULL])
def test_decimated_blocks_are_the_decimated_rows(rate_hz):
    rng = np.random.default_rng(11)
    for n in (1, 2, 5, 700):
        table = _table(rng, n)
        t = table.column("t").to_numpy()
        rows = decimate(t, rate_hz)
        assert rows[-1] == n - 1 and (rate_hz is FULL or rate_hz > 100 or rows.size < n or n < 3)
        assert pa.concat_tables(decimated_blocks(_blocks(rng, table), rate_hz)).equals(table.take(pa.array(rows)))


@pytest.mark.parametrize("rate_hz", [10.0, 33.0, FULL])
def test_mean_rate_in_blocks_is_the_whole_streams(rate_hz):
    rng = np.random.default_rng(5)
    for n in (2, 3, 10, 999, 1000):
        table = _table(rng, n)
        t, values = table.column("t").to_numpy(), np.column_stack([table.column(c).to_numpy() for c in "ab"])
        dt = float(np.median(np.diff(t)))
        assert median_interval(_blocks(rng, table)) == (dt, n)
        step = 1 if rate_hz is FULL else max(1, int(round(1.0 / (rate_hz * dt))))
        k = n // step
        blocks = _blocks(rng, table)
        times, rates = (np.concatenate(x) for x in zip(*mean_rates(blocks, ["a", "b"], rate_hz,
                                                                   median_interval(blocks))))
        assert np.array_equal(times, t[step - 1:k * step:step])
        assert np.array_equal(rates, values[:k * step].reshape(k, step, 2).sum(axis=1) / (step * dt))


def test_sample_times_of_blocks_are_the_distinct_times():
    rng = np.random.default_rng(2)
    table = pa.table({"t": np.repeat(np.arange(50) * 0.5, 7), "support": np.tile(np.arange(7), 50)})
    assert np.array_equal(sample_times(_blocks(rng, table)), np.arange(50) * 0.5)


def test_latest_rows_at_some_times_are_the_forward_filled_rows():
    rng = np.random.default_rng(4)
    t = np.sort(rng.choice(np.arange(40) * 0.5, 300))  # many rows at one time, ids repeated at a time
    ident = rng.integers(0, 6, 300)
    at = np.sort(rng.choice(np.unique(t), 12, replace=False))
    times, ids, rows = latest_rows(t, ident, at)
    assert np.array_equal(times, at) and np.array_equal(ids, np.unique(ident))
    for k, time in enumerate(at):
        for j, one in enumerate(ids):
            mine = np.flatnonzero(ident == one)
            before = mine[t[mine] <= time]
            # the latest state (of two at one time the later row), else the id's first
            assert rows[k, j] == (before[np.lexsort((before, t[before]))[-1]] if before.size
                                  else mine[np.lexsort((mine, t[mine]))[0]])
    assert np.array_equal(latest_rows(t, ident)[2][np.searchsorted(np.unique(t), at)], rows)


@pytest.mark.parametrize("seed", range(4))
def test_latest_frames_of_blocks_are_the_whole_streams_latest_rows(seed):
    """Each id's latest row at the last time of each interval (every time at FULL rate), from blocks cut anywhere (an
    id appearing late takes its first row before): latest_rows of the whole table at those times, in chunks of
    exactly `frames` times (`states` // 7 ids; the last with the rest), the columns' types kept."""
    rng = np.random.default_rng(seed)
    n = 400
    t = np.sort(rng.choice(np.arange(160) * 0.25, n))  # 4 times a second, several rows at one time
    ident = np.where(t < 10.0, rng.integers(0, 5, n), rng.integers(0, 7, n))  # ids 5 and 6 first seen after 10 s
    table = pa.table({"t": t, "id": ident.astype(np.int32), "x": rng.normal(size=n),
                      "flag": rng.integers(0, 2, n).astype(np.int8)})
    for rate_hz in (FULL, 1.0, 0.3):
        times = np.unique(t)
        if rate_hz is not FULL:  # the last time of each interval
            times = times[np.r_[np.diff(np.floor(times * rate_hz + 1e-9)) > 0, True]]
        rows = latest_rows(t, ident, times)[2]
        for states, frames in ((3, 1), (7, 1), (55, 7), (7000, 1000)):
            chunks = list(latest_frames(_blocks(rng, table), "id", ("x", "flag"), rate_hz, states))
            assert [c[0].size for c in chunks[:-1]] == [frames] * (len(chunks) - 1)
            assert 0 < chunks[-1][0].size <= frames
            assert np.array_equal(np.concatenate([c[0] for c in chunks]), times)
            for name in ("x", "flag"):
                whole = table.column(name).to_numpy()[rows]
                got = np.concatenate([c[1][name] for c in chunks])
                assert got.dtype == whole.dtype and got.shape == (times.size, 7) and np.array_equal(got, whole)
    assert list(latest_frames(table.slice(0, 0), "id", ("x",), 1.0, 5)) == []


@pytest.mark.parametrize("rate_hz", [10.0, 2.0, FULL])
def test_marker_cut_in_blocks_keeps_the_whole_tracks_rows(rate_hz):
    """A body's two ends (K, 6) moving in steps, stops and jumps, at times with repeats: MarkerCut over blocks cut
    anywhere keeps marker_rows' rows of the whole track, the last row included."""
    rng = np.random.default_rng(8)
    for _ in range(40):
        n = int(rng.integers(1, 400))
        t = np.cumsum(rng.choice([0.0, 0.01, 0.05, 0.2], n))
        p = np.cumsum(rng.normal(size=(n, 6)) * rng.choice([0.0, 0.001, 0.03], (n, 1)), axis=0)
        whole = marker_rows(t, p, rate_hz)
        assert whole[-1] == n - 1 and (rate_hz is FULL or whole.size < n or n < 3)
        cut = MarkerCut(rate_hz)
        rows = [cut.push(t[part], p[part]) for part in _cuts(rng, n)]
        assert np.array_equal(np.r_[np.concatenate(rows), cut.finish()], whole)


def _visible_rows_whole(t: np.ndarray, values: np.ndarray, rate_hz: float | None, band: bool) -> np.ndarray:
    """visible_rows as it was written for a whole series (before the blocks), the reference of the cut in blocks."""
    keep = decimate(t, rate_hz)
    if rate_hz is FULL or keep.size < 3:
        return keep
    y = np.asarray(values, float).reshape(len(t), -1)[keep]
    t = np.asarray(t, float)[keep]
    finite = y[np.isfinite(y)]
    span = float(finite.max() - finite.min()) if finite.size else 0.0
    line = line_rows(t, y, LINE_TOLERANCE * span)
    if not band:
        return keep[line]
    extremes = band_rows(t, y, BAND_ROWS / rate_hz)
    ident = _intervals(t, BAND_ROWS / rate_hz)
    n = ident[-1] + 1
    slope = np.sign(np.diff(y, axis=0))
    turns = np.r_[False, ((slope[1:] * slope[:-1]) < 0).any(axis=1), False]
    on_line = np.bincount(ident[line], minlength=n)
    noisy = ((2 * on_line > np.bincount(ident, minlength=n)) & (np.bincount(ident, turns, n) >= BAND_TURNS)
             & (np.bincount(ident[extremes], minlength=n) < on_line))
    return keep[np.union1d(line[~noisy[ident[line]]], extremes[noisy[ident[extremes]]])]


def _plotted(rng: np.random.Generator, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """A series at 50 Hz (repeated times, gaps) that is in turns noisy, smooth, flat, stepped and NaN."""
    t = np.cumsum(rng.choice([0.0, 0.02, 0.02, 0.02, 0.5, 3.0], n, p=[0.02, 0.3, 0.3, 0.3, 0.05, 0.03]))
    kind = np.repeat(rng.integers(0, 4, n // 50 + 1), 50)[:n]
    y = np.where((kind == 0)[:, None], rng.normal(size=(n, m)), 0.0)  # noise
    y += np.where((kind == 1)[:, None], np.sin(t[:, None] * rng.uniform(0.1, 3.0, m)), 0.0)  # smooth
    y += np.where((kind == 3)[:, None], rng.integers(0, 2, (n, m)), 0.0)  # 0/1 steps
    y[rng.random((n, m)) < 0.02] = np.nan
    return t, y


@pytest.mark.parametrize("seed", range(3))
def test_visible_cut_in_blocks_keeps_the_whole_series_rows(seed):
    """SeriesRange then VisibleCut over blocks cut anywhere keep the rows (and values) the whole series' cut keeps,
    bit for bit, with and without bands, at record rates of 10 and 2 Hz and FULL; so does visible_rows."""
    rng = np.random.default_rng(seed)
    thinned = 0  # cuts that left record-rate rows out
    for _ in range(8):
        n, m = int(rng.integers(0, 2000)), int(rng.integers(1, 4))
        t, y = _plotted(rng, n, m)
        for rate_hz in (10.0, 2.0, FULL):
            for band in (True, False):
                whole = _visible_rows_whole(t, y, rate_hz, band)
                thinned += int(whole.size < decimate(t, rate_hz).size)
                assert np.array_equal(visible_rows(t, y, rate_hz, band), whole)
                parts = _cuts(rng, n)
                measured = SeriesRange(rate_hz)
                for part in parts:
                    measured.push(t[part], y[part])
                measured.finish()
                cut, got = VisibleCut(rate_hz, measured, band), []
                for part in parts:
                    got.append(cut.push(t[part], y[part]))
                got.append(cut.finish())
                rows, times, values = (np.concatenate(x) for x in zip(*got))
                assert np.array_equal(rows, whole)
                assert np.array_equal(times, t[whole]) and np.array_equal(values, y[whole], equal_nan=True)
    assert thinned >= 8


@pytest.mark.parametrize("rate_hz", [10.0, 2.0, FULL])
def test_interval_reduce_in_blocks_is_reduceat_over_the_decimated_rows(rate_hz):
    """Flags OR-ed and peaks kept over each record interval, from blocks cut anywhere: reduceat over the whole
    series at decimate's rows (a single-sample flag between two record instants stays)."""
    rng = np.random.default_rng(9)
    for _ in range(30):
        n = int(rng.integers(0, 500))
        t = np.cumsum(rng.choice([0.0, 0.02, 0.1, 0.7], n))
        flags = np.where(rng.random(n) < 0.05, 1 << rng.integers(0, 3, n), 0).astype(np.int32)
        peaks = np.where(rng.random((n, 2)) < 0.1, np.nan, rng.normal(size=(n, 2)))
        keep = decimate(t, rate_hz)
        for values, reduce in ((flags, np.bitwise_or), (peaks, np.fmax)):
            cut, got = IntervalReduce(rate_hz, reduce), []
            for part in _cuts(rng, n):
                got.append(cut.push(t[part], values[part]))
            got.append(cut.finish())
            times, reduced = (np.concatenate(x) for x in zip(*got))
            assert np.array_equal(times, t[keep])
            if n:
                assert np.array_equal(reduced, reduce.reduceat(values, keep, axis=0), equal_nan=True)
                assert reduced.dtype == values.dtype


def _per_support(rng: np.random.Generator) -> pa.Table:
    """A per-support stream in time order: several rows at a time, some supports missing, a row repeated late."""
    t = np.repeat(np.arange(120) * 0.5, 6)
    support = np.tile(np.arange(6), 120)
    keep = rng.random(t.size) < 0.8
    t, support = np.r_[t[keep], t[-1]], np.r_[support[keep], support[keep][-1]]
    leg = np.where(rng.random(t.size) < 0.1, np.nan, rng.normal(30, 5, t.size))
    leg[rng.random(t.size) < 0.2] = 0.0
    leg[rng.random(t.size) < 0.2] = -0.0  # a lowered leg: which zero is the lowest goes by the rows' order
    return pa.table({"t": t, "support": support.astype(np.int32), "leg": leg, "ram": rng.normal(10, 3, t.size)})


@pytest.mark.parametrize("cells", [6, 40, 10_000])
def test_bar_frames_of_blocks_are_the_whole_streams_grids(cells):
    """Each support's latest reading at the times shown, from blocks cut anywhere, in chunks of cells // supports
    times: the grid filled from the whole table (NaN where a support has no row at a time)."""
    rng = np.random.default_rng(3)
    table = _per_support(rng)
    t, support = table.column("t").to_numpy(), table.column("support").to_numpy()
    shown = np.unique(t)[::3]
    whole = np.full((shown.size, 6), np.nan)
    rows = np.flatnonzero(np.isin(t, shown))
    whole[np.searchsorted(shown, t[rows]), support[rows]] = table.column("leg").to_numpy()[rows]
    chunks = list(bar_frames(_blocks(rng, table), shown, ("leg", "ram"), cells))
    assert [c[0].size for c in chunks[:-1]] == [max(1, cells // 6)] * (len(chunks) - 1)
    assert np.array_equal(np.concatenate([c[0] for c in chunks]), shown)
    assert np.array_equal(np.concatenate([c[1][0] for c in chunks]), whole, equal_nan=True)
    assert len(list(bar_frames(_blocks(rng, table), shown[:0], ("leg",), cells))) == 1  # nothing shown: one empty


def test_pressure_extremes_of_blocks_are_the_whole_streams():
    rng = np.random.default_rng(6)
    table = _per_support(rng)
    t = table.column("t").to_numpy()
    times = np.unique(t)
    whole = np.full((times.size, 2), np.nan)
    np.fmin.at(whole[:, 0], np.searchsorted(times, t), table.column("leg").to_numpy())
    np.fmax.at(whole[:, 1], np.searchsorted(times, t), table.column("ram").to_numpy())
    got_t, got = (np.concatenate(x) for x in zip(*pressure_extremes(_blocks(rng, table))))
    assert np.array_equal(got_t, times) and np.array_equal(got.view(np.int64), whole.view(np.int64))  # bit for bit


@pytest.mark.parametrize("seed", [5, 6])
def test_plotted_series_from_a_one_shot_generator_sends_the_whole_series_rows(seed, monkeypatch):
    """PlottedSeries reads its blocks once (measure spools them; send reads the spool): a generator cut anywhere
    sends, per entity, the rows the whole series in one block sends; a second send has nothing to read."""
    rng = np.random.default_rng(seed)
    t, y = _series(rng, 3000, 3)
    flags = (rng.random((t.size, 1)) < 0.01).astype(float)
    sent: dict[str, list] = {}

    def capture(rec, entity, names):
        return RowBatches(lambda tt, values: sent.setdefault(entity, []).append((tt, values)))

    monkeypatch.setattr(rerun_columns, "series_batches", capture)
    names = {"plots/y": ["a", "b", "c"], "plots/flag": ["flag"]}
    whole = PlottedSeries(names, 2.0, ["plots/flag"])
    whole.log(None, [{"plots/y": (t, y), "plots/flag": (t, flags)}])
    expected, sent = sent, {}
    cut = PlottedSeries(names, 2.0, ["plots/flag"])
    cut.log(None, ({"plots/y": (t[i], y[i]), "plots/flag": (t[i], flags[i])} for i in _cuts(rng, t.size)))
    assert sent.keys() == expected.keys()
    for entity in expected:
        got = [np.concatenate(c) for c in zip(*sent[entity])]
        want = [np.concatenate(c) for c in zip(*expected[entity])]
        assert all(np.array_equal(g, w, equal_nan=True) for g, w in zip(got, want))
    assert sum(len(tt) for tt, _ in expected["plots/y"]) < t.size  # the cut left rows out
    with pytest.raises(RuntimeError, match="before measure"):
        cut.send(None)
