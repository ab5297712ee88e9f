"""The face alignment system (OPC 40561 Longwall Operation, use case 4.2.6; LASC's face alignment): from one shear's
estimated shearer path, the face line and an offset per shield for the next shear.

Face line. The shearer rides on the AFC on two shoes `shoe_spacing_m` apart, its body point midway between them, so
over a straight cut the path's advance coordinate x against the along-face y (both in the face frame F, DESIGN: x
towards the coal wall, y along the face) is the mean of the pan line at the two shoes, as it stood when the machine
passed: p(y) = (L(y - a) + L(y + a)) / 2, a half the shoe spacing. Averaged over each shield's share of the face
(|y - y_j| <= spacing / 2) the path gives p_j; the line at the shields L_j (linear between them) solves

    min  sum_j (p_j - (L(y_j - a) + L(y_j + a)) / 2)^2 + LINE_SMOOTHING sum_j (D2 L)_j^2

(numpy least squares). The two-shoe mean is blind at wavelengths 4a / (2m + 1), which the small second-difference
term fills smoothly; the path alone, taken as the line, is not: on drift_200 a shield's stop errors are independent of
its neighbours', and the path's deviation from its best-fit line correlated with the pan line's at -0.1 to 0.1; the
solved line at 0.91-0.94, its error 1.6-1.8 mm RMS of 3.7-5.0. With no shoe spacing the path is the line.

That is the true body point's path. An inertial estimate of it is not: the filter holds the machine's velocity along
its body axis (the non-holonomic constraint, estimators.shearer), and the body's heading is the chord between the
shoes, so the path it gives integrates the chord's slope, (L(y + a) - L(y - a)) / 2a, and is the line's mean over the
shoe span, p(y) = 1/(2a) integral of L from y - a to y + a: blind at wavelengths 2a / m and of the opposite sign
between them, where the two-shoe model reads a kink backwards and the loop steered it further out. `path_model`
says which the path is ("shoes" for the truth, "heading" for an estimate); on face_alignment open loop (12 cycles),
the line's error about its best-fit line against the truth's, per shear: kf_rts 5.3 mm growing to 17.9 mm with the
two-shoe model, 3.0-5.3 mm with the heading model; kf_cpoem_rts 5.7-19.4 and 3.7-10.4 mm; the true path 1.6-4.0
and 5.4-16.4 mm.

Not everywhere: at the gate where the cut starts, the pans were pushed a web during the last shear's snake sumping,
and the snake runs back down to the unpushed line; the path there says nothing of the line the rest of the cut
sees. Shields within `end_zone_m` of the start of the path are left out (the sump and the snake: the shearer's length
and the push lag, snake and two pans, as the positioning filters' end zone). A shear counts as full when the path
spans at least `min_coverage` of the face (first to last shield) and its points cover that share of the shields
between its ends outside that zone.

Creep. The face slides along itself as it is pushed (the seam's dip, the snake's pull), and the shields with it:
after 50 cycles of face_alignment's 3 deg seam, by 1.7 m, a shield spacing. A cut runs between the shearer's
reversal points, which the drive frames at the gates carry along, so the mean shift of the path's two ends from
where they were on the installed face (`path_ends_m`) is the creep at the gates, and the shields stand that far from
their installed y. Without it the offsets meant for one shield went to its neighbour: the loop held the line at 8-11
mm RMS for 50 cycles, then drove it to 53 mm by cycle 100.

The deviation from the target line is carried from shear to shear: each shear measures it where its face line is
valid; elsewhere (the start gate's end zone, the last half machine length at the far gate that the body point never
reaches) the deviation is the last one measured there less the share of it the offsets since have corrected, times
(1 - gain) per shear. In bidirectional cutting each gate's end zone is measured every other shear, from the cut that
finishes there.

Target. The target line runs through the face line's mean, x*(y) = xbar + b* (y - ybar). Its slope b* is the face
line's own least-squares slope b turned towards the planned slope (`planned_slope`: 0 is square to the gate roads,
which run along F's x; None keeps the face's present orientation) by at most tan(max_turn) per shear.

Offsets. The wanted correction is d_j = gain (x*(y_j) - x_j), x*(y_j) - x_j the carried deviation: a gain under 1 corrects part of the error per shear,
so that the estimate's noise is not pushed into the face in full. The offsets o solve the bounded least squares
(scipy.optimize.lsq_linear)

    min  sum_j (o_j - d_j)^2 + lambda sum_j (D2 o)_j^2,     |(D2 o)_j| <= kappa,

parametrized by o's first value, first difference and second differences (o = A z, A the double running sum), so
that the bend limit is a box bound: kappa = curvature_limit * spacing is the share of the pans' horizontal bend
limit an offset profile may use (the twin's check_offsets), lambda = smoothing_shields^4 spreads a correction over
about that many shields. The result is then scaled, if need be, into the stroke limits (|o| <= max_offset,
o <= max_extra_push), which keeps its bends within kappa.

Uncertainty. An offset is gain times the face line's error where it stands; the path's one-sigma across the face,
sigma_x^2 = cos^2(a) sd_e^2 + sin^2(a) sd_n^2 (a the face azimuth), averaged over the shield's share, is taken as
the offset's one-sigma over gain: the filters' errors along a pass are strongly correlated, so the smoothing is not
credited with averaging them down (an upper bound; a common error is removed by the target line and costs nothing).

Sequence. Every full shear from a healthy estimator gives a new set of offsets and increments the sequence number
(OPC 40561's SequenceNumber), which the roof support system watches. A shear that is not full, or an estimator
whose health monitor raised (estimators.shearer.health), gives no new offsets: the last good set is held, with a
note saying why.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.optimize import lsq_linear

from estimators.face.straightness import mat_ft, sd_in_face_frame

LINE_SMOOTHING = 0.03
"""Weight of the line's second differences against the path's misfit when the line is solved from the two-shoe mean
(module docstring; the line's correlation with the truth on drift_200: 0.91-0.94 at 0.01, 0.89-0.92 at 0.1, 0.71 at
1)."""
HEADING_POINTS = 29
"""Points of the trapezoidal mean over the shoe span in the heading path model (a 7 m span: one every 0.25 m, under
the pans' 1.5-2 m)."""
LIMIT_MARGIN = 0.95
"""Share of each limit the offsets are brought within (the bounded solver meets its bounds to about 1e-10; the
twin's check_offsets holds the exact limits)."""


@dataclass(frozen=True)
class AlignmentConfig:
    """A face's figures for its alignment system. Lengths in metres, along-face positions y in F."""

    station_y_m: np.ndarray
    """Along-face position of each shield's push (its ram point), headgate first."""
    spacing_m: float
    """Shield spacing along the face."""
    azimuth_rad: float
    """Face azimuth: F's y axis, clockwise from north."""
    max_offset_m: float
    """Largest offset either way (a share of the web: more is a re-cut)."""
    max_extra_push_m: float
    """Largest offset towards the coal wall: what the snake can take beyond the web within the bend limit."""
    curvature_limit_rad: float
    """Largest bend an offset profile may put in the face line: its second difference over the spacing [rad]."""
    gain: float = 0.7
    smoothing_shields: float = 1.0
    planned_slope: float | None = None
    max_turn_rad: float = float(np.radians(0.05))
    min_coverage: float = 0.8
    end_zone_m: float = 0.0
    """Length of the path from its start whose face line is left out (the last shear's sump and snake)."""
    shoe_spacing_m: float = 0.0
    """Distance between the shearer's shoes on the pans (0: the path is the line itself)."""
    path_model: Literal["shoes", "heading"] = "shoes"
    """What the path is of the line (module docstring): the two-shoe mean (the true body point) or the mean over the
    shoe span (an inertial estimate, which integrates the machine's heading)."""
    path_ends_m: tuple[float, float] | None = None
    """Along-face y of a straight cut's two ends on the face as installed (the shearer's reversal points, half its
    length in from each face end): the face's creep is measured against them (None: the shields stay at
    station_y_m)."""


@dataclass(frozen=True)
class ShearOffsets:
    """One set of offsets, as the alignment system publishes it."""

    sequence: int
    """Increments with every new set (0: none computed yet)."""
    offsets_m: np.ndarray
    """Per shield, positive towards the coal wall, for the next shear."""
    sd_m: np.ndarray
    """One-sigma of each offset (NaN where the estimator gives no covariance, or none computed)."""
    line_x_m: np.ndarray
    """The face line at the shields from the shear's path (NaN where the path did not reach)."""
    target_x_m: np.ndarray
    """The target line at the shields."""
    held: bool
    """True when this shear gave no new offsets and the last good set stands."""
    note: str = ""
    creep_m: float = 0.0
    """The face's creep along it measured at the gates by this shear's path (0 without path_ends_m)."""


def path_in_face_frame(p_t: np.ndarray, sd_en: np.ndarray | None, azimuth_rad: float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """A path's positions in F (K, 3) from the tangent plane t (K, 3 ENU), and its one-sigma along F's x (K,) from
    the east and north one-sigma (K, 2; None or NaN: unknown)."""
    c = mat_ft(azimuth_rad)
    p_f = np.asarray(p_t, float) @ c.T
    if sd_en is None:
        return p_f, np.full(p_f.shape[0], np.nan)
    sd = np.asarray(sd_en, float)
    return p_f, sd_in_face_frame(np.column_stack([sd[:, 0], sd[:, 1], np.zeros(len(sd))]), azimuth_rad)[:, 0]


def path_at_shields(p_f: np.ndarray, sd_x: np.ndarray, station_y_m: np.ndarray, spacing_m: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """A path in F at the shields: the mean x of its points within half a spacing of each shield's y, and the RMS of
    their one-sigma; NaN where no point falls."""
    y, x = p_f[:, 1], p_f[:, 0]
    j = np.rint((y - station_y_m[0]) / spacing_m).astype(np.int64)
    inside = (j >= 0) & (j < station_y_m.size) & np.isfinite(x)
    n = np.bincount(j[inside], minlength=station_y_m.size).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        line = np.bincount(j[inside], x[inside], station_y_m.size) / n
        var = np.bincount(j[inside], sd_x[inside] ** 2, station_y_m.size) / n
    return line, np.sqrt(var)


def _interpolation(y: np.ndarray, y_st: np.ndarray) -> np.ndarray:
    """(len(y), len(y_st)): values at y of the piecewise-linear function through the shields' values (held at the
    ends)."""
    n = y_st.size
    pos = np.clip((y - y_st[0]) / (y_st[1] - y_st[0]), 0.0, n - 1.0)
    i0 = np.minimum(np.floor(pos).astype(np.int64), n - 2)
    w = pos - i0
    m = np.zeros((y.size, n))
    rows = np.arange(y.size)
    m[rows, i0] = 1.0 - w
    m[rows, i0 + 1] += w
    return m


def path_kernel(station_y_m: np.ndarray, shoe_spacing_m: float, path_model: str) -> np.ndarray:
    """(n, n): the path at the shields from the line at the shields, as `path_model` sees it (module docstring): the
    two-shoe mean, or the trapezoidal mean over the shoe span (HEADING_POINTS)."""
    a = shoe_spacing_m / 2
    if path_model == "shoes":
        return 0.5 * (_interpolation(station_y_m - a, station_y_m) + _interpolation(station_y_m + a, station_y_m))
    w = np.full(HEADING_POINTS, 1.0 / (HEADING_POINTS - 1))
    w[[0, -1]] *= 0.5
    return sum(wk * _interpolation(station_y_m + dy, station_y_m)
               for wk, dy in zip(w, np.linspace(-a, a, HEADING_POINTS)))


def rail_line(path_x: np.ndarray, rows: np.ndarray, station_y_m: np.ndarray, shoe_spacing_m: float,
              path_model: str = "shoes") -> np.ndarray:
    """The pan line at the shields from the path at the shields `path_x`, using the shields `rows` (mask): the
    least-squares line whose path (path_kernel) is the path (module docstring)."""
    n = station_y_m.size
    mean = path_kernel(station_y_m, shoe_spacing_m, path_model)
    d2 = np.diff(np.eye(n), 2, axis=0)
    lhs = np.vstack([mean[rows], np.sqrt(LINE_SMOOTHING) * d2])
    rhs = np.concatenate([path_x[rows], np.zeros(n - 2)])
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0]


def _double_sum(n: int) -> np.ndarray:
    """A (n, n): o = A z for z = (o_0, o_1 - o_0, second differences of o)."""
    a = np.zeros((n, n))
    a[:, 0] = 1.0
    if n > 1:
        a[:, 1] = np.arange(n)
        k = np.arange(n)[:, None] - np.arange(2, n)[None, :] + 1  # rows i >= col + 1 take (i - col + 1) of it
        a[:, 2:] = np.clip(k, 0, None)
    return a


def solve_offsets(wanted_m: np.ndarray, cfg: AlignmentConfig) -> np.ndarray:
    """The offsets closest to the wanted correction within the bend limit, smoothed, then scaled into the stroke
    limits (module docstring)."""
    n = wanted_m.size
    a = _double_sum(n)
    lam = cfg.smoothing_shields ** 4
    rows = np.vstack([a, np.sqrt(lam) * np.eye(n)[2:]])
    rhs = np.concatenate([wanted_m, np.zeros(max(n - 2, 0))])
    kappa = LIMIT_MARGIN * cfg.curvature_limit_rad * cfg.spacing_m
    lo = np.concatenate([[-np.inf, -np.inf], np.full(n - 2, -kappa)])[:n]
    hi = -lo
    z = lsq_linear(rows, rhs, bounds=(lo, hi), method="bvls").x
    o = a @ z
    worst = max(np.abs(o).max() / (LIMIT_MARGIN * cfg.max_offset_m),
                o.max() / (LIMIT_MARGIN * cfg.max_extra_push_m), 1.0)
    return o / worst


class FaceAlignmentSystem:
    """Offsets per shear with their sequence number; holds the last good set when a shear cannot give one."""

    def __init__(self, cfg: AlignmentConfig):
        self.cfg = cfg
        n = cfg.station_y_m.size
        nan = np.full(n, np.nan)
        self.last = ShearOffsets(0, np.zeros(n), nan, nan, nan, held=True, note="no shear yet")
        self.deviation, self.deviation_sd = nan.copy(), nan.copy()
        self.notes: list[str] = []

    def shear(self, p_f: np.ndarray, sd_x: np.ndarray, healthy: bool = True, label: str = "") -> ShearOffsets:
        """The offsets for the next shear from one straight cut's path (p_f (K, 3) in F in time order, sd_x (K,) its
        one-sigma along x) from an estimator whose health is `healthy`; `label` names the shear in notes."""
        cfg = self.cfg
        y = p_f[np.isfinite(p_f[:, 0]), 1]
        creep = 0.0
        if y.size and cfg.path_ends_m is not None:
            creep = 0.5 * ((y.min() - cfg.path_ends_m[0]) + (y.max() - cfg.path_ends_m[1]))
        y_st = cfg.station_y_m + creep
        path_x, sd = path_at_shields(p_f, sd_x, y_st, cfg.spacing_m)
        inside = valid = np.zeros(y_st.size, bool)
        extent = 0.0
        if y.size:
            inside = (y_st >= y.min() + cfg.spacing_m / 2) & (y_st <= y.max() - cfg.spacing_m / 2)
            inside &= np.abs(y_st - y[0]) > cfg.end_zone_m
            valid = inside & np.isfinite(path_x)
            extent = (y.max() - y.min()) / (y_st[-1] - y_st[0])
        if not healthy:
            held = "the estimator lost track (health monitor)"
        elif extent < cfg.min_coverage or valid.sum() < max(3.0, cfg.min_coverage * inside.sum()):
            held = (f"not a full shear (the path spans {extent:.0%} of the face, {int(valid.sum())} of "
                    f"{int(inside.sum())} shields in its reach covered)")
        else:
            held = ""
        line = np.full(y_st.size, np.nan)
        if valid.any():
            line[valid] = (rail_line(path_x, valid, y_st, cfg.shoe_spacing_m, cfg.path_model) if cfg.shoe_spacing_m > 0
                           else path_x)[valid]
        if held:
            note = f"face alignment {label}: {held}: offsets of sequence {self.last.sequence} held"
            self.notes.append(note)
            self.last = ShearOffsets(self.last.sequence, self.last.offsets_m, self.last.sd_m, line,
                                     self.last.target_x_m, held=True, note=note, creep_m=creep)
            return self.last
        target = self._target(line[valid], y_st[valid], y_st)
        keep = 1.0 - cfg.gain
        self.deviation = np.where(valid, target - line, keep * self.deviation)
        self.deviation_sd = np.where(valid, sd, self.deviation_sd)
        offsets = solve_offsets(cfg.gain * np.nan_to_num(self.deviation), cfg)
        self.last = ShearOffsets(self.last.sequence + 1, offsets, cfg.gain * self.deviation_sd, line, target,
                                 held=False, creep_m=creep)
        return self.last

    def _target(self, x: np.ndarray, y: np.ndarray, y_st: np.ndarray) -> np.ndarray:
        """The target line at every shield (at y_st) from the valid part of the face line (x at y)."""
        cfg = self.cfg
        slope = float(np.polyfit(y, x, 1)[0])
        if cfg.planned_slope is not None:
            turn = np.tan(cfg.max_turn_rad)
            slope += float(np.clip(cfg.planned_slope - slope, -turn, turn))
        return x.mean() + slope * (y_st - y.mean())
