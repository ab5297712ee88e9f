"""Per-support checks of the push-ram stroke sensors (the PUSHRAM stream) that name the faulty support.

Input is the push-ram log alone (t, support, extension, valid; estimators.io.logformat.PUSHRAM) and what a user
knows of the face (`RamLayout`): the number of supports and their spacing, the commanded stroke of a push (the
web depth), the AFC's bend limit, and the sensors' noise and resolution. Output is a list of `Finding`s: the
support (or, for a lateral deviation, the run of supports), the kind, the window, when the data first confirmed
it, the estimated fault value and the test statistic against its threshold. `format_findings` prints one line
each. The readings are put on the log's common sample grid (the stream has one row per support per sample; a
missing row counts as an invalid reading).

Sensor self-checks (each support on its own)
--------------------------------------------
sigma = sqrt(noise^2 + resolution^2 / 12) is the one-sigma error of a reading.

* dropout      readings flagged invalid (valid = 0), NaN or missing: the window is exact.
* noise_burst  the robust scatter of the reading-to-reading differences dx in a centred window of
               BURST_WINDOW readings, 1.4826 median|dx - median dx| / sqrt(2), exceeds BURST_RATIO sigma.
               The medians ignore the ram's own steps (under half of any window) and a drift.
* stuck        a run of identical readings that the noise makes improbable: a reading stays in the quantum of
               its true value with probability at most p = 2 Phi(resolution / (2 noise)) - 1, so a run of
               L = max(FLAT_MIN_RUN, 1 + log(FLAT_FALSE_ALARM) / log p) equal readings flags the support from
               the run's first reading (L = 30 for noise = resolution, 6 for 004's 0.02 m sensor). A sensor
               much finer than its quantum (L > FLAT_MAX_RUN) reads constant at rest anyway: then the neighbour
               check (b) finds a stuck ram once its neighbours move and it does not follow; its frozen readings
               are then left out as well and (a) and (b) run again (up to STUCK_PASSES times).

The readings these flag are left out of the checks below.

Support advances
----------------
The ram only retracts when its support advances (lowered, pulled up to the pan by the ram, set), by the
commanded stroke s_c, to its set length. A drop is a down-swing of a quarter stroke (estimators.faults.ram_levels
`swings`), split where the ram rests on the way down (two advances without a push between them, as at a face
end); the level on each side is the median of up to LEVEL_SAMPLES readings next to it within the plateau
tolerance (6 sigma, at least 5 mm, as the CPOEM stroke measurement), cut at the most significant level change
(CHANGE_SIGMAS), so the short last step of a face-end push is not averaged with the pause before it. A drop of
ADVANCE_BAND strokes is a candidate advance; it is sure when the levels around it lie whole strokes above the
face's rest level (the median level after all candidates), within REST_TOLERANCE strokes plus the stroke
check's tolerance. Whether a candidate was an advance is settled by the neighbours (see _pan_advance).

(a) Commanded versus measured stroke
------------------------------------
Every push extends the ram by s_c and every advance retracts it by s_c, so

* each advance must measure s_c, and
* between two advances the level must rise by a whole number of strokes (one; none or two where the face-end
  push and advance come in the other order; the log must start between pushes; the open stretch after the
  last advance is not judged: its push may be under way),

within tau_s = STROKE_TOLERANCE s_c (the ram line is not exactly the advance direction: floor steps and pitch
change a healthy stroke by up to 2 % in the twin) + CHANGE_SIGMAS sigma sqrt(1 + 1/14) (a one-reading last
step the level-change test can miss) + STROKE_SIGMAS sigma 1.2533 sqrt(1/n1 + 1/n2) (the two plateau medians
of n1 and n2 readings): 28 mm for the default 0.1 mm sensor and a 0.8 m web, 0.17 m for 004's 0.02 m sensor
and a 1 m web. A drop across unusable readings is not judged. A failed stroke is confirmed at the advance.

(b) Neighbour consistency
-------------------------
The AFC is a chain: neighbouring pans cannot move independently by more than their bend allows. The pan
advance implied by a ram is p_j(t) = reading_j(t) + s_c (advances of support j so far), the same for every
support whatever the order of pushes and advances. A leave-one-out quadratic through the NEIGHBOURS nearest
other supports predicts each p_j; rho = P p are the prediction residuals, and a reading error v at support k
alone makes rho = v P[:, k], so

    v_k = P[:, k] . rho / |P[:, k]|^2 = (A p)_k,    A = diag(1 / |P[:, k]|^2) P^T P,

is each support's reading error (exact for a quadratic face), and of the supports whose patterns overlap the
one whose pattern explains rho best (largest (P[:, k] . rho)^2 / |P[:, k]|^2) is named. A face bent within the
chain's limit, |D2 p| <= B = h^2 tan(bend limit) / l (h the support spacing, l the pan length), gives
|v_k| <= B |c_k|_1 with A_k = D2^T c_k. The threshold on v smoothed by a running median of NEIGHBOUR_WINDOW
readings (confirmed half a window later) is

    tau_k = B |c_k|_1 + NEIGHBOUR_SIGMAS sigma |A_k| 1.2533 / sqrt(NEIGHBOUR_WINDOW),

28 mm inside the default face (B = 31 mm), 92 mm inside seed004's (20 mm noise); about twice that at the two
supports of each face end, which are predicted by extrapolation (and whose fault patterns are over 90 % alike,
so overlapping findings there are merged). Flagged runs shorter than MIN_FLAGGED readings, or lying inside a
longer one two supports away or less, are the attribution flicking and are dropped.

A support's flagged stretch (the neighbour flags and its failed strokes, MERGE_GAP apart at most) is classified
on its flagged readings by fitting v with a constant, with c r and with a + b t:

* stuck   (a sensor finer than its quantum) the reading stays put while v moves by more than tau;
* scale   c r beats the constant by MODEL_SIGMAS residual sigmas and c explains more than tau / 2 over the
          stretch, r = reading - v the true ram length: the error grows with the extension (value: c, the
          relative error); a stretch only the stroke check saw is a scale error too. Without a stroke in the
          window a scale error reads as an offset (c times the rest length);
* drift   a + b t beats the constant so, b explains more than tau / 2 (value: b [m/s]; the window starts where
          the line crosses zero);
* offset  otherwise (value: median v).

A run of at least RAIL_MIN_SUPPORTS supports, each within RAIL_REACH of another, flagged by (a) or (b) at
overlapping times (RAIL_GAP readings apart at most) is one lateral deviation over the run (`rail_deviation`:
004's deviated rail seen by the supports it covers as the shearer passes; the deviation is smooth along the run,
so the chain check sees its moving end, one support after the other).

Limits: a reading error that starts or ends with a jump of more than half a stroke at an advance is taken for
a miscounted advance; the end supports need about twice the error of the others; a fault of a noise-free sensor
at rest with still neighbours leaves nothing to see; strokes at a face end, where the twin pushes and advances
a row of supports within a reading or two, are not judged by (a), so a scale error there reads as an offset.

Measured here (benchmarks/bench_ram_checks.py: seed004, 6.5 h, 200 supports, 0.02 m sensors; fault on support
100 around its first push): confirmation after the fault start 5 s stuck, 7 s offset (0.15 m), 454 s drift
(0.2 mm/s, = tau / rate), 7 s scale (15 %), 0 s dropout, 26 s noise burst (0.1 m), 76 s for 004's rail
deviation (run 141-155 of the deviated 138-155); each named on its support only; no finding over 20 redrawn
fault-free trials; 3 s per log.

Not seen here
-------------
push_shortfall is a fault of the face, not of the sensor: the pan stops short while the ram reads the full
commanded stroke, so every check above passes. It is left to the rail kinematics model filter, which compares
the pan line with the shearer's measured path; nothing here pretends to detect it. (The twin adds the shortfall
to the readings from the start of its window, also before the pan has been pushed short, and takes it off at the
end: the neighbour check may flag those steps. That is not a detection of the shortfall.)
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import median_filter
from scipy.stats import norm

from estimators.faults.ram_levels import (
    CHANGE_SIGMAS,
    LEVEL_SAMPLES,
    change_sigma,
    drop_levels,
    level_tolerance,
    side_level,
    swings,
)

KINDS = ("dropout", "noise_burst", "stuck", "offset", "drift", "scale", "rail_deviation")
"""Finding kinds (the twin's faults ram_dropout, ram_noise_burst, ram_stuck, ram_offset, ram_drift, ram_scale,
rail_deviation)."""

VALUE_UNITS = {"dropout": "s", "noise_burst": "m", "stuck": "m", "offset": "m", "drift": "m/s", "scale": "1",
               "rail_deviation": "m"}
"""Unit of Finding.value per kind: dropout its length, noise_burst the extra scatter (one sigma), stuck the frozen
reading, offset the reading error, drift its rate, scale the relative error of the reading, rail_deviation the
largest lateral error over the run (positive: the pans appear further towards the coal wall)."""

BURST_WINDOW = 31
"""Readings in the centred window of the scatter estimate (noise_burst)."""
BURST_RATIO = 4.0
"""A window's robust scatter over the reading noise sigma that flags a noise burst."""
FLAT_FALSE_ALARM = 1e-12
"""Probability of a run of equal readings of a healthy sensor at rest that still counts as stuck."""
FLAT_MIN_RUN = 5
"""Fewest equal readings that flag a stuck sensor, however noisy."""
FLAT_MAX_RUN = 600
"""Above this run length the sensor is too fine for its quantum to tell stuck from at rest by flatness."""
ADVANCE_BAND = (0.5, 1.5)
"""A drop of the ram this many commanded strokes may be a support advance."""
REST_TOLERANCE = 0.1
"""Strokes (on top of the stroke check's tolerance) the levels around a sure advance may differ from whole
strokes above the face's rest level."""
STROKE_TOLERANCE = 0.03
"""Share of the commanded stroke that a healthy stroke may differ by (ram line geometry)."""
STROKE_SIGMAS = 5.0
"""Noise sigmas of a stroke (difference of two plateau medians) on top of the geometry tolerance."""
NEIGHBOURS = 4
"""Other supports in each leave-one-out quadratic prediction of a support's pan advance."""
NEIGHBOUR_WINDOW = 15
"""Samples in the running median of the neighbour residual."""
NEIGHBOUR_SIGMAS = 6.0
"""Noise sigmas of the smoothed neighbour residual on top of the bend tolerance."""
MISCOUNT_GAIN = 0.1
"""Strokes squared by which a change of the miscounts must reduce the squared residual to be taken."""
MISCOUNT_LEFT = 0.25
"""Largest share of the squared residual a miscount fit may leave unexplained and still be taken."""
MISCOUNT_RUN = 16
"""Longest run of neighbouring supports whose counts one step of the miscount fit changes together."""
MIN_FLAGGED = NEIGHBOUR_WINDOW // 2 + 1
"""Fewest consecutive flagged samples of the neighbour check that count (shorter: the attribution flicked)."""
MERGE_GAP = 8 * NEIGHBOUR_WINDOW
"""Samples between two flagged stretches of one support that still make one finding."""
MODEL_SIGMAS = 5.0
"""Significance (in sigmas of the residual scatter) with which a scale or drift model must beat a constant."""
STUCK_PASSES = 4
"""Most rams found stuck by their neighbours (not by flatness) that are left out, one per pass, and the checks
run again."""
RAIL_MIN_SUPPORTS = 3
"""Fewest supports flagged together that make a lateral deviation of the rail."""
RAIL_REACH = 2
"""Supports apart that still join one run."""
RAIL_GAP = 4 * NEIGHBOUR_WINDOW
"""Readings between two findings of one run."""


@dataclass(frozen=True)
class RamLayout:
    """What a user knows of the face and its push-ram sensors (SI units).

    stroke_m is the commanded stroke of every push and advance: the web depth (scenario face.web_depth_m).
    pan_length_m defaults to spacing_m (one support per pan); bend_limit_deg is the AFC's horizontal bend limit
    between pans; stroke_tolerance_m defaults to STROKE_TOLERANCE * stroke_m."""

    n_supports: int
    spacing_m: float
    stroke_m: float
    noise_m: float
    resolution_m: float = 0.0
    pan_length_m: float | None = None
    bend_limit_deg: float = 1.0
    stroke_tolerance_m: float | None = None

    def __post_init__(self):
        checks = [
            (int(self.n_supports) == self.n_supports and self.n_supports >= NEIGHBOURS + 1, "n_supports",
             f"an integer >= {NEIGHBOURS + 1} (the neighbour check needs {NEIGHBOURS} neighbours)"),
            (self.spacing_m > 0, "spacing_m", "positive"),
            (self.stroke_m > 0, "stroke_m", "positive (the web depth)"),
            (self.noise_m >= 0, "noise_m", "non-negative"),
            (self.resolution_m >= 0, "resolution_m", "non-negative"),
            (self.pan_length_m is None or self.pan_length_m > 0, "pan_length_m", "positive or None"),
            (0 < self.bend_limit_deg < 90, "bend_limit_deg", "in (0, 90)"),
            (self.stroke_tolerance_m is None or self.stroke_tolerance_m >= 0, "stroke_tolerance_m",
             "non-negative or None"),
        ]
        for ok, name, what in checks:
            value = getattr(self, name)
            if not (ok and (value is None or math.isfinite(value))):
                raise ValueError(f"RamLayout.{name} = {value!r}: must be {what}")

    @property
    def sigma_m(self) -> float:
        """One-sigma error of a reading: noise and quantization."""
        return math.sqrt(self.noise_m ** 2 + self.resolution_m ** 2 / 12.0)

    @property
    def bend_m(self) -> float:
        """Largest second difference of the pan advance across three neighbouring supports [m]."""
        pan = self.spacing_m if self.pan_length_m is None else self.pan_length_m
        return self.spacing_m ** 2 * math.tan(math.radians(self.bend_limit_deg)) / pan

    @property
    def stroke_tol_m(self) -> float:
        return STROKE_TOLERANCE * self.stroke_m if self.stroke_tolerance_m is None else self.stroke_tolerance_m

    @property
    def change_sigma_m(self) -> float:
        """Sigma of the level-change test (estimators.faults.ram_levels.change_sigma)."""
        return change_sigma(self.sigma_m)

    @property
    def level_tol_m(self) -> float:
        """Plateau tolerance (estimators.faults.ram_levels.level_tolerance, as estimators.shearer.cpoem.ram_stroke)."""
        return level_tolerance(self.sigma_m)


@dataclass(frozen=True)
class Finding:
    """One detected fault. support..last_support is the run of supports (one support except rail_deviation);
    t_start..t_end [s] the samples it affects, t_detect [s] when the log up to then confirms it; value the
    estimated fault in VALUE_UNITS[kind]; statistic and threshold the test that fired, in `unit`."""

    support: int
    last_support: int
    kind: str
    t_start: float
    t_end: float
    t_detect: float
    value: float
    statistic: float
    threshold: float
    unit: str


def format_finding(f: Finding) -> str:
    """One line: who, what, when, how big, and the test."""
    who = f"support {f.support}" if f.last_support == f.support else f"supports {f.support}-{f.last_support}"
    return (f"{who:<16} {f.kind:<14} {f.t_start:9.1f} .. {f.t_end:9.1f} s  confirmed {f.t_detect:9.1f} s  "
            f"value {f.value:+.4g} {VALUE_UNITS[f.kind]:<3}  statistic {abs(f.statistic):.4g} > "
            f"{f.threshold:.4g} {f.unit}")


def format_findings(findings: list[Finding]) -> str:
    return "\n".join(format_finding(f) for f in findings) if findings else "no push-ram faults found"


# ------------------------------------------------------------------------------------------------ input


def _grid(t, support, extension, valid, n_sup: int) -> tuple[np.ndarray, np.ndarray]:
    """(times (T,), readings (T, S) with NaN where invalid or missing) on the log's sample grid."""
    t = np.asarray(t, dtype=float).ravel()
    sup = np.asarray(support).ravel()
    ext = np.asarray(extension, dtype=float).ravel()
    val = np.asarray(valid).ravel()
    if t.size == 0:
        raise ValueError("pushram: the log has no rows; pass the PUSHRAM stream (t, support, extension, valid) "
                         "of a run with push-ram sensors")
    if not (sup.size == ext.size == val.size == t.size):
        raise ValueError(f"pushram: columns of different lengths (t {t.size}, support {sup.size}, extension "
                         f"{ext.size}, valid {val.size}); pass the columns of one stream")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"pushram: time is not finite at row {np.flatnonzero(~np.isfinite(t))[0]}; "
                         "drop or repair those rows")
    if sup.dtype.kind not in "iu" and (not np.all(np.isfinite(sup.astype(float))) or np.any(sup.astype(float) % 1)):
        raise ValueError("pushram: support ids must be integers (support index from the headgate)")
    sup = sup.astype(np.int64)
    bad = (sup < 0) | (sup >= n_sup)
    if bad.any():
        raise ValueError(f"pushram: support id {sup[bad][0]} is not one of the layout's supports 0..{n_sup - 1}; "
                         "give RamLayout the face's support count (n_supports)")
    tg, ti = np.unique(t, return_inverse=True)
    if tg.size < 2:
        raise ValueError("pushram: the log has a single sample time; the checks need a record over time")
    flat = ti * n_sup + sup
    uniq, first, counts = np.unique(flat, return_index=True, return_counts=True)
    if uniq.size != flat.size:
        k = first[np.flatnonzero(counts > 1)[0]]
        raise ValueError(f"pushram: support {sup[k]} has two rows at t = {t[k]:g} s; keep one row per support "
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


# ------------------------------------------------------------------------------------------ self-checks


def _flat_run(layout: RamLayout) -> int | None:
    """Equal readings that flag a stuck sensor (None: flatness tells nothing for this sensor)."""
    noise, q = layout.noise_m, layout.resolution_m
    if noise <= 0:
        return None
    p = 0.0 if q <= 0 else 2.0 * norm.cdf(q / (2.0 * noise)) - 1.0
    if p <= 0:
        return FLAT_MIN_RUN
    if p >= 1:
        return None
    run = max(FLAT_MIN_RUN, 1 + math.ceil(math.log(FLAT_FALSE_ALARM) / math.log(p)))
    return run if run <= FLAT_MAX_RUN else None


def _self_checks(tg: np.ndarray, x: np.ndarray, layout: RamLayout) -> tuple[list[Finding], np.ndarray]:
    """Dropout, noise-burst and stuck findings, and the mask of the samples they make unusable."""
    dt = float(np.median(np.diff(tg)))
    findings: list[Finding] = []
    bad = ~np.isfinite(x)
    for j, a, b in zip(*_runs(bad)):
        findings.append(Finding(int(j), int(j), "dropout", tg[a], tg[b], tg[a], tg[b] - tg[a] + dt,
                                float(b - a + 1), 1.0, "samples"))
    mask = bad.copy()
    sigma = layout.sigma_m
    burst_thr = max(BURST_RATIO * sigma, 1e-12)
    flat_run = _flat_run(layout)
    half = BURST_WINDOW // 2
    for j in range(x.shape[1]):
        idx = np.flatnonzero(~bad[:, j])
        if idx.size < 2:
            continue
        r = x[idx, j]
        d = np.diff(r)
        if idx.size > BURST_WINDOW:
            sd = 1.4826 * _centred_median(np.abs(d - _centred_median(d, BURST_WINDOW)), BURST_WINDOW) / math.sqrt(2.0)
            hot = sd > burst_thr
            noisy = np.zeros(idx.size, bool)
            noisy[:-1] |= hot
            noisy[1:] |= hot
            for a, b in _runs_1d(noisy, gap=half):
                s = sd[a:min(b, d.size - 1) + 1]
                value = math.sqrt(max(float(np.median(s)) ** 2 - sigma ** 2, 0.0))
                findings.append(Finding(j, j, "noise_burst", tg[idx[a]], tg[idx[b]],
                                        tg[idx[min(a + half, idx.size - 1)]], value, float(s.max()), burst_thr,
                                        "m"))
                mask[idx[max(a - half, 0):b + half + 1], j] = True
        if flat_run is not None:
            for a, b in _runs_1d(d == 0):
                if b - a + 2 >= flat_run:
                    findings.append(Finding(j, j, "stuck", tg[idx[a]], tg[idx[b + 1]],
                                            tg[idx[a + flat_run - 1]], float(r[a]), float(b - a + 2),
                                            float(flat_run), "samples"))
                    mask[idx[a:b + 2], j] = True
    return findings, mask


# ----------------------------------------------------------------------------------- advances and strokes


@dataclass
class _Advances:
    """Drops of one support that may be advances; reading indices of its usable readings."""

    top_end: np.ndarray  # last reading before the drop
    post_start: np.ndarray  # first reading after it
    top: np.ndarray  # level before [m]
    post: np.ndarray  # level after [m]
    n_top: np.ndarray  # readings in the level before
    n_post: np.ndarray
    top_run_start: np.ndarray  # first reading of the plateau before the drop
    post_run_end: np.ndarray  # last reading of the plateau after it

    def keep(self, which: np.ndarray) -> _Advances:
        return _Advances(*(getattr(self, f)[which] for f in self.__dataclass_fields__))


def _drops(r: np.ndarray, stroke: float, tol: float) -> list[tuple[int, int]]:
    """(peak, trough) of each drop of the reading: the down-swings of a quarter stroke (estimators.faults.ram_levels
    `swings` on -r), split where the ram rests on the way down (a level of at least three readings a quarter
    stroke from both ends: two advances without a push between them, as at a face end)."""
    out = []
    for lo, hi in swings(np.ascontiguousarray(-r), 0.25 * stroke):
        seg = r[lo:hi + 1]
        step_ok = np.abs(np.diff(seg)) <= tol
        flat = np.zeros(seg.size, bool)
        flat[1:-1] = step_ok[:-1] & step_ok[1:]
        start = lo
        for a, b in _runs_1d(flat):
            level = float(np.median(seg[a:b + 1]))
            if b - a >= 2 and r[start] - level > 0.25 * stroke and level - seg[-1] > 0.25 * stroke:
                out.append((start, lo + a))
                start = lo + b
        out.append((start, hi))
    return out


def _candidate_advances(r: np.ndarray, layout: RamLayout) -> _Advances:
    tol, stroke, sig = layout.level_tol_m, layout.stroke_m, layout.change_sigma_m
    rows = []
    for lo, hi in _drops(r, stroke, tol) if r.size > 2 else []:
        row = drop_levels(r, lo, hi, tol, sig)
        if ADVANCE_BAND[0] * stroke <= row[2] - row[3] <= ADVANCE_BAND[1] * stroke:
            rows.append(row)
    cols = [np.array(c) for c in zip(*rows)] if rows else [np.zeros(0)] * 8
    return _Advances(*(c.astype(float) if k in (2, 3) else c.astype(np.int64) for k, c in enumerate(cols)))


def _advances(x: np.ndarray, usable: np.ndarray, layout: RamLayout) -> tuple[list[np.ndarray], list[_Advances],
                                                                          list[np.ndarray]]:
    """Per support: its usable grid indices, its drops of about a stroke, and which of them are sure advances:
    the ram was extended by whole strokes above the face's rest level before and is at the rest level (or
    whole strokes above it, after a face-end push) after, within REST_TOLERANCE strokes and the stroke
    check's tolerance. The others (a scaled sensor, the end of a rail deviation) are left to the neighbours."""
    idxs = [np.flatnonzero(usable[:, j]) for j in range(x.shape[1])]
    cand = [_candidate_advances(x[idx, j], layout) for j, idx in enumerate(idxs)]
    posts = np.concatenate([c.post for c in cand])
    rest = float(np.median(posts)) if posts.size else 0.0
    stroke = layout.stroke_m
    sure = []
    for c in cand:
        tol = REST_TOLERANCE * stroke + _stroke_threshold(layout, c.n_top, c.n_post)
        above, below = c.top - rest, c.post - rest
        sure.append((np.abs(above - stroke * np.maximum(np.rint(above / stroke), 1.0)) <= tol)
                    & (np.abs(below - stroke * np.maximum(np.rint(below / stroke), 0.0)) <= tol))
    return idxs, cand, sure


def _pan_advance(x: np.ndarray, usable: np.ndarray, idxs, advances: list[_Advances], sure: list[np.ndarray],
                 a: np.ndarray, stroke: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """p = reading + stroke x (advances so far), NaN where unusable or while the ram retracts, and the number of
    advances counted at each drop (in the order of `advances`).

    Sure advances count one. The count is then re-anchored on the neighbours at every drop, at the first
    reading and after every stretch of unusable readings, since a support's reading error v = A p moves by
    A[:, k] x stroke for each advance miscounted at support k: the events within NEIGHBOUR_WINDOW samples of
    the first of them on supports whose patterns overlap (and the supports from them on to a face end within
    reach, which may have pushed and advanced within one reading) are solved together: the median v over the
    next NEIGHBOUR_WINDOW readings, or its change from the readings before, fitted with whole miscounts
    (`_miscounts`), unless the error of one support without an event there explains it as well. That drops a sensor drop of about a stroke that is no
    advance (the end of a rail deviation on several supports at once), and counts the advances hidden in a
    dropout or a stuck stretch. A reading error of more than half a stroke at such an event is taken for a
    miscount."""
    n_t, n_sup = x.shape
    pan = np.where(usable, x, np.nan)
    count = np.zeros((n_t, n_sup))
    events = []  # (grid index from which the count changes, support, index in `advances` or -1 for a gap end)
    for j in range(n_sup):
        idx, adv = idxs[j], advances[j]
        for m, (b, k) in enumerate(zip(adv.top_end, adv.post_start)):
            pan[idx[b] + 1:idx[k], j] = np.nan
            events.append((int(idx[k]), j, m))
            if sure[j][m]:
                count[idx[k]:, j] += 1.0
        if idx.size:  # the first reading (a log may start in mid-cycle) and the first after each gap
            events += [(int(idx[0]), j, -1)] + [(int(idx[g + 1]), j, -1) for g in np.flatnonzero(np.diff(idx) > 1)]
    events.sort()
    v = _apply_banded(a, pan + stroke * count)
    band = max(abs(o) for o in range(-(n_sup - 1), n_sup) if np.any(np.abs(np.diagonal(a, o)) > 1e-12))
    fixes: dict[tuple[int, int], float] = {}
    k = prev = 0
    while k < len(events):  # clusters of events close in time
        end = k + 1
        while end < len(events) and events[end][0] - events[k][0] <= NEIGHBOUR_WINDOW:
            end += 1
        cluster, k = events[k:end], end
        stop = min(events[end][0] if end < len(events) else n_t, n_t)  # v up to the next cluster
        sups = sorted({j for _, j, _ in cluster})
        groups, cur = [], [sups[0]]
        for j in sups[1:]:
            if j - cur[-1] <= band:
                cur.append(j)
            else:
                groups.append(cur)
                cur = [j]
        groups.append(cur)
        for g in groups:
            last = {j: (i, m) for i, j, m in cluster if j in g}  # the last event of each support
            t0 = max(i for i, _ in last.values())
            t_first = min(i for i, _ in last.values())
            # the supports from the group on to a face end within reach may have advanced unseen (a push and
            # an advance within one reading, as at a face end): they may take a count too
            lo_g = 0 if g[0] <= 3 * band else g[0]
            hi_g = n_sup - 1 if g[-1] >= n_sup - 1 - 3 * band else g[-1]
            for j in [*range(lo_g, g[0]), *range(g[-1] + 1, hi_g + 1)]:
                last[j] = (t0, None)
            g = sorted(last)
            rows = np.arange(max(g[0] - band, 0), min(g[-1] + band, n_sup - 1) + 1)
            after = _near_median(v[t0:max(min(t0 + 3 * NEIGHBOUR_WINDOW, stop), t0 + 1), rows])
            before = _near_median(v[max(t_first - 3 * NEIGHBOUR_WINDOW, prev, 0):t_first, rows][::-1])
            ok = np.isfinite(after)
            if not ok.any():
                continue
            # v after the events is whole miscounts, and a sensor error that either vanished with them (the end
            # of a rail deviation) or went on through them (a drift at an advance)
            design = stroke * a[np.ix_(rows[ok], g)]
            best = None
            for obs in (after[ok], after[ok] - np.nan_to_num(before[ok])):
                miss = _miscounts(design, obs, stroke)
                if miss.any():
                    left = ((obs - design @ miss) ** 2).sum()
                    if best is None or left / (obs ** 2).sum() < best[2]:
                        best = (miss, obs, left / (obs ** 2).sum())
            if best is None:
                continue
            miss, obs, share = best
            # a sensor error of a support without an event here (a stuck ram) that explains v as well is no
            # miscount of its neighbours
            others = a[np.ix_(rows[ok], [r for r in rows if r not in last])]
            norm2 = (others ** 2).sum(axis=0)
            fit = np.divide((obs @ others) ** 2, norm2, out=np.zeros_like(norm2), where=norm2 > 0)
            if others.size and (obs ** 2).sum() - fit.max() <= share * (obs ** 2).sum():
                continue
            for j, n_miss in zip(g, miss):
                if n_miss:
                    i, m = last[j]
                    if m is not None:
                        fixes[(j, m)] = fixes.get((j, m), 0.0) - n_miss
                    count[i:, j] -= n_miss
                    v[i:] -= stroke * n_miss * a[:, j][None, :]
        prev = cluster[-1][0]
    p = pan + stroke * count
    n_counted = [np.array([float(sure[j][m]) + fixes.get((j, m), 0.0) for m in range(advances[j].top.size)])
                 for j in range(n_sup)]
    return p, n_counted


def _near_median(seg: np.ndarray) -> np.ndarray:
    """Per column, the median of the first NEIGHBOUR_WINDOW finite values (NaN if none)."""
    out = np.full(seg.shape[1], np.nan)
    for r in range(seg.shape[1]):
        fin = seg[np.isfinite(seg[:, r]), r][:NEIGHBOUR_WINDOW]
        if fin.size:
            out[r] = np.median(fin)
    return out


def _miscounts(design: np.ndarray, obs: np.ndarray, stroke: float) -> np.ndarray:
    """Whole miscounts m (one per column, columns in support order) with obs ~ design @ m: from m = 0, the
    change by one of a run of neighbouring counts (a block of neighbours miscounted together looks almost like a
    smooth face: only its edges show, so single changes alone do not find it), or of two neighbours in opposite
    senses, that reduces |obs - design m|^2 most, while it reduces it by more than MISCOUNT_GAIN strokes
    squared; taken only if it leaves at most MISCOUNT_LEFT of |obs|^2."""
    n = design.shape[1]
    if (obs ** 2).sum() <= MISCOUNT_GAIN * stroke ** 2:  # no change can gain more than all there is
        return np.zeros(n)
    moves = []
    for k in range(n):
        for end in range(k + 1, min(k + MISCOUNT_RUN, n) + 1):  # a run of neighbours, all one more or one less
            step = np.zeros(n)
            step[k:end] = 1.0
            moves += [step, -step]
    for k in range(1, n):  # every count from one end of the group on (a face end that advanced unseen)
        step = np.zeros(n)
        step[k:] = 1.0
        moves += [step, -step, step[::-1].copy(), -step[::-1]]
    for k in range(n - 1):  # one more and one less next to each other
        step = np.zeros(n)
        step[k], step[k + 1] = 1.0, -1.0
        moves += [step, -step]
    moves = np.array(moves).T  # (n, moves)
    miss = np.zeros(n)
    resid = obs.copy()
    for _ in range(4 * n):
        after = resid[:, None] - design @ moves
        gain = (resid ** 2).sum() - (after ** 2).sum(axis=0)
        k = int(np.argmax(gain))
        if gain[k] <= MISCOUNT_GAIN * stroke ** 2:
            break
        miss += moves[:, k]
        resid = after[:, k]
    # miscounts explain the residual nearly whole; a fit that leaves much is a sensor error, not a count
    return miss if (resid ** 2).sum() <= MISCOUNT_LEFT * (obs ** 2).sum() else np.zeros(n)


@dataclass(frozen=True)
class _Stroke:
    """A stroke that failed the commanded-stroke check (grid indices)."""

    support: int
    first: int
    last: int
    confirmed: int
    error: float  # measured - commanded [m]
    threshold: float
    relative: float  # measured / commanded - 1


def _stroke_threshold(layout: RamLayout, n1, n2):
    """tau_s: geometry tolerance + the noise of two plateau medians + the largest step the level-change
    test can miss next to an event (one reading against LEVEL_SAMPLES - 1)."""
    n1, n2 = np.maximum(n1, 1), np.maximum(n2, 1)
    hidden = CHANGE_SIGMAS * layout.change_sigma_m * math.sqrt(1.0 + 1.0 / (LEVEL_SAMPLES - 1))
    return (layout.stroke_tol_m + hidden
            + STROKE_SIGMAS * layout.sigma_m * 1.2533 * np.sqrt(1.0 / n1 + 1.0 / n2))


def _stroke_checks(x: np.ndarray, idxs, advances: list[_Advances], layout: RamLayout,
                   drops: list[np.ndarray] | None = None) -> list[_Stroke]:
    """Check (a): every advance retracts the ram by the commanded stroke, and between advances it rises by whole
    strokes (none where a face-end push came first).

    Not judged: a drop across unusable readings (the push may have gone on unseen before it), and a drop at
    the same reading as a drop of a neighbour (`drops`: grid indices of every support's drops), as at a face
    end, where the last push step and the advance may fall within one reading."""
    stroke, tol = layout.stroke_m, layout.level_tol_m
    out = []
    for j, (idx, adv) in enumerate(zip(idxs, advances)):
        if adv.top.size == 0:
            continue
        r = x[idx, j]
        seen = idx[adv.post_start] - idx[adv.top_end] == adv.post_start - adv.top_end
        if drops is not None:
            for k in (j - 1, j + 1):
                if 0 <= k < len(drops) and drops[k].size:
                    seen &= np.abs(drops[k][None, :] - idx[adv.post_start][:, None]).min(axis=1) > 1
        err = np.where(seen, adv.top - adv.post - stroke, 0.0)
        thr = _stroke_threshold(layout, adv.n_top, adv.n_post)
        for m in np.flatnonzero(np.abs(err) > thr):
            out.append(_Stroke(j, idx[adv.top_end[m]], idx[adv.post_start[m]], idx[adv.post_start[m]],
                               float(err[m]), float(thr[m]), float(err[m] / stroke)))
        start_level, n_start, start_run_end = side_level(r, 0, 1, tol, layout.change_sigma_m)
        starts = np.concatenate([[start_level], adv.post[:-1]])
        n_starts = np.concatenate([[n_start], adv.n_post[:-1]])
        run_ends = np.concatenate([[start_run_end], adv.post_run_end[:-1]])
        rise = adv.top - starts
        k = np.maximum(np.rint(rise / stroke), 0.0)
        seen[0] &= idx[0] == 0  # a support whose first readings are missing may have been pushing already
        err = np.where(seen, rise - k * stroke, 0.0)
        thr = _stroke_threshold(layout, adv.n_top, n_starts)
        for m in np.flatnonzero(np.abs(err) > thr):
            first = min(int(run_ends[m]), int(adv.top_run_start[m]))
            out.append(_Stroke(j, idx[first], idx[adv.top_run_start[m]], idx[adv.post_start[m]],
                               float(err[m]), float(thr[m]), float(err[m] / (max(k[m], 1.0) * stroke))))
    return out


# -------------------------------------------------------------------------------------- neighbour check


@functools.lru_cache(maxsize=8)
def _neighbour_filter(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, |P[:, k]|^2, noise gain |A_k|, bend gain |c_k|_1) of the single-support fault estimate v = A p for a
    face of n supports (cached: the benchmark checks many logs of one face; do not modify the arrays)."""
    p = np.eye(n)
    for j in range(n):
        order = np.argsort(np.abs(np.arange(n) - j) + 1e-3 * np.arange(n), kind="stable")
        others = np.sort(order[1:NEIGHBOURS + 1])
        x = (others - j).astype(float)
        design = np.column_stack([np.ones_like(x), x, x ** 2])
        p[j, others] -= np.linalg.pinv(design)[0]  # intercept row: the prediction at j
    pp = (p ** 2).sum(axis=0)
    a = (p.T @ p) / pp[:, None]
    d2 = np.zeros((n - 2, n))
    i = np.arange(n - 2)
    d2[i, i], d2[i, i + 1], d2[i, i + 2] = 1.0, -2.0, 1.0
    c = np.linalg.lstsq(d2.T, a.T, rcond=None)[0]  # a_k = d2^T c_k (a kills linear and quadratic faces)
    return a, pp, np.linalg.norm(a, axis=1), np.abs(c).sum(axis=0)


def _apply_banded(a: np.ndarray, p: np.ndarray) -> np.ndarray:
    """p @ a.T using only the non-zero entries of a, so a NaN spreads only to the supports that use it."""
    n = a.shape[0]
    out = np.zeros_like(p)
    for o in range(-(n - 1), n):
        coef = np.diagonal(a, o)  # a[k, k + o]
        if not np.any(np.abs(coef) > 1e-12):
            continue
        ks = np.arange(max(0, -o), min(n, n - o))
        use = np.abs(coef) > 1e-12
        out[:, ks[use]] += coef[use] * p[:, ks[use] + o]
    return out


def _strongest(vs: np.ndarray, a: np.ndarray, pp: np.ndarray) -> np.ndarray:
    """(T, S) mask: the support's fault pattern explains the residuals at least as well as that of any support
    whose pattern overlaps it (score v^2 |P[:, k]|^2; a fault at k moves v_i only where a[i, k] != 0)."""
    n = a.shape[0]
    score = np.nan_to_num(vs ** 2 * pp[None, :], nan=0.0)
    best = score.copy()
    for o in range(1, n):
        near = (np.abs(np.diagonal(a, o)) > 1e-12) | (np.abs(np.diagonal(a, -o)) > 1e-12)  # pairs (k, k + o)
        if not near.any():
            continue
        k = np.flatnonzero(near)
        best[:, k] = np.maximum(best[:, k], score[:, k + o])
        best[:, k + o] = np.maximum(best[:, k + o], score[:, k])
    return score >= best


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


# ------------------------------------------------------------------------------------- classification


def _classify(j: int, lo: int, hi: int, tg, x, v, vs, thr, strokes: list[_Stroke], flat_ok: bool) -> Finding:
    """One finding for support j's flagged stretch lo..hi (grid indices): the neighbour check's flagged readings
    decide the kind; a stretch only the stroke check saw is a scale error."""
    n_t = len(tg)
    own = [s for s in strokes if s.support == j and s.last >= lo and s.first <= hi]
    confirmed = min([s.confirmed for s in own], default=n_t - 1)
    span = np.arange(lo, hi + 1)
    hot = span[np.isfinite(vs[span, j]) & (np.abs(np.nan_to_num(vs[span, j])) > thr[j])]
    use = hot[np.isfinite(v[hot, j]) & np.isfinite(x[hot, j])]
    if use.size < 3:
        if own:
            s = max(own, key=lambda s: abs(s.error))
            return Finding(j, j, "scale", tg[lo], tg[hi], tg[confirmed], s.relative, s.error, s.threshold, "m")
        stat = float(vs[hot[np.argmax(np.abs(vs[hot, j]))], j])
        return Finding(j, j, "offset", tg[hot[0]], tg[hot[-1]], tg[min(hot[0] + NEIGHBOUR_WINDOW // 2, n_t - 1)],
                       stat, stat, float(thr[j]), "m")
    confirmed = min(confirmed, hot[0] + NEIGHBOUR_WINDOW // 2, n_t - 1)
    first, last = tg[hot[0]], tg[hot[-1]]
    t, e = tg[use], v[use, j]
    r = x[use, j] - e  # the true ram length, as the neighbours see it
    stat = float(vs[hot[np.argmax(np.abs(vs[hot, j]))], j])
    tau = float(thr[j])
    if not flat_ok:  # a reading that stays put while the neighbours say the ram moved
        col = x[:, j]
        lo_f = hi_f = int(use[0])
        while lo_f > 0 and col[lo_f - 1] == col[lo_f]:  # back to where the reading froze
            lo_f -= 1
        while hi_f < hi and col[hi_f + 1] == col[hi_f]:
            hi_f += 1
        frozen = use[use <= hi_f]
        if frozen.size >= MIN_FLAGGED and np.ptp(v[lo_f:hi_f + 1, j][np.isfinite(v[lo_f:hi_f + 1, j])]) > tau:
            return Finding(j, j, "stuck", tg[lo_f], tg[hi_f], tg[confirmed], float(col[lo_f]), stat, tau, "m")
    rss_const = float(((e - e.mean()) ** 2).sum())
    c = float(e @ r / (r @ r))
    rss_scale = float(((e - c * r) ** 2).sum())
    tc = t - t.mean()
    slope = float(tc @ e / (tc @ tc)) if tc @ tc > 0 else 0.0
    rss_drift = float(((e - e.mean() - slope * tc) ** 2).sum())
    var = max(min(rss_scale, rss_drift), 1e-30) / max(e.size - 2, 1)  # scatter about the better model
    gain = MODEL_SIGMAS ** 2 * var  # a model must explain this much more than a constant
    is_scale = rss_const - rss_scale > gain and abs(c) * np.ptp(r) > 0.5 * tau
    is_drift = rss_const - rss_drift > gain and abs(slope) * (t[-1] - t[0]) > 0.5 * tau
    if is_scale and (not is_drift or rss_scale <= rss_drift):
        return Finding(j, j, "scale", first, last, tg[confirmed], c, stat, tau, "m")
    if is_drift:
        start = min(max(float(t.mean() - e.mean() / slope), tg[0]), first)
        return Finding(j, j, "drift", start, last, tg[confirmed], slope, stat, tau, "m")
    return Finding(j, j, "offset", first, last, tg[confirmed], float(np.median(e)), stat, tau, "m")


def _end_pairs(chain: list[Finding], n_sup: int, gap: float) -> list[Finding]:
    """At each face end the last two supports' fault patterns are nearly alike (one side only: the pattern of
    support 0 and that of support 1 are over 90 % parallel), so the attribution may flick between them: of two
    overlapping findings there, keep the longer, stretched over both windows."""
    out = list(chain)
    for pair in ((0, 1), (n_sup - 2, n_sup - 1)):
        changed = True
        while changed:
            changed = False
            ends = [f for f in out if f.support in pair and f.last_support == f.support]
            for f in ends:
                for g in ends:
                    if (f is not g and f.support != g.support and f.t_start <= g.t_end + gap
                            and g.t_start <= f.t_end + gap):
                        keep, drop = (f, g) if f.t_end - f.t_start >= g.t_end - g.t_start else (g, f)
                        merged = dataclasses.replace(keep, t_start=min(keep.t_start, drop.t_start),
                                                     t_end=max(keep.t_end, drop.t_end),
                                                     t_detect=min(keep.t_detect, drop.t_detect))
                        out = [merged if h is keep else h for h in out if h is not drop]
                        changed = True
                        break
                if changed:
                    break
    return out


def _rail_runs(findings: list[Finding], dt: float) -> list[Finding]:
    """Merge chain findings on RAIL_MIN_SUPPORTS or more neighbouring supports at overlapping times into one
    rail_deviation finding each."""
    n = len(findings)
    if n < RAIL_MIN_SUPPORTS:
        return findings
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    gap = RAIL_GAP * dt
    for i in range(n):
        for k in range(i + 1, n):
            fi, fk = findings[i], findings[k]
            if (fi.support != fk.support and abs(fi.support - fk.support) <= RAIL_REACH
                    and fi.t_start <= fk.t_end + gap and fk.t_start <= fi.t_end + gap):
                parent[root(i)] = root(k)
    groups: dict[int, list[Finding]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(findings[i])
    out = []
    for members in groups.values():
        sups = sorted({f.support for f in members})
        if len(sups) < RAIL_MIN_SUPPORTS:
            out.extend(members)
            continue
        seen: set[int] = set()
        confirmed = members[0].t_detect
        for f in sorted(members, key=lambda f: f.t_detect):
            seen.add(f.support)
            if len(seen) >= RAIL_MIN_SUPPORTS:
                confirmed = f.t_detect
                break
        lateral = [f.value for f in members if f.kind in ("offset", "stuck")] or [f.statistic for f in members]
        big = max(members, key=lambda f: abs(f.statistic) / f.threshold)
        out.append(Finding(sups[0], sups[-1], "rail_deviation", min(f.t_start for f in members),
                           max(f.t_end for f in members), confirmed, float(max(lateral, key=abs)),
                           big.statistic, big.threshold, big.unit))
    return out


# ------------------------------------------------------------------------------------------------- API


def _chain_checks(tg: np.ndarray, x: np.ndarray, usable: np.ndarray, layout: RamLayout) -> list[Finding]:
    """Checks (a) and (b) on the usable readings: one finding per flagged stretch of a support."""
    n_sup = x.shape[1]
    idxs, candidates, sure = _advances(x, usable, layout)
    # (b) neighbour consistency: each support's reading error against the chain of its neighbours
    a, pp, noise_gain, bend_gain = _neighbour_filter(n_sup)
    pan, counts = _pan_advance(x, usable, idxs, candidates, sure, a, layout.stroke_m)
    v = _apply_banded(a, pan)
    # (a) commanded stroke, on the drops the neighbours confirm as advances
    strokes = _stroke_checks(x, idxs, [c.keep(n >= 1) for c, n in zip(candidates, counts)], layout,
                             [idx[c.post_start] for idx, c in zip(idxs, candidates)])
    vs = _running_median(v, NEIGHBOUR_WINDOW)
    thr = layout.bend_m * bend_gain + NEIGHBOUR_SIGMAS * layout.sigma_m * noise_gain * 1.2533 / math.sqrt(
        NEIGHBOUR_WINDOW)
    flag = (np.abs(np.nan_to_num(vs)) > thr[None, :]) & _strongest(vs, a, pp)
    for j, lo, hi in zip(*_runs(flag)):  # a flick of the attribution to a neighbour is no finding
        if hi - lo + 1 < MIN_FLAGGED:
            flag[lo:hi + 1, j] = False
    # stretches per support: neighbour flags and failed strokes, merged; a stretch inside a longer one of a
    # support two or fewer away is that fault's spill-over
    chain: list[Finding] = []
    flat_ok = _flat_run(layout) is not None
    for j in range(n_sup):
        marks = flag[:, j].copy()
        for s in strokes:
            if s.support == j:
                marks[s.first:s.last + 1] = True
        for lo, hi in _runs_1d(marks, gap=MERGE_GAP):
            chain.append(_classify(j, lo, hi, tg, x, v, vs, thr, strokes, flat_ok))
    return [f for f in chain if not any(g is not f and 0 < abs(g.support - f.support) <= 2
                                        and g.t_start <= f.t_start and f.t_end <= g.t_end
                                        and g.t_end - g.t_start > f.t_end - f.t_start for g in chain)]


def _frozen_runs(tg: np.ndarray, x: np.ndarray, stuck: list[Finding]) -> list[tuple[int, int, int]]:
    """(support, first, last grid index) of the whole run of equal readings around each stuck finding."""
    out = []
    for f in stuck:
        col = x[:, f.support]
        lo, hi = int(np.searchsorted(tg, f.t_start)), int(np.searchsorted(tg, f.t_end))
        same = np.abs(col - col[lo]) <= 1e-12
        while lo > 0 and same[lo - 1]:
            lo -= 1
        while hi + 1 < col.size and same[hi + 1]:
            hi += 1
        out.append((f.support, lo, hi))
    return out


def check_rams(t, support, extension, valid, layout: RamLayout) -> list[Finding]:
    """All push-ram findings of a log (columns of the PUSHRAM stream), sorted by time then support.

    A sensor too fine for its quantum to show a frozen reading by flatness (see `_flat_run`) is found stuck by
    the neighbour check once its neighbours move; its frozen readings are then left out like those of a flat
    stuck sensor and checks (a) and (b) run again, so the stuck ram's error of up to a stroke does not spill
    into the advance counts of its neighbours."""
    tg, x = _grid(t, support, extension, valid, layout.n_supports)
    dt = float(np.median(np.diff(tg)))
    findings, mask = _self_checks(tg, x, layout)
    usable = ~mask
    chain = _chain_checks(tg, x, usable, layout)
    stuck: list[Finding] = []
    for _ in range(STUCK_PASSES):  # the strongest stuck ram first: its error spills onto the others' counts
        new = [f for f in chain if f.kind == "stuck"
               and not any(f.support == g.support and f.t_start <= g.t_end and g.t_start <= f.t_end for g in stuck)]
        if not new:
            break
        f = max(new, key=lambda f: abs(f.statistic) / f.threshold)
        (_, lo, hi), = _frozen_runs(tg, x, [f])
        usable[lo:hi + 1, f.support] = False
        stuck.append(dataclasses.replace(f, t_start=float(tg[lo]), t_end=float(tg[hi])))
        chain = _chain_checks(tg, x, usable, layout)
    chain = stuck + [f for f in chain if not any(f.support == g.support and f.t_start <= g.t_end
                                                 and g.t_start <= f.t_end for g in stuck)]
    findings += _rail_runs(_end_pairs(chain, layout.n_supports, MERGE_GAP * dt), dt)
    findings.sort(key=lambda f: (f.t_start, f.support, f.kind))
    return findings


def check_log(pushram, layout: RamLayout) -> list[Finding]:
    """check_rams on a PUSHRAM table (a mapping of column arrays or a pyarrow table)."""
    try:
        cols = [pushram[c] for c in ("t", "support", "extension", "valid")]
    except (KeyError, TypeError):
        raise ValueError("pushram: the table needs the columns t, support, extension, valid "
                         "(estimators.io.logformat.PUSHRAM)") from None
    cols = [c.to_numpy() if hasattr(c, "to_numpy") else np.asarray(c) for c in cols]
    return check_rams(*cols, layout)
