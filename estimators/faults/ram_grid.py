"""The push-ram log on its common sample grid (T samples x S supports; a missing row is an invalid reading), the
runs of flagged samples on it and running medians along it."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import median_filter


def table_columns(table, names: tuple[str, ...], stream: str) -> list[np.ndarray]:
    """The columns `names` of a log table (a mapping of column arrays or a pyarrow table) as numpy arrays; ValueError
    naming the stream and its columns when one is missing."""
    try:
        cols = [table[c] for c in names]
    except (KeyError, TypeError):
        raise ValueError(f"{stream}: the table needs the columns {', '.join(names)} "
                         f"(estimators.io.logformat.{stream.upper()})") from None
    return [c.to_numpy() if hasattr(c, "to_numpy") else np.asarray(c) for c in cols]


def _grid(t, support, extension, valid, n_sup: int, stream: str = "pushram") -> tuple[np.ndarray, np.ndarray]:
    """(times (T,), readings (T, S) with NaN where invalid or missing) on the log's sample grid (`stream` names the
    log in the errors)."""
    t = np.asarray(t, dtype=float).ravel()
    sup = np.asarray(support).ravel()
    ext = np.asarray(extension, dtype=float).ravel()
    val = np.asarray(valid).ravel()
    if t.size == 0:
        raise ValueError(f"{stream}: the log has no rows; pass the {stream.upper()} stream "
                         "of a run with the supports' sensors")
    if not (sup.size == ext.size == val.size == t.size):
        raise ValueError(f"{stream}: columns of different lengths (t {t.size}, support {sup.size}, extension "
                         f"{ext.size}, valid {val.size}); pass the columns of one stream")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{stream}: time is not finite at row {np.flatnonzero(~np.isfinite(t))[0]}; "
                         "drop or repair those rows")
    if sup.dtype.kind not in "iu" and (not np.all(np.isfinite(sup.astype(float))) or np.any(sup.astype(float) % 1)):
        raise ValueError(f"{stream}: support ids must be integers (support index from the headgate)")
    sup = sup.astype(np.int64)
    bad = (sup < 0) | (sup >= n_sup)
    if bad.any():
        raise ValueError(f"{stream}: support id {sup[bad][0]} is not one of the layout's supports 0..{n_sup - 1}; "
                         "give RamLayout the face's support count (n_supports)")
    tg, ti = np.unique(t, return_inverse=True)
    if tg.size < 2:
        raise ValueError(f"{stream}: the log has a single sample time; the checks need a record over time")
    flat = ti * n_sup + sup
    uniq, first, counts = np.unique(flat, return_index=True, return_counts=True)
    if uniq.size != flat.size:
        k = first[np.flatnonzero(counts > 1)[0]]
        raise ValueError(f"{stream}: support {sup[k]} has two rows at t = {t[k]:g} s; keep one row per support "
                         "per sample")
    x = np.full(tg.size * n_sup, np.nan)
    ok = (val > 0) & np.isfinite(ext)
    x[flat[ok]] = ext[ok]
    return tg, x.reshape(tg.size, n_sup)


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True in the columns of a (T, S) mask: (column, first row, last row), by column then time."""
    m = np.zeros((mask.shape[1], mask.shape[0] + 2), np.int8)
    m[:, 1:-1] = mask.T
    d = np.diff(m, axis=1)
    col, start = np.nonzero(d == 1)
    _, stop = np.nonzero(d == -1)
    return col, start, stop - 1


def _runs_1d(mask: np.ndarray, gap: int = 0) -> list[tuple[int, int]]:
    """Runs of True (first, last), runs separated by at most `gap` False merged."""
    _, a, b = _runs(mask[:, None])
    out: list[tuple[int, int]] = []
    for lo, hi in zip(a.tolist(), b.tolist()):
        if out and lo - out[-1][1] - 1 <= gap:
            out[-1] = (out[-1][0], hi)
        else:
            out.append((lo, hi))
    return out


def _centred_median(v: np.ndarray, size: int) -> np.ndarray:
    """Running median over `size` samples centred on each; the first and last size // 2 samples take the
    nearest whole window's median (a padded edge would repeat one reading into half the window)."""
    out = median_filter(v, size=size, mode="nearest")
    half = size // 2
    if v.size > 2 * half:
        out[:half] = out[half]
        out[v.size - half:] = out[v.size - half - 1]
    else:
        out[:] = np.median(v)
    return out


def _running_median(v: np.ndarray, size: int) -> np.ndarray:
    """_centred_median of each column over its finite samples (NaN stays NaN)."""
    out = np.full_like(v, np.nan)
    for j in range(v.shape[1]):
        idx = np.flatnonzero(np.isfinite(v[:, j]))
        if idx.size:
            out[idx, j] = _centred_median(v[idx, j], size)
    return out
