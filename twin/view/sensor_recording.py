"""The sensor streams of a run in its Rerun recording (twin.view.recording): every channel as time series (fast
streams averaged to the record rate), the push-ram readings, pressures and face alignment offsets as bar charts
per support, the fault windows as 0/1 steps.

Entities: `sensors/imu/{gyro,accel}`, `sensors/odometer/distance`, `sensors/mag`, `sensors/support_imu/J/...`,
`sensors/pushram`, `sensors/pressure/{leg_bars,ram_bars,extremes}`, `alignment/{offsets_mm,sequence}`,
`faults/KIND[_TARGET]`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pyarrow as pa
import pyarrow.compute  # noqa: F401  (pa.compute)
import rerun as rr

from twin.view.record_rate import FULL
from twin.view.rerun_columns import PlottedSeries, mean_rates, median_interval, send_bar_chart, series, vec
from twin.view.row_cuts import Blocks, blocks_of, bounded, col, decimate, decimated_blocks


def log_sensors(rec: rr.RecordingStream, sensors: dict[str, Blocks], rate_hz: float | None) -> None:
    """Every sensor channel as time series (fast streams averaged to about rate_hz), fault windows as
    0/1 steps, the ram readings as a bar chart per support. The imu, pushram and pressure streams may come in blocks
    (twin.view.row_cuts.Blocks), the others as tables."""
    # The long streams are read a block at a time (PlottedSeries: their ranges, then their cut from its spool).
    if "imu" in sensors:
        imu, interval = sensors["imu"], median_interval(sensors["imu"])
        increments = [f"{p}_{a}" for p in ("dtheta", "dv") for a in "xyz"]
        PlottedSeries({f"sensors/imu/{name}": [f"{a} [{label}]" for a in "xyz"]
                       for name, label in (("gyro", "rad/s"), ("accel", "m/s^2"))}, rate_hz).log(rec, (
            {"sensors/imu/gyro": (t, rates[:, :3]), "sensors/imu/accel": (t, rates[:, 3:])}
            for t, rates in mean_rates(bounded(imu), increments, rate_hz, interval)))
    # Of the other long streams the rows at the record rate (series decimates them the same again).
    if "odometer" in sensors:
        PlottedSeries({"sensors/odometer/distance": ["distance [m]"]}, rate_hz).log(rec, (
            {"sensors/odometer/distance": (col(odo, "t"), col(odo, "distance")[:, None])}
            for odo in decimated_blocks(bounded(sensors["odometer"]), rate_hz)))
    if "mag" in sensors:
        PlottedSeries({"sensors/mag": [f"{a} [uT]" for a in "xyz"]}, rate_hz).log(rec, (
            {"sensors/mag": (col(mag, "t"), vec(mag, "b", "xyz") * 1e6)}
            for mag in decimated_blocks(bounded(sensors["mag"]), rate_hz)))
    if "support_imu" in sensors:
        units = sensors["support_imu"]
        for j in np.unique(col(units, "support")):
            rows = units.filter(pa.compute.equal(units.column("support"), int(j)))
            series(rec, f"sensors/support_imu/{j}/accel", col(rows, "t"), vec(rows, "accel", "xyz"),
                   [f"{a} [m/s^2]" for a in "xyz"], rate_hz=rate_hz)
            series(rec, f"sensors/support_imu/{j}/gyro", col(rows, "t"), vec(rows, "gyro", "xyz"),
                   [f"{a} [rad/s]" for a in "xyz"], rate_hz=rate_hz)
    if "pushram" in sensors:
        ram = sensors["pushram"]
        times = sample_times(ram)
        shown = times[decimate(times, FULL if rate_hz is FULL else min(rate_hz, 0.2))]
        for frames, (grid,) in bar_frames(ram, shown, ("extension",)):
            send_bar_chart(rec, "sensors/pushram", frames, grid)
    if "pressure" in sensors:
        _log_pressures(rec, sensors["pressure"], rate_hz)
    if "alignment" in sensors and sensors["alignment"].num_rows:
        _log_alignment(rec, sensors["alignment"])
    if "faults" in sensors and sensors["faults"].num_rows:
        faults = sensors["faults"]
        for kind, target, t0, t1 in zip(faults.column("kind").to_pylist(), col(faults, "target"),
                                       col(faults, "t_start"), col(faults, "t_end")):
            name = f"faults/{kind}" + (f"_{target}" if target >= 0 else "")
            series(rec, name, np.array([0.0, t0, t1]), np.array([[0.0], [1.0], [0.0]]), [f"{name} active"])


def _log_alignment(rec: rr.RecordingStream, alignment: pa.Table) -> None:
    """The offsets each cycle's push applied as a bar chart per support (mm), at the cycle's start, and the face
    alignment system's sequence number of the set applied."""
    t, cycle, support = col(alignment, "t"), col(alignment, "cycle"), col(alignment, "support")
    grid = np.zeros((int(cycle.max()) + 1, int(support.max()) + 1))
    grid[cycle, support] = col(alignment, "offset") * 1e3
    starts, sequence = np.zeros((2, grid.shape[0]))
    starts[cycle], sequence[cycle] = t, col(alignment, "sequence")
    send_bar_chart(rec, "alignment/offsets_mm", starts, grid)
    series(rec, "alignment/sequence", starts, sequence[:, None], ["SequenceNumber applied"], band=False)


PRESSURE_BAR_HZ = 0.2
"""Rate of the pressure bar charts (one bar per support) at the default record rate."""


def _log_pressures(rec: rr.RecordingStream, pressure: Blocks, rate_hz: float | None) -> None:
    """The legs' and rams' pressure readings as a bar chart per support each, and the face's lowest leg pressure and
    highest ram pressure as time series (a support that failed to set, a leaking leg, a stalled ram stand out)."""
    times = sample_times(pressure)
    shown = times[decimate(times, FULL if rate_hz is FULL else min(rate_hz, PRESSURE_BAR_HZ))]
    for frames, grids in bar_frames(pressure, shown, ("leg", "ram")):
        for column, grid in zip(("leg", "ram"), grids):
            send_bar_chart(rec, f"sensors/pressure/{column}_bars", frames, grid)
    PlottedSeries({"sensors/pressure/extremes": ["lowest leg [MPa]", "highest ram [MPa]"]}, rate_hz).log(
        rec, ({"sensors/pressure/extremes": rows} for rows in pressure_extremes(pressure)))


def pressure_extremes(pressure: Blocks) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """The lowest leg and highest ram pressure at each time of the stream (NaN-ignoring, NaN where a time has no
    reading) a block at a time: (times, (k, 2)); the rows of a block's last time held for the next block's."""
    held_t, held = np.zeros(0), np.zeros((0, 2))
    for block in bounded(pressure):
        t = np.r_[held_t, col(block, "t")]
        rows = np.concatenate([held, np.column_stack([col(block, "leg"), col(block, "ram")])])
        if not t.size:
            continue
        times, at = np.unique(t, return_inverse=True)
        extremes = np.full((times.size, 2), np.nan)
        np.fmin.at(extremes[:, 0], at, rows[:, 0])  # in row order, as a whole stream's (the sign of a zero kept)
        np.fmax.at(extremes[:, 1], at, rows[:, 1])
        held_t, held = times[-1:], extremes[-1:]
        yield times[:-1], extremes[:-1]
    yield held_t, held


def sample_times(data: Blocks) -> np.ndarray:
    """The distinct times of a stream (one table or blocks), sorted: a per-support stream has many rows at each."""
    times = np.zeros(0)
    for block in blocks_of(data):
        times = np.unique(np.r_[times, np.unique(col(block, "t"))])
    return times


BAR_CELLS = 250_000
"""Bars (times x supports) of a per-support bar chart built and sent at a time."""


def bar_frames(data: Blocks, shown: np.ndarray, columns: tuple[str, ...], cells: int = BAR_CELLS
               ) -> Iterator[tuple[np.ndarray, list[np.ndarray]]]:
    """A per-support stream's `columns` at the times `shown` (sorted), each as (times, supports) with NaN where a
    support has no row (the later of two rows at one time), F = cells // supports times at a time (at least one
    chunk): (times (F,), a grid per column), from one pass over its blocks in time order (and one for the supports)."""
    n_sup = max(int(col(block, "support").max(initial=-1)) for block in blocks_of(data)) + 1
    frames = max(1, cells // max(n_sup, 1))
    chunks = max(1, -(-shown.size // frames))

    def grids(k: int) -> list[np.ndarray]:
        return [np.full((shown[k * frames:(k + 1) * frames].size, n_sup), np.nan) for _ in columns]

    k, held = 0, grids(0)
    for block in blocks_of(data):
        t = col(block, "t")
        at = np.minimum(np.searchsorted(shown, t), max(shown.size - 1, 0))
        hit = np.flatnonzero(shown[at] == t) if shown.size else np.zeros(0, int)
        at, support = at[hit], col(block, "support")[hit]
        values = [col(block, column)[hit] for column in columns]
        chunk = at // frames
        last = int(chunk.max(initial=k))
        for j in range(k, last + 1):  # the rows of a later chunk: the earlier ones are complete (time order)
            mine = chunk == j
            for grid, value in zip(held, values):
                grid[at[mine] - j * frames, support[mine]] = value[mine]
            if j < last:
                yield shown[j * frames:(j + 1) * frames], held
                k, held = j + 1, grids(j + 1)
    for j in range(k, chunks):
        yield shown[j * frames:(j + 1) * frames], held
        held = grids(j + 1)
