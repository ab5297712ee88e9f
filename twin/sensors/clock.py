"""Sensor clocks: sample times on a fixed rate grid, and a truth stream's values at them."""

from __future__ import annotations

import numpy as np


def sample_times(t0: float, t1: float, rate_hz: float) -> np.ndarray:
    """The clock k / rate_hz for every integer k with t0 <= k / rate_hz <= t1 (no accumulated rounding).

    A bound that is itself a sample of the clock (k / rate_hz, or a time of another clock that falls on it) is
    inside, whatever the rounding of t * rate_hz: the tolerance is a few of its rounding steps, which grow with the
    time (7.5e-9 of a sample at 200 Hz beyond 2^18 s = 72.8 h, where a fixed 1e-9 dropped a sample at chunk
    boundaries)."""
    x0, x1 = t0 * rate_hz, t1 * rate_hz
    k0 = int(np.ceil(x0 - _tolerance(x0)))
    k1 = int(np.floor(x1 + _tolerance(x1)))
    return np.arange(k0, k1 + 1) / rate_hz


def _tolerance(x: float) -> float:
    """How far t * rate_hz may lie from the integer it stands for: the rounding of t (half a step) and of the
    product (half a step), with margin."""
    return 1e-9 + 4.0 * float(np.spacing(abs(x)))


def true_at(supports: dict[str, np.ndarray], column: str, t_grid: np.ndarray, n_supports: int) -> np.ndarray:
    """(len(t_grid), n_supports) true values of a truth_supports `column`: the latest row of each support at or
    before each time."""
    t_row = np.asarray(supports["t"], dtype=float)
    sup = np.asarray(supports["support"], dtype=np.int64)
    ram = np.asarray(supports[column], dtype=float)
    if sup.size and (sup.min() < 0 or sup.max() >= n_supports):
        raise ValueError(f"truth_supports: support index {sup.max() if sup.max() >= n_supports else sup.min()} "
                         f"outside 0..{n_supports - 1}")
    missing = np.setdiff1d(np.arange(n_supports), sup)
    if missing.size:
        raise ValueError(f"truth_supports: no row for support {missing[0]}")
    order = np.lexsort((np.arange(sup.size), t_row, sup))  # by support, then time, then row order
    sup, t_row, ram = sup[order], t_row[order], ram[order]
    n_t = t_grid.size
    first_k = np.searchsorted(t_grid, t_row, side="left")  # first grid sample at or after each row
    keep = first_k < n_t
    pos = np.arange(sup.size)
    flat = sup[keep] * n_t + first_k[keep]  # nondecreasing; the last of equal entries is the latest row
    pos_k = pos[keep]
    last = np.ones(flat.size, dtype=bool)
    last[:-1] = flat[1:] != flat[:-1]
    index = np.full(n_supports * n_t, -1, dtype=np.int64)
    index[flat[last]] = pos_k[last]
    index = np.maximum.accumulate(index.reshape(n_supports, n_t), axis=1)  # forward fill within a support
    first_row = np.searchsorted(sup, np.arange(n_supports), side="left")
    index = np.where(index < 0, first_row[:, None], index)
    return ram[index].T
