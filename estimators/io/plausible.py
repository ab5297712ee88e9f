"""Physical ranges of the sensor streams' values: a value outside them is not a reading but a broken file, a
wrong unit or a corrupted row (a 1e300 accelerometer increment, a 12 km odometer jump in one sample).

The limits are far outside what any longwall sensor reports, so no real or simulated reading comes near them;
they stop values that would overflow the filters. Rates are checked on the increments: an increment over
(t_prev, t] divided by its interval (the first row of a log takes the interval that follows it, 1 s when it is
the only row), the odometer's distance as its step from the row before. Truth and
estimate streams have no limits here (the twin writes them, the estimators check their own health).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa


@dataclass(frozen=True)
class Limit:
    """|value| (or |value / interval| with `per_second`) must lie in [lo, hi]; `what` names the quantity."""

    columns: tuple[str, ...]
    lo: float
    hi: float
    what: str
    per_second: bool = False
    unit: str = ""


_XYZ = ("x", "y", "z")
_POS = (Limit(("lat",), -math.pi / 2, math.pi / 2, "latitude", unit="rad"),
        Limit(("lon",), -2 * math.pi, 2 * math.pi, "longitude", unit="rad"),
        Limit(("h",), -1e4, 1e5, "ellipsoidal height", unit="m"),
        Limit(("sd_horizontal", "sd_vertical"), 0.0, 1e3, "survey one-sigma", unit="m"))
TIME = Limit(("t",), -1e9, 1e9, "time from the start of the recording (not an absolute clock time)", unit="s")
LIMITS: dict[str, tuple[Limit, ...]] = {
    "imu": (Limit(tuple(f"dtheta_{a}" for a in _XYZ), -100.0, 100.0, "angular rate", True, "rad/s"),
            Limit(tuple(f"dv_{a}" for a in _XYZ), -1e3, 1e3, "acceleration", True, "m/s^2")),
    "odometer": (Limit(("distance",), -1e7, 1e7, "travelled distance", unit="m"),
                 Limit(("distance",), -20.0, 20.0, "haulage speed (odometer jump)", True, "m/s"),
                 Limit(("direction",), -1, 1, "direction (-1, 0 or +1)", unit="1")),
    "pushram": (Limit(("support",), 0, 1e5, "support index", unit="1"),
                Limit(("extension",), -100.0, 100.0, "ram extension", unit="m"),
                Limit(("valid",), 0, 1, "valid flag (0 or 1)", unit="1")),
    "pressure": (Limit(("support",), 0, 1e5, "support index", unit="1"),
                 Limit(("leg", "ram"), -100.0, 1000.0, "hydraulic pressure", unit="MPa"),
                 Limit(("valid_leg", "valid_ram"), 0, 1, "valid flag (0 or 1)", unit="1")),
    "mag": (Limit(tuple(f"b_{a}" for a in _XYZ), -0.1, 0.1, "magnetic flux density", unit="T"),),
    "support_imu": (Limit(("support",), 0, 1e5, "support index", unit="1"),
                    Limit(tuple(f"gyro_{a}" for a in _XYZ), -100.0, 100.0, "angular rate", unit="rad/s"),
                    Limit(tuple(f"accel_{a}" for a in _XYZ), -1e3, 1e3, "acceleration", unit="m/s^2"),
                    Limit(tuple(f"mag_{a}" for a in _XYZ), -0.1, 0.1, "magnetic flux density", unit="T")),
    "faults": (Limit(("target",), -1, 1e5, "fault target (a support index or -1)", unit="1"),
               Limit(("t_start", "t_end"), -1e9, 1e9, "fault window time", unit="s")),
    "alignment": (Limit(("cycle", "support", "sequence"), 0, 1e7, "cycle, support or sequence number", unit="1"),
                  Limit(("offset",), -1.0, 1.0, "push offset", unit="m"),
                  Limit(("sd",), 0.0, 1.0, "offset one-sigma", unit="m")),
    "survey": (*_POS, Limit(("yaw",), -4 * math.pi, 4 * math.pi, "yaw", unit="rad"),
               Limit(("sd_yaw",), 0.0, 2 * math.pi, "yaw one-sigma", unit="rad")),
    "face_survey": (Limit(("u",), -1e5, 1e5, "distance along the face", unit="m"), *_POS),
}
"""The limits of each sensor stream (streams not named here have none, beside TIME)."""


def first_implausible(stream_name: str, table: pa.Table, before: dict[str, float] | None = None
                      ) -> tuple[int, str, str] | None:
    """(row index, column, what is wrong) of the first value of `table` outside its stream's limits, or None.

    `before` holds the values of the row before the table's first (a log read in blocks); NaN values are left
    to the NaN checks. Only the columns the table holds are checked."""
    before = before or {}
    limits = LIMITS.get(stream_name, ()) + (TIME,)
    names = set(table.column_names)
    t = table.column("t").to_numpy(zero_copy_only=False).astype(float) if "t" in names else None
    interval = None
    found: list[tuple[int, str, str]] = []
    for limit in limits:
        for name in limit.columns:
            if name not in names:
                continue
            raw = table.column(name).to_numpy(zero_copy_only=False).astype(float)
            values = raw
            if limit.per_second:
                if t is None or t.size < 1:
                    continue
                if interval is None:
                    interval = _intervals(t, before.get("t"))
                with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                    raw = np.diff(raw, prepend=before.get(name, np.nan)) if name == "distance" else raw
                    values = raw / interval
            with np.errstate(invalid="ignore"):
                bad = np.flatnonzero((values < limit.lo) | (values > limit.hi))
            if bad.size:
                i = int(bad[0])
                unit = "" if limit.unit == "1" else f" {limit.unit}"
                value = f"{values[i]:.6g}{unit}"
                if limit.per_second:
                    raw_unit = (table.schema.field(name).metadata or {}).get(b"unit", b"").decode()
                    step = "a step of " if name == "distance" else ""
                    value = f"{step}{raw[i]:.6g} {raw_unit} in {interval[i]:.6g} s ({value})"
                what = f"{value} is not a possible {limit.what} (limits {limit.lo:g} .. {limit.hi:g}{unit})"
                found.append((i, name, what))
    return min(found, default=None)


def _intervals(t: np.ndarray, t_before: float | None) -> np.ndarray:
    """Each row's sample interval (t_prev, t]; the first row of a log takes the next interval (1 s without one)."""
    dt = np.diff(t, prepend=np.nan if t_before is None else t_before)
    if t_before is None:
        dt[0] = t[1] - t[0] if t.size > 1 else 1.0
    return np.where(dt > 0, dt, np.nan)
