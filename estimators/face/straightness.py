"""Straightness and creep of the face line, from pan positions in the face frame F or from a log's truth_pans table.

Straightness is the spread of the pans' advance x about the best-fit line through them against the along-face y
(least squares, x = a + b y): its RMS and largest absolute deviation. Creep is the along-face displacement of the
pans since a reference line: the mean y shift of all pans, and that of the tailgate drive frame (the last pan).
Both work on any number of lines at once (leading axes) and on any log with truth (simulated, or a face surveyed).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def line_deviation(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Deviation of x from its least-squares line in y, along the last axis (shape of x)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    y_c = y - y.mean(axis=-1, keepdims=True)
    x_c = x - x.mean(axis=-1, keepdims=True)
    slope = (x_c * y_c).sum(axis=-1, keepdims=True) / (y_c * y_c).sum(axis=-1, keepdims=True)
    return x_c - slope * y_c


def straightness(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """RMS and largest absolute deviation [m] of the pan line (x, y in F, pans along the last axis) from its
    best-fit line."""
    dev = line_deviation(x, y)
    return np.sqrt((dev * dev).mean(axis=-1)), np.abs(dev).max(axis=-1)


def mat_ft(azimuth_rad: float) -> np.ndarray:
    """C_t^F: tangent-plane (ENU) components to face-frame components; F's y axis along the face azimuth (degrees
    clockwise from north, here in radians), x 90 deg clockwise from it (DESIGN, twin.face.layout.FaceFrame)."""
    a = azimuth_rad
    return np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])


def sd_in_face_frame(sd_enu: np.ndarray, azimuth_rad: float) -> np.ndarray:
    """One-sigma along F's x, y, z (..., 3) from the tangent plane's east, north, up one-sigma (..., 3) taken as
    independent."""
    return np.sqrt(np.asarray(sd_enu, float) ** 2 @ (mat_ft(azimuth_rad) ** 2).T)


def pan_lines(pans: dict[str, np.ndarray], times: np.ndarray, n_pans: int, azimuth_rad: float) -> np.ndarray:
    """Every pan's position in F (T, N, 3) as it stood at each of `times`: its latest row of the truth_pans columns
    (t, pan, p_t_e/n/u) at or before the time. A pan with no row by then is NaN."""
    t, pan = np.asarray(pans["t"], float), np.asarray(pans["pan"], int)
    times = np.asarray(times, float)
    t0 = min(t.min(), times.min())
    span = max(t.max(), times.max()) - t0 + 1.0  # keys pan * span + t: each pan's rows apart, in time order
    key = pan * span + (t - t0)
    order = np.argsort(key, kind="stable")
    query = np.arange(n_pans)[None, :] * span + (times[:, None] - t0)
    row = order[np.clip(np.searchsorted(key[order], query, side="right") - 1, 0, None)]
    p_t = np.column_stack([pans["p_t_e"], pans["p_t_n"], pans["p_t_u"]])
    p_f = p_t[row] @ mat_ft(azimuth_rad).T
    p_f[(pan[row] != np.arange(n_pans)) | (t[row] > times[:, None])] = np.nan
    return p_f


@dataclass(frozen=True)
class FaceDrift:
    """The face line at a series of times: straightness RMS and max [m], creep of the pans' mean and of the tailgate
    drive frame [m, positive towards the tailgate], each per time."""

    t: np.ndarray
    straightness_rms: np.ndarray
    straightness_max: np.ndarray
    creep: np.ndarray
    creep_tailgate: np.ndarray


def face_drift(pans: dict[str, np.ndarray], times: np.ndarray, n_pans: int, azimuth_rad: float) -> FaceDrift:
    """Straightness and creep of a log's truth_pans at `times` (e.g. truth_cycles' t_end), creep since the first row
    of each pan."""
    lines = pan_lines(pans, np.asarray(times, float), n_pans, azimuth_rad)
    start = pan_lines(pans, np.array([float(np.min(pans["t"]))]), n_pans, azimuth_rad)[0]
    rms, worst = straightness(lines[..., 0], lines[..., 1])
    shift = lines[..., 1] - start[:, 1]
    return FaceDrift(np.asarray(times, float), rms, worst, shift.mean(axis=-1), shift[:, -1])
