"""The supports' canopy attitude in estimates.rrd (twin.pipeline.support_estimate.SupportAttitude, issue 8): the
`plots/support_attitude/...` entities of twin.view.estimate_recording's docstring."""

from __future__ import annotations

import numpy as np
import rerun as rr

from twin.pipeline.support_estimate import ANGLES, FLAG_NAMES, SupportAttitude
from twin.view.rerun_columns import series
from twin.view.row_cuts import decimate

SUPPORT_PLOT_RATE_HZ = 2.0
"""Largest rate of the supports' plots: a canopy moves over seconds (an advance, the shearer's pass), and a face has
many units."""


def log_support_attitude(rec: rr.RecordingStream, supports: SupportAttitude, rate_hz: float | None) -> None:
    """Each support's angles (with the truth) and errors per method, ours' flags (OR-ed over each plot
    interval) with the shearer's field, the GD objective; decimated to rate_hz, sent column-wise."""
    root = "plots/support_attitude"
    for name, t in supports.t.items():
        keep = decimate(t, rate_hz)
        est = np.degrees(supports.euler[name][:, keep])
        truth = np.degrees(supports.truth_euler[name][:, keep]) if supports.truth_euler else None
        for i, j in enumerate(supports.supports):
            for a, angle in enumerate(ANGLES):
                series(rec, f"{root}/angles/{angle}/{j}/{name}", t[keep], est[i, :, a:a + 1],
                       [f"support {j} {name} [deg]"], rate_hz=rate_hz)
                if truth is not None:
                    series(rec, f"{root}/errors/{angle}/{j}/{name}", t[keep],
                           ((est[i, :, a] - truth[i, :, a] + 180.0) % 360.0 - 180.0)[:, None],
                           [f"support {j} {name} [deg]"], rate_hz=rate_hz)
                    if name == "ours":
                        series(rec, f"{root}/angles/{angle}/{j}/truth", t[keep], truth[i, :, a:a + 1],
                               [f"support {j} truth [deg]"], rate_hz=rate_hz)
    t = supports.t["ours"]
    keep = decimate(t, rate_hz)
    for i, j in enumerate(supports.supports):
        flags = np.bitwise_or.reduceat(supports.flags[i].astype(np.int64), keep)
        values = [(flags & bit) != 0 for _, bit in FLAG_NAMES]
        labels = [f"support {j} ours {label}" for label, _ in FLAG_NAMES]
        if supports.near is not None:
            values.append(np.maximum.reduceat(supports.near[i], keep))
            labels.append(f"support {j} shearer's field / peak")
        series(rec, f"{root}/magnetometer/{j}", t[keep], np.column_stack(values).astype(float), labels,
               rate_hz=rate_hz, band=False)
    if supports.objective:
        rec.log(f"{root}/gd_objective", rr.BarChart(np.degrees(supports.objective)), static=True)
