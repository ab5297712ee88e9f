"""A batch of canopy units for the support filters: readings as (units, samples, 3) arrays, so that one kernel call
runs every unit's filter (estimators.support.filters_002, estimators.support.error_state).

`batch_inputs` checks a filter call's arrays; `support_batch` turns a face's SUPPORT_IMU stream (one row per
support and sample) into a `SupportBatch`, the units it cannot use left out with their reason.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np


def _batch(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a, float)
    if a.ndim == 2:
        a = a[None]
    if a.ndim != 3 or a.shape[-1] != 3:
        raise ValueError(f"{name} must have shape (K, 3) or (N, K, 3), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has NaN or infinite samples")
    return np.ascontiguousarray(a)


def batch_inputs(gyro, accel, mag):
    """gyro, accel and mag of a filter call checked and as contiguous (N, K, 3) arrays: (K, 3) is one unit; all
    three the same shape, every sample finite (ValueError otherwise)."""
    gyro, accel, mag = _batch(gyro, "gyro"), _batch(accel, "accel"), _batch(mag, "mag")
    if not gyro.shape == accel.shape == mag.shape:
        raise ValueError(f"gyro, accel and mag differ in shape: {gyro.shape}, {accel.shape}, {mag.shape}")
    return gyro, accel, mag


@dataclass(frozen=True)
class SupportBatch:
    """The SUPPORT_IMU stream of a face as arrays over supports and samples: one batched call per filter."""

    t: np.ndarray  # (K,) [s] the sample times every support kept shares
    supports: np.ndarray  # (N,) support index of each row of the arrays
    gyro: np.ndarray  # (N, K, 3) [rad/s] in the canopy frame c
    accel: np.ndarray  # (N, K, 3) [m/s^2] in c
    mag: np.ndarray  # (N, K, 3) [T] in c
    skipped: dict[int, str]  # support left out -> why (one line)
    dt: float  # [s] the sample interval


def support_batch(columns: Mapping[str, np.ndarray], expected: Iterable[int] = ()) -> SupportBatch:
    """SUPPORT_IMU columns (t, support, gyro_x .. mag_z: estimators.io.logformat) as (N, K, 3) arrays.

    Never passes on a non-finite value: a support is left out, with its reason in `skipped`, when it is in
    `expected` but has no rows, when one of its readings is NaN or infinite, or when its sample times are not the
    common ones (the times at least half of the other supports have). ValueError (one line) when no support is
    left or the common times are not uniformly spaced (the filters take one interval dt).
    """
    t = np.asarray(columns["t"], float)
    ids = np.asarray(columns["support"], np.int64)
    sensors = {name: np.stack([np.asarray(columns[f"{name}_{a}"], float) for a in "xyz"], axis=-1)
               for name in ("gyro", "accel", "mag")}
    finite = np.isfinite(t)
    for v in sensors.values():
        finite &= np.isfinite(v).all(axis=1)
    skipped: dict[int, str] = {int(j): "no rows in support_imu" for j in set(expected) - set(ids.tolist())}
    rows = {}
    for j in np.unique(ids):
        sel = np.flatnonzero(ids == j)
        bad = sel[~finite[sel]]
        if bad.size:
            skipped[int(j)] = f"{bad.size} of its {sel.size} rows have NaN or infinite values (first: row {bad[0]})"
        else:
            rows[int(j)] = sel[np.argsort(t[sel], kind="stable")]
    times, counts = np.unique(np.concatenate([t[r] for r in rows.values()] or [np.zeros(0)]), return_counts=True)
    grid = times[2 * counts >= len(rows)]
    for j, r in list(rows.items()):
        if r.size != grid.size or np.any(t[r] != grid):
            missing, extra = np.setdiff1d(grid, t[r]).size, r.size - np.intersect1d(grid, t[r]).size
            skipped[j] = f"{missing} of the {grid.size} common sample times missing, {extra} others"
            del rows[j]
    if not rows:
        reasons = "; ".join(f"support {j}: {why}" for j, why in sorted(skipped.items()))
        raise ValueError(f"support_imu: no support with usable readings ({reasons or 'the stream is empty'})")
    steps = np.diff(grid)
    dt = float(np.median(steps)) if steps.size else 0.0
    if not dt > 0 or np.any(np.abs(steps - dt) > 1e-6 * dt):
        at = int(np.argmax(np.abs(steps - dt))) if steps.size else 0
        raise ValueError(f"support_imu: the sample times are not uniform (step {steps[at] if steps.size else 0:g} s "
                         f"at t = {grid[at]:g} s, median {dt:g} s); the filters need one sample interval")
    order = np.array(sorted(rows))
    sel = np.stack([rows[j] for j in order])
    return SupportBatch(grid, order, *(np.ascontiguousarray(sensors[name][sel]) for name in ("gyro", "accel", "mag")),
                        dict(sorted(skipped.items())), dt)
