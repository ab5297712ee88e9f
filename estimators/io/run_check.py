"""A run directory checked before the estimators work on it: metrics.json readable, and the log's own layout the one
its scenario describes (sample rates, the supports whose push rams and canopy units report, the odometer's pulse
length), so an edited or foreign scenario.toml is refused instead of changing the results silently. The streams are
read a row group at a time: the check's memory does not grow with the log."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from estimators.io.logformat import (
    ODOMETER,
    PUSHRAM,
    STREAMS,
    SUPPORT_IMU,
    LogError,
    StreamBlocks,
)
from estimators.io.stream_median import StreamMedian

METRICS_FILE = "metrics.json"
RATE_TOLERANCE = 0.02
"""Relative difference allowed between a stream's median sample interval and the one its rate gives."""
PULSE_TOLERANCE = 1e-6
"""Relative difference allowed between distance / pulses and the nominal metres per pulse."""


@dataclass(frozen=True)
class Expected:
    """A value the scenario gives and where it gives it (e.g. "[sensors.imu] rate_hz"), for the messages."""

    value: object
    key: str


@dataclass(frozen=True)
class LogLayout:
    """What the scenario says the log holds."""

    rates_hz: dict[str, Expected] = field(default_factory=dict)
    """Stream name -> sample rate [Hz]."""
    ram_supports: Expected | None = None
    """Number of supports; the push-ram stream reports supports 0 .. n-1."""
    imu_supports: Expected | None = None
    """Tuple of the supports with canopy units (the support_imu stream)."""
    metres_per_pulse: Expected | None = None
    """The odometer's nominal pulse length [m] (its distance column is pulses times it)."""
    source: str = "scenario.toml"


def read_metrics(run_dir: Path) -> dict:
    """metrics.json of a run directory ({} without one); LogError naming the file and the fix when it is damaged."""
    path = Path(run_dir) / METRICS_FILE
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        data = err
    if not isinstance(data, dict):
        why = f"not valid JSON ({data})" if isinstance(data, Exception) else "not a JSON object"
        raise LogError(f"{path}: {why}; move the damaged file away (`longwall estimate {run_dir}` then writes the "
                       f"estimators' metrics anew) or restore it from a copy")
    return data


def check_layout(run_dir: Path, layout: LogLayout) -> None:
    """LogError naming the stream file, the scenario key and the fix where the log disagrees with `layout`."""
    run_dir = Path(run_dir)
    for name, rate in layout.rates_hz.items():
        if (run_dir / STREAMS[name].filename).is_file():
            _check_rate(run_dir, name, rate, layout.source)
    if layout.ram_supports is not None and (run_dir / PUSHRAM.filename).is_file():
        n = int(layout.ram_supports.value)
        _check_supports(run_dir, PUSHRAM.name, tuple(range(n)), f"{n} supports 0-{n - 1} ({layout.ram_supports.key})",
                        layout.source)
    if layout.imu_supports is not None and (run_dir / SUPPORT_IMU.filename).is_file():
        ids = tuple(layout.imu_supports.value)
        _check_supports(run_dir, SUPPORT_IMU.name, ids, f"canopy units on supports {list(ids)} "
                        f"({layout.imu_supports.key})", layout.source)
    if layout.metres_per_pulse is not None and (run_dir / ODOMETER.filename).is_file():
        _check_pulses(run_dir, layout.metres_per_pulse, layout.source)


def _check_rate(run_dir: Path, name: str, rate: Expected, source: str) -> None:
    """The stream's median positive sample interval against `rate`, read a row group at a time (the exact median in
    bounded memory: estimators.io.stream_median)."""
    steps, last = StreamMedian(), None
    for block in StreamBlocks(run_dir, STREAMS[name], ("t",)):
        t = block.column("t").to_numpy()
        dt = np.diff(t, prepend=t[:0] if last is None else last)
        steps.push(dt[dt > 0])
        last = t[-1:] if t.size else last
    if steps.count == 0:
        return
    median = steps.median()
    if abs(median * float(rate.value) - 1.0) > RATE_TOLERANCE:
        raise LogError(f"{run_dir / STREAMS[name].filename}: samples every {median:.6g} s ({1 / median:.6g} Hz), "
                       f"but {source} {rate.key} = {rate.value:g}; set {rate.key} = {1 / median:.6g}, or give this "
                       f"recording its own scenario")


def _check_supports(run_dir: Path, name: str, expected: tuple[int, ...], what: str, source: str) -> None:
    path = run_dir / STREAMS[name].filename
    ids = np.unique(np.concatenate([np.unique(block.column("support").to_numpy())
                                    for block in StreamBlocks(run_dir, STREAMS[name], ("t", "support"))]))
    extra = sorted(set(ids.tolist()) - set(expected))
    missing = sorted(set(expected) - set(ids.tolist()))
    if extra or missing:
        found = f"rows for supports {_ranges(extra)}" if extra else f"no rows for supports {_ranges(missing)}"
        raise LogError(f"{path}: {found}, but {source} has {what}; correct the scenario to the face of this "
                       f"recording")


def _check_pulses(run_dir: Path, mpp: Expected, source: str) -> None:
    nominal, first_row = float(mpp.value), 0
    for odo in StreamBlocks(run_dir, ODOMETER, ("t", "distance", "pulses")):
        distance, pulses = odo.column("distance").to_numpy(), odo.column("pulses").to_numpy().astype(float)
        with np.errstate(divide="ignore", invalid="ignore"):
            off = np.abs(distance - pulses * nominal) / (np.abs(pulses) * nominal)
        bad = np.flatnonzero((pulses != 0) & ~(off <= PULSE_TOLERANCE))
        if bad.size:
            i = int(bad[0])
            raise LogError(f"{run_dir / ODOMETER.filename}: row {first_row + i}: distance {distance[i]:.6g} m for "
                           f"{pulses[i]:.0f} pulses is {distance[i] / pulses[i]:.6g} m per pulse, but {source} "
                           f"{mpp.key} = {nominal:g}; set {mpp.key} to the odometer's pulse length")
        first_row += odo.num_rows


def _ranges(ids: list[int]) -> str:
    """[0, 1, 2, 5] -> '0-2, 5' (the first ten runs)."""
    runs: list[list[int]] = []
    for i in ids:
        if runs and i == runs[-1][1] + 1:
            runs[-1][1] = i
        else:
            runs.append([i, i])
    text = ", ".join(f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:10])
    return text + (", ..." if len(runs) > 10 else "")
