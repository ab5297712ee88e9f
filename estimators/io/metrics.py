"""Accuracy of an estimate against the truth: the truth at estimate times, position and attitude errors, per-cycle
statistics (whole, or over blocks of rows), NEES. What an estimate says of itself without truth is
estimators.io.self_assessment.

Inputs are tables as `estimators.io.logformat.read_stream` / `read_estimate` return them (pyarrow tables), or any
mapping of column name to array with the same columns (the twin's dicts of numpy arrays).

Error conventions (one set, everywhere):

* position error = estimate - truth, in metres East/North/Up at the truth point;
* attitude error phi = the psi-angle of `estimators.sins.error_model`: the computed navigation frame n' is off by
  C_n^n' = I - [phi x], so C_b^n(true) = (I + [phi x]) C_b^n(est) to first order; computed exactly here as the
  rotation vector of C_b^n(true) C_b^n(est)^T. A yaw estimate too large by d gives phi_U = -d.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import pyarrow as pa
from scipy.stats import chi2

from estimators.io.logformat import LogError
from estimators.io.stream_median import StreamMedian
from estimators.nav import earth
from estimators.nav.rotations import (
    quat_conj,
    quat_mul,
    quat_normalize,
    quat_to_rotvec,
    rotvec_to_quat,
)

ENU = "enu"


def column(table, name: str) -> np.ndarray:
    """One column of a pyarrow table or a mapping of arrays, as a float64 numpy array."""
    values = table[name] if isinstance(table, Mapping) else table.column(name)
    return np.asarray(values, dtype=float)


def columns(table, prefix: str, axes: str = ENU) -> np.ndarray:
    """Columns prefix_a for a in axes stacked to (K, len(axes))."""
    return np.column_stack([column(table, f"{prefix}_{a}") for a in axes])


def slerp(t_src: np.ndarray, q_src: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Quaternions q_src (K, 4) given at increasing times t_src interpolated at t (M,) by spherical linear
    interpolation between the neighbouring samples (shortest arc); t outside the span is clamped to the ends."""
    t_src, t = np.asarray(t_src, float), np.asarray(t, float)
    q_src = np.asarray(q_src, float)
    if t_src.size == 1:
        return np.broadcast_to(quat_normalize(q_src[0]), (t.size, 4)).copy()
    k = np.clip(np.searchsorted(t_src, t, side="right") - 1, 0, t_src.size - 2)
    u = np.clip((t - t_src[k]) / (t_src[k + 1] - t_src[k]), 0.0, 1.0)
    q0 = q_src[k]
    step = quat_to_rotvec(quat_mul(quat_conj(q0), q_src[k + 1]))  # q0^-1 q1, w >= 0: the shorter arc
    return quat_normalize(quat_mul(q0, rotvec_to_quat(u[:, None] * step)))


class TruthTrack:
    """The truth_shearer stream, given whole (a table or mapping of arrays) or as blocks of consecutive rows (e.g.
    estimators.io.logformat.StreamBlocks, iterable again), interpolated at estimate times (`at`). Only one block is
    held at a time, and a cursor stays on it: a call whose earliest time is not before that block's start goes on
    from it (a run scored a pass at a time reads the truth once), an earlier one reads the blocks again from the
    first. The answers for the last KEEP sets of times are kept, since the methods of a run are scored, and drawn,
    at the same filter epochs. Block by block equals whole, bit for bit: each time is interpolated between the same
    two samples, and the longitude unwrapped with its correction summed in order."""

    KEEP = 2

    def __init__(self, blocks):
        self.blocks = [blocks] if isinstance(blocks, Mapping | pa.Table) else blocks
        self._kept: list[tuple[np.ndarray, dict[str, np.ndarray]]] = []
        self._cursor = None  # the generator of prepared blocks, positioned after self._block
        self._block = None  # (cols, lo, hi) of the block the cursor is on; None before the first
        self._t_first = np.nan  # the first sample's time

    def at(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """truth_at's dict at times t, plus "cycle" (of the sample at or before each time) when the truth has it."""
        t = np.asarray(t, float)
        for t_kept, true in self._kept:
            if np.array_equal(t_kept, t):
                return true
        true = self._interpolate(t)
        self._kept = [(t.copy(), true), *self._kept][:self.KEEP]
        return true

    def _interpolate(self, t: np.ndarray) -> dict[str, np.ndarray]:
        out: dict[str, np.ndarray] = {}
        todo = np.ones(t.size, bool)
        if self._block is None or (t.size and t.min() < self._block[1]):
            self._cursor, self._block = truth_windows(self.blocks), None
        while True:
            if self._block is not None:
                cols, lo, hi = self._block
                self._fill(out, cols, t, todo & (t >= lo) & (t < hi), todo)
                if not (todo & (t >= hi)).any():
                    break
            block = next(self._cursor, None)
            if block is None:
                break
            if block[1] == -np.inf:
                self._t_first = block[0]["t"][0]
            self._block = block
        if self._block is None:
            raise LogError("truth_shearer holds no samples to score against")
        cols, _, hi = self._block
        self.check_span(t, self._t_first, hi)
        self._fill(out, cols, t, todo.copy(), todo)  # the times at the last sample
        return out

    @staticmethod
    def check_span(t: np.ndarray, first: float, last: float) -> None:
        """LogError (one line) when a time lies outside the truth's span first .. last."""
        if t.size and (t.min() < first - 1e-9 or t.max() > last + 1e-9):
            raise LogError(f"estimate times {t.min():.6g} .. {t.max():.6g} s lie outside the truth span "
                           f"{first:.6g} .. {last:.6g} s")

    @staticmethod
    def _fill(out: dict[str, np.ndarray], cols: dict[str, np.ndarray], t: np.ndarray, sel: np.ndarray,
              todo: np.ndarray) -> None:
        """Interpolate the times `sel` in the samples `cols` into `out` (allocated at the first call)."""
        if not out:
            out |= {k: np.empty(t.size) for k in ("lat", "lon", "h")} | {"q_nb": np.empty((t.size, 4))}
            if "cycle" in cols:
                out["cycle"] = np.empty(t.size)
        if not sel.any():
            return
        ts, t_src = t[sel], cols["t"]
        for k in ("lat", "lon", "h"):
            out[k][sel] = np.interp(ts, t_src, cols[k])
        out["q_nb"][sel] = slerp(t_src, cols["q_nb"], ts)
        if "cycle" in out:
            out["cycle"][sel] = cols["cycle"][np.clip(np.searchsorted(t_src, ts, side="right") - 1, 0, None)]
        todo &= ~sel


def truth_windows(blocks):
    """TruthTrack's blocks as (cols, lo, hi): a block's columns after the previous block's last sample, the
    longitude unwrapped from the run's first sample; the times it interpolates are lo <= t < hi (lo -inf for the
    first block). A function of the blocks, not a method: a generator held by the object it reads would keep it
    alive until a cyclic collection."""
    prev = None  # the previous block's last sample, its longitude unwrapped, the correction summed to it
    for block in blocks:
        cols = {k: column(block, k) for k in ("t", "lat", "lon", "h")}
        if not cols["t"].size:
            continue
        cols["q_nb"] = columns(block, "q_nb", "wxyz")
        if "cycle" in (block.keys() if isinstance(block, Mapping) else block.column_names):
            cols["cycle"] = column(block, "cycle")
        if prev is None:
            lo, carry, lon_first = -np.inf, 0.0, cols["lon"][:1]
        else:
            cols = {k: np.concatenate([prev[k], v]) for k, v in cols.items()}
            lo, carry, lon_first = cols["t"][0], prev["carry"], prev["lon_unwrapped"]
        # np.unwrap's correction, summed in order from the run's first sample
        lon = cols["lon"]
        dd = np.diff(lon)
        correction = np.mod(dd + np.pi, 2 * np.pi) - np.pi
        np.copyto(correction, np.pi, where=(correction == -np.pi) & (dd > 0))
        correction -= dd
        np.copyto(correction, 0.0, where=np.abs(dd) < np.pi)
        summed = np.cumsum(np.concatenate([[carry], correction]))
        cols["lon"] = np.concatenate([lon_first, lon[1:] + summed[1:]])
        prev = {k: v[-1:] for k, v in cols.items()} | {"lon": lon[-1:], "carry": summed[-1],
                                                       "lon_unwrapped": cols["lon"][-1:]}
        yield cols, lo, cols["t"][-1]


def truth_at(truth_shearer, t: np.ndarray) -> dict[str, np.ndarray]:
    """The true body point (lat, lon, h: linear) and attitude (q_nb (M, 4): slerp) at times t within the truth
    span, and the cycle of the sample at or before each when the truth has it. `truth_shearer`: a table, a mapping
    of arrays or a TruthTrack. Raises LogError (one line) when a time lies outside the span."""
    track = truth_shearer if isinstance(truth_shearer, TruthTrack) else TruthTrack(truth_shearer)
    return track.at(t)


def geodetic_to_enu_offset(lat, lon, h, lat_ref, lon_ref, h_ref) -> np.ndarray:
    """(lat, lon, h) - (lat_ref, lon_ref, h_ref) as East/North/Up metres (K, 3), with the WGS-84 radii of
    curvature at the reference point (001 eq. 7 inverted); exact to ~1e-9 relative for offsets of metres."""
    r_m, r_n = earth.radii(lat_ref)
    d_lon = np.angle(np.exp(1j * (np.asarray(lon, float) - lon_ref)))  # wrapped to (-pi, pi]
    return np.column_stack([d_lon * (r_n + h_ref) * np.cos(lat_ref),
                            (np.asarray(lat, float) - lat_ref) * (r_m + h_ref),
                            np.asarray(h, float) - h_ref])


def enu_offset_to_geodetic(d_enu: np.ndarray, lat, lon, h) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The point d_enu (K, 3) metres East/North/Up from (lat, lon, h): the inverse of `geodetic_to_enu_offset`."""
    d_enu = np.asarray(d_enu, float)
    r_m, r_n = earth.radii(lat)
    return (lat + d_enu[..., 1] / (r_m + h), lon + d_enu[..., 0] / ((r_n + h) * np.cos(lat)), h + d_enu[..., 2])


SCORED_ESTIMATE = ("t", "lat", "lon", "h", *(f"sd_{q}_{a}" for q in ("pos", "att") for a in ENU), "flags")
"""The ESTIMATE columns scoring and self_assessment read: a run loads only these."""
SCORED_TRUTH = ("t", "lat", "lon", "h", "q_nb_w", "q_nb_x", "q_nb_y", "q_nb_z", "cycle")
"""The truth_shearer columns scoring reads (errors at the truth point, per cycle): a run loads only these."""


def position_errors(estimate, truth_shearer) -> tuple[np.ndarray, np.ndarray]:
    """(t (K,), err_enu (K, 3)): estimated minus true body point in metres East/North/Up at the truth point,
    the truth linearly interpolated at the estimate times."""
    t = column(estimate, "t")
    true = truth_at(truth_shearer, t)
    err = geodetic_to_enu_offset(column(estimate, "lat"), column(estimate, "lon"), column(estimate, "h"),
                                 true["lat"], true["lon"], true["h"])
    return t, err


def attitude_errors(estimate, truth_shearer) -> tuple[np.ndarray, np.ndarray]:
    """(t (K,), phi (K, 3) [rad] about East/North/Up): the psi-angle attitude error of the estimate
    (C_b^n(true) = Exp([phi x]) C_b^n(est), first order I + [phi x]; module docstring), the true attitude
    slerp-interpolated at the estimate times. The two n frames (at the estimated and the true position) differ
    by the position error over the Earth radius, ~1e-7 rad per metre, which is neglected."""
    t = column(estimate, "t")
    q_true = truth_at(truth_shearer, t)["q_nb"]
    q_est = quat_normalize(columns(estimate, "q_nb", "wxyz"))
    return t, quat_to_rotvec(quat_mul(q_true, quat_conj(q_est)))


# ----------------------------------------------------------------------------------------------- statistics

STAT_KEYS = ("samples", "rmse_e", "rmse_n", "rmse_u", "max_e", "max_n", "max_horizontal", "max_3d", "sep")


class ErrorStats:
    """`error_stats` over position errors pushed in blocks (K, 3) [m]: the sums, largest values and the 3-D norms'
    median (estimators.io.stream_median, exact in bounded memory) carried from block to block. One block gives
    error_stats' numbers bit for bit; more blocks sum the squares block by block (the last bits may differ)."""

    def __init__(self):
        self.samples = 0
        self.sum_sq = np.zeros(3)
        self.peaks = np.zeros(4)  # the largest |east|, |north|, horizontal and 3-D error
        self.norms = StreamMedian()

    def push(self, err_enu: np.ndarray) -> ErrorStats:
        err = np.asarray(err_enu, float).reshape(-1, 3)
        if err.shape[0]:
            norm = np.linalg.norm(err, axis=1)
            self.samples += err.shape[0]
            self.sum_sq += np.sum(err ** 2, axis=0)
            self.peaks = np.maximum(self.peaks, [np.abs(err[:, 0]).max(), np.abs(err[:, 1]).max(),
                                                 np.hypot(err[:, 0], err[:, 1]).max(), norm.max()])
            self.norms.push(norm)
        return self

    def stats(self) -> dict[str, float]:
        if not self.samples:
            return {"samples": 0, **{k: float("nan") for k in STAT_KEYS[1:]}}
        rmse = np.sqrt(self.sum_sq / self.samples)
        return {"samples": self.samples, **dict(zip(STAT_KEYS[1:4], map(float, rmse))),
                **dict(zip(STAT_KEYS[4:8], map(float, self.peaks))), "sep": self.norms.median()}


def error_stats(err_enu: np.ndarray) -> dict[str, float]:
    """RMSE per axis, the largest |east|, |north|, horizontal and 3-D error, and the SEP of position errors
    (K, 3) [m].

    SEP (spherical error probable) is the radius of the sphere about the truth that holds half of the errors:
    here the empirical median of the 3-D error norm |e_k| over the samples (001 section 4, Table 3), not the
    Gaussian approximation from the standard deviations. Empty input gives NaN statistics and 0 samples.
    """
    return ErrorStats().push(err_enu).stats()


def cycle_label(cycle: int) -> str:
    """A cutting cycle (truth_cycles' 0-based `cycle`) as tables and plots name it: A1 for cycle 0 (001 Table 3)."""
    return f"A{int(cycle) + 1}"


class CycleScore:
    """`cycle_metrics` over (t, err_enu) pushed in blocks of increasing time (a pass at a time). A cycle's
    statistics are final, and its errors let go, once the times pass its end."""

    def __init__(self, truth_cycles):
        self.starts, self.cut_ends, self.ends = (column(truth_cycles, k) for k in ("t", "t_cut_end", "t_end"))
        self.cycles = column(truth_cycles, "cycle").astype(int)
        n = self.cycles.size
        self.windows: list[ErrorStats | dict] = [ErrorStats() for _ in range(n)]
        self.cuts: list[ErrorStats | dict] = [ErrorStats() for _ in range(n)]
        self.all, self.all_cuts = ErrorStats(), ErrorStats()
        self.t_first = self.t_last = float("nan")

    def push(self, t: np.ndarray, err_enu: np.ndarray) -> CycleScore:
        t = np.asarray(t, float)
        err = np.asarray(err_enu, float).reshape(-1, 3)
        if not t.size:
            return self
        if t.min() < self.t_last:
            raise ValueError(f"CycleScore: a block from t = {t.min():.6g} s after one to {self.t_last:.6g} s; "
                             "push blocks in time order")
        last = self.cycles.size - 1
        in_cuts = np.zeros(t.size, bool)
        for j in np.flatnonzero((np.maximum(self.ends, self.cut_ends) >= t.min()) & (self.starts <= t.max())):
            window = (t >= self.starts[j]) & ((t <= self.ends[j]) if j == last else (t < self.ends[j]))
            cut = (t >= self.starts[j]) & (t <= self.cut_ends[j])
            in_cuts |= cut
            for acc, rows in ((self.windows[j], window), (self.cuts[j], cut)):
                if rows.any():  # (a final window has no more rows)
                    acc.push(err[rows])
        self.all.push(err)
        self.all_cuts.push(err[in_cuts])
        if np.isnan(self.t_first):
            self.t_first = float(t[0])
        self.t_last = float(t[-1])
        for j in range(last):  # final: no later time falls in the window [t, t_end) or the cut [t, t_cut_end]
            if isinstance(self.windows[j], ErrorStats) and self.ends[j] <= self.t_last:
                self.windows[j] = self.windows[j].stats()
            if isinstance(self.cuts[j], ErrorStats) and self.cut_ends[j] < self.t_last:
                self.cuts[j] = self.cuts[j].stats()
        return self

    def rows(self) -> list[dict]:
        def stats(acc: ErrorStats | dict) -> dict:
            return acc if isinstance(acc, dict) else acc.stats()

        rows = [{"cycle": int(cycle), "t_start": float(t0), "t_end": float(t1), **stats(window),
                 "straight_cut": stats(cut)}
                for cycle, t0, t1, window, cut in zip(self.cycles, self.starts, self.ends, self.windows, self.cuts)]
        return rows + [{"cycle": "all", "t_start": self.t_first, "t_end": self.t_last, **self.all.stats(),
                        "straight_cut": self.all_cuts.stats()}]


def cycle_metrics(t: np.ndarray, err_enu: np.ndarray, truth_cycles) -> list[dict]:
    """Error statistics (`error_stats`) per cutting cycle and over the whole run.

    One dict per row of truth_cycles, then one with cycle "all". A cycle's window is its rows' t .. t_end
    (half-open, the last cycle closed), "all" is every sample. Each dict holds cycle, t_start, t_end, the
    `STAT_KEYS` of the window and, under "straight_cut", the same statistics over t .. t_cut_end only: the A-B
    straight cut of 001 Fig. 3 (for "all": the union of the straight cuts). 001 Table 3 reports the SEP per
    cycle (A1-A4). In blocks: `CycleScore`.
    """
    return CycleScore(truth_cycles).push(t, err_enu).rows()


# ----------------------------------------------------------------------------------------------- consistency


def nees(err: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Normalized estimation error squared sum_i (err_i / sd_i)^2 over the last axis, for errors and one-sigma
    columns of the same shape (..., n) (diagonal covariance). A consistent filter gives chi-square with n dof."""
    err, sd = np.asarray(err, float), np.asarray(sd, float)
    if err.shape != sd.shape:
        raise ValueError(f"nees: errors {err.shape} and sigmas {sd.shape} differ in shape")
    return np.sum((err / sd) ** 2, axis=-1)


def nees_band(dof: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided acceptance interval of the NEES averaged over `trials` Monte Carlo runs with `dof` states:
    trials * mean NEES ~ chi-square(trials * dof), so the band is chi2.ppf((1 -+ confidence) / 2, M n) / M
    (Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and Navigation, section 5.4.2)."""
    if dof < 1 or trials < 1 or not 0.0 < confidence < 1.0:
        raise ValueError(f"nees_band: need dof >= 1, trials >= 1, 0 < confidence < 1 (got {dof}, {trials}, "
                         f"{confidence})")
    alpha = 0.5 * (1.0 - confidence)
    lo, hi = chi2.ppf([alpha, 1.0 - alpha], dof * trials) / trials
    return float(lo), float(hi)
