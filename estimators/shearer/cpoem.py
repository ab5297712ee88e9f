"""Closed-path optimal estimation model (CPOEM, 001 section 2.2): position fixes for the next cutting cycle.

The shearer cuts the same face every cycle, moved towards the coal wall by the advance d (001 Fig. 3). Points
every Delta metres of face coordinate u (the odometer's signed travel from the start) are recorded when the
shearer crosses them on a straight cut, from the filter (or, better, the RTS-smoothed pass); on the next
straight cut, when the shearer crosses u_i again, the recorded point moved by the advance of the pans there is a
position fix (001 eq. 6, with C of eq. 7 turning the ENU increment into latitude, longitude, height):

    p_i,j+1 = p_i,j + C C_b^n C_m^b [d, 0, 0]^T

The fix carries no information along the face (ALONG_FACE_SD): the point's face coordinate is the odometer's
count on the earlier pass, and the two passes' path lengths to the same place on the face part by the diagonal
entry of every cut-out (a 0.8 m web over a 15 m snake adds 2.6 cm, with the sign of the direction of travel).
The point is moved square to the face line and along the floor (`advance_direction`), as the supports' rams push
the pans: not along the shearer's body x, which the diagonal entry turns, but with eq. 6's rise of the floor in the
advance direction (C_b^n's tilt across the face), which the pass's mean attitude gives; a horizontal advance held
every fix at the last pass's height, and on a 1 deg floor the chain fell 14 mm behind the face every 0.8 m shear.

The advance comes from the push-ram stroke sensors of the supports on either side of the point (interpolated
along the face): between two passes each pan is pushed once, so the ram of a support shows one stroke of the
web, in one or several partial strokes, whatever the order of push and support advance
(`ram_stroke`). A point without a valid stroke on both neighbouring supports (dropout, missing support) is
skipped and reported, never guessed; a point beyond the outermost supports (the face ends, half a support
spacing) has one neighbour only and is not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.faults.ram_levels import (
    change_sigma,
    drop_levels,
    level_tolerance,
    side_level,
    swings,
)
from estimators.nav import earth


@dataclass
class Points:
    """Recorded CPOEM points of the last straight cut (one row per face coordinate u_i = i * spacing)."""

    u: np.ndarray  # (P,) face coordinate [m]
    t: np.ndarray  # (P,) time the shearer crossed the point
    llh: np.ndarray  # (P, 3) body-point latitude, longitude, height
    cov: np.ndarray  # (P, 3, 3) ENU covariance of the point [m^2]
    c_nb: np.ndarray  # (P, 3, 3) attitude C_b^n at the point (body z: the normal of the floor under it)
    spacing: float  # the step of u, whose multiples the points sit at and a pass's crossings are found at [m]

    @classmethod
    def empty(cls) -> Points:
        return cls(np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3, 3)), np.nan)

    def take(self, keep: np.ndarray) -> Points:
        """The points selected by `keep` (a mask or indices)."""
        return Points(self.u[keep], self.t[keep], self.llh[keep], self.cov[keep], self.c_nb[keep], self.spacing)


def at_spacing(points: Points, spacing: float | None = None) -> Points:
    """The points at the face coordinates that are multiples of `spacing` (None: their own, Points.spacing) within
    their span, each interpolated linearly in u between its two neighbours (position, time and covariance; the
    nearer one's attitude), as CPOEM points of that spacing (Points.spacing). A line surveyed on a regular grid (the
    face survey, a point per chute) read at its own step gives its own points; read at another step, the chords of a
    curved line and the fixes that share a surveyed point move the filter (tests/estimators/shearer/
    test_independent_trajectories.py, az45_eq: the odometer scale off by 1.1e-4 at 2 m from a 1.75 m survey, 7e-6
    at 1.75 m)."""
    if points.u.size < 2:
        return points
    p = points.take(np.argsort(points.u, kind="stable"))
    spacing = p.spacing if spacing is None else spacing
    u = np.arange(np.ceil(p.u[0] / spacing), np.floor(p.u[-1] / spacing) + 1) * spacing
    k = np.clip(np.searchsorted(p.u, u, side="right") - 1, 0, p.u.size - 2)
    w = (u - p.u[k]) / (p.u[k + 1] - p.u[k])

    def lerp(a: np.ndarray) -> np.ndarray:
        wk = w.reshape(-1, *([1] * (a.ndim - 1)))
        return a[k] + wk * (a[k + 1] - a[k])

    return Points(u, lerp(p.t), lerp(p.llh), lerp(p.cov), p.c_nb[np.where(w < 0.5, k, k + 1)], spacing)


def crossings(u: np.ndarray, spacing: float, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """Epochs j in (lo, hi] where the face coordinate crosses a multiple of `spacing`: (j, crossed u_i).

    The crossing lies between epochs j - 1 and j (u_i between u[j-1] and u[j], first crossing per point)."""
    seg = u[lo:hi + 1]
    cell = np.floor(seg / spacing)
    jumps = np.flatnonzero(cell[1:] != cell[:-1])
    epochs, marks = [], []
    for k in jumps:
        a, b = cell[k], cell[k + 1]
        # Moving up past (a+1)*spacing ..., or down past a*spacing ...
        pts = np.arange(a + 1, b + 1) if b > a else np.arange(a, b, -1)
        epochs.append(np.full(pts.size, lo + k + 1))
        marks.append(pts * spacing)
    if not epochs:
        return np.zeros(0, int), np.zeros(0)
    j, m = np.concatenate(epochs), np.concatenate(marks)
    _, first = np.unique(m, return_index=True)
    order = np.sort(first)
    return j[order], m[order]


def record(u: np.ndarray, t: np.ndarray, llh: np.ndarray, cov_enu: np.ndarray, c_nb: np.ndarray,
           spacing: float, lo: int, hi: int) -> Points:
    """Points crossed between epochs lo and hi, interpolated linearly between the two epochs around each."""
    j, marks = crossings(u, spacing, lo, hi)
    du = u[j] - u[j - 1]
    w = np.where(np.abs(du) > 0, (marks - u[j - 1]) / np.where(du == 0, 1, du), 1.0)[:, None]
    return Points(marks, t[j - 1] + w[:, 0] * (t[j] - t[j - 1]), llh[j - 1] + w * (llh[j] - llh[j - 1]),
                  cov_enu[j], c_nb[j], spacing)


ALONG_FACE_SD = 1e3
"""One-sigma [m] along the face of a fix from an earlier pass's point: none of its information is along the face.
Held at the 5 cm a cut-out's path length suggests, each pass kept the last one's along-face error, which the first
cut makes (seed004 trial 5: 0.2-0.3 m east rms in cycles 2-5 from a first cut's 1.3 m; 0.03-0.06 m without), and
the odometer scale followed the cut-outs' path length (+6e-4 to +1.3e-3 on error-free independent trajectories,
tests/estimators/shearer/test_independent_trajectories.py). Along the face the shearer is placed by the odometer,
its scale calibrated by the face-end fixes of every cut."""


RAM_WINDOW = 3
"""Readings in the running median that cleans a noisy push-ram record before its drops are found (a precise
sensor, below 1 mm of noise, is used as it reads: a fast end push may leave a single reading at the top)."""
DROP_SIGMAS = 10.0
"""Down-swing of the cleaned reading, in its noise sigmas, that is a drop: the noise over the thousands of
readings of a pass spans about 8 sigma, a support's advance is a stroke."""
NOISY_LEVEL_RUN = 10
"""Fewest readings of a level of a noisy sensor (1 mm or more of noise): a last step of a push shorter than that
cannot be told from neighbouring readings a few sigma off (seed004 trial 3, 0.02 m sensor: 2.303, 2.266 and
2.238 m by a drop from a 2.20 m plateau made a 4 cm step of 5 readings); the twin's snake holds each step 37 s."""
RAMP_SIGMAS = 3.0
"""A reading this many noise sigmas off the level on its side of a drop lies on the drop's ramp."""
RAM_LEVEL_SAMPLES = 60
"""Readings next to an event whose median is a level of the stroke measurement (a minute at 1 Hz; the
level-change test cuts a shorter plateau)."""
RAM_TOP_SAMPLES = 30
"""Readings before a drop whose median is the level the pan was pushed to (half a minute at 1 Hz). The last step
of a snake push can be a few millimetres, always upward, below what the level-change test resolves on a noisy
sensor, so a minute of readings mixes in the step before and reads low: with 0.02 m of noise and an 8 mm last step
37 s before the advance, 3.2 mm short per stroke from 60 readings, 0.0 mm from 30 (tests/estimators/shearer/test_cpoem.py); on
seed004 against the truth's ram and support advance, -3.9 and -2.8 mm, the spread 10.4 and 10.8 mm."""


def ram_stroke(t: np.ndarray, ext: np.ndarray, valid: np.ndarray, t0: float, t1: float, noise_sd: float) -> float:
    """The pan's advance at one support between t0 and t1: how far its ram extended (NaN when fewer than
    RAM_WINDOW valid readings).

    The ram extends while the support pushes the pan (in one or several partial strokes as the snake forms, or
    in one stroke followed at once by the support's advance at the face end) and drops by about a stroke while
    the support pulls itself up to the pan; only the extensions move the pan. So the advance is the net change of
    the reading plus every drop:

        d = (level at t1 - level at t0) + sum over drops (level before - level after).

    Each level is the plateau next to its event (estimators.faults.ram_levels: readings within 6 sigma, at least 5 mm,
    up to RAM_LEVEL_SAMPLES of them (RAM_TOP_SAMPLES before a drop), cut at a level change; of a noisy sensor at
    least NOISY_LEVEL_RUN readings, so that outliers next to a drop are not taken for a last step), so the last
    partial step of a push counts in full and the noise's extremes do not add up; a drop is a down-swing of
    DROP_SIGMAS sigmas (at least 5 mm) of the reading cleaned by a running median. A drop that noise makes anyway
    splits one plateau and adds about nothing."""
    sel = (t > t0) & (t <= t1) & (valid > 0) & np.isfinite(ext)
    r = ext[sel]
    if r.size < RAM_WINDOW:
        return np.nan
    tol, sigma = level_tolerance(noise_sd), change_sigma(noise_sd)
    min_run = 1
    if noise_sd < 1e-3:
        clean, threshold = r, tol
    else:
        min_run = NOISY_LEVEL_RUN
        half = RAM_WINDOW // 2
        pad = np.concatenate([np.full(half, r[0]), r, np.full(half, r[-1])])
        clean = np.median(np.lib.stride_tricks.sliding_window_view(pad, RAM_WINDOW), axis=1)
        threshold = DROP_SIGMAS * 1.25 * noise_sd / np.sqrt(RAM_WINDOW)
    start = side_level(r, 0, 1, tol, sigma, RAM_LEVEL_SAMPLES, min_run)[0]
    end = side_level(r, r.size - 1, -1, tol, sigma, RAM_LEVEL_SAMPLES, min_run)[0]
    drops = [drop_levels(r, lo, hi, tol, sigma, RAM_LEVEL_SAMPLES, RAMP_SIGMAS * sigma, min_run, RAM_TOP_SAMPLES)
             for lo, hi in swings(-clean, threshold)]
    return float(end - start + sum(row[2] - row[3] for row in drops))


@dataclass(frozen=True)
class RamLog:
    """Push-ram readings grouped per support, and where each support sits in face coordinates."""

    t: list[np.ndarray]
    ext: list[np.ndarray]
    valid: list[np.ndarray]
    u: np.ndarray  # (S,) face coordinate of each support [m]
    noise_sd: float  # one-sigma noise of a reading [m]

    @classmethod
    def from_rows(cls, t, support, ext, valid, support_u, noise_sd: float) -> RamLog:
        s = np.asarray(support)
        order = np.argsort(s, kind="stable")  # each support's rows in time order
        bounds = np.searchsorted(s[order], np.arange(len(support_u) + 1))
        groups = [order[lo:hi] for lo, hi in zip(bounds[:-1], bounds[1:])]
        return cls([t[g] for g in groups], [ext[g] for g in groups], [valid[g] for g in groups],
                   np.asarray(support_u, float), noise_sd)

    def advance(self, u: float, t0: float, t1: float) -> float:
        """Pan advance at face coordinate u between t0 and t1 from the two neighbouring supports (NaN if one
        of them has no stroke)."""
        k = int(np.clip(np.searchsorted(self.u, u) - 1, 0, self.u.size - 2))
        a = ram_stroke(self.t[k], self.ext[k], self.valid[k], t0, t1, self.noise_sd)
        b = ram_stroke(self.t[k + 1], self.ext[k + 1], self.valid[k + 1], t0, t1, self.noise_sd)
        w = float(np.clip((u - self.u[k]) / (self.u[k + 1] - self.u[k]), 0.0, 1.0))
        return (1 - w) * a + w * b


def advance_direction(points: Points) -> np.ndarray:
    """The direction the pans were pushed (ENU, unit): horizontally square to the face line, the least-squares line
    through the points' horizontal positions, towards the coal wall (the side of the points' body x); vertically
    along the floor, rising by the floor's slope s in that direction (the rams push the pans over the floor, and a
    ram's stroke is its length along it: the point moves d cos(atan s) across and d sin(atan s) up).

    Not the shearer's body x: in the diagonal entry of a cut-out it is turned by the snake (0.1 rad for a 0.8 m web
    over 15 m), and its height then takes a share of the seam's dip along the face. The slope is the floor's, seen
    by the machine sitting on the pans: each point's body z is the normal of the pans under it, and
    s = -(z_e h_e + z_n h_n) / z_u along the horizontal direction h, which no yaw of the machine on the floor and
    no tilt along the face changes; averaged over the pass, as the points' attitude errors and the floor's local
    variations along the face average out. Nothing else in a log sees it as well: the push-ram strokes are lengths,
    the surveyed face ends' heights (5 cm each) a slope only over tens of shears, and the passes' heights are what
    the chained fixes make of this slope.

    Error budget: an error delta of the pass's mean slope puts a point d delta off in height per shear, and the
    chain of passes keeps it, N d delta after N shears. The filter cannot part the tilt across the face from the
    accelerometer's bias across it (the machine never turns round), so delta is about that bias over g: on
    face_alignment (nav-004, 30 ug) the pass's mean was 0.12-0.16 mrad off the machine's true tilt, and the height
    error held at -47 +- 2 mm over 12 shears where the level direction lost 17 mm a shear; on default (the
    MTi-G-700's 3 mg) 4.0 and 2.4 mrad off, 3.2 mm a 0.8 m shear against the 7 mm of its 0.5 deg floor, and on a
    level floor, where the level direction was right, that much is added. The slope's variation along the face
    (0.5-0.65 mrad sd on face_alignment, the floor's undulation) is left out: 0.7-0.9 mm rms a shear along the
    face, where each point's own true tilt would leave 0.55-0.6 mm; a real floor's roughness at a shield's scale
    tilts single points further.
    A level face (every body z up) gives the horizontal direction exactly."""
    x_n = points.c_nb[:, :, 0].mean(axis=0)
    if points.u.size < 2:
        h = x_n[:2] / np.linalg.norm(x_n[:2])
    else:
        lat0, lon0, h0 = points.llh[0]
        enu = earth.lla_to_enu(points.llh[:, 0], points.llh[:, 1], points.llh[:, 2], lat0, lon0, h0)[:, :2]
        _, _, vt = np.linalg.svd(enu - enu.mean(axis=0), full_matrices=False)
        h = np.array([-vt[0, 1], vt[0, 0]])
        h = h if h @ x_n[:2] >= 0 else -h
    z_n = points.c_nb[:, :, 2]
    slope = float(np.mean(-(z_n[:, :2] @ h) / z_n[:, 2]))
    return np.append(h, slope) / np.hypot(1.0, slope)


def predict_fixes(points: Points, u: np.ndarray, t: np.ndarray, epochs: np.ndarray, marks: np.ndarray,
                  rams: RamLog, advance_sd: float,
                  path_sd: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fixes for the crossings (epochs, marks) of the current pass from the previous pass's points (001 eq. 6).

    The predicted point is moved along the face (body y at the point) by u[j] - u_i so that it refers to the
    epoch where it is applied, and by the pans' advance along `advance_direction` (square to the face line, up the
    floor's slope). R = point covariance + the change of the path between the passes, in the body axes at the point:
    advance_sd and path_sd across the face (x, tilted as the floor), ALONG_FACE_SD along it (y), path_sd vertically
    (z).
    Returns (epochs, llh (F, 3), R (F, 3, 3), skipped face coordinates, advance direction in n at each point
    (F, 3): the direction along which the ram stroke moved it, made square to the point's along-face axis so that a
    test of the innovation along it (rail_fix_update) sees none of the fix's along-face sigma)."""
    path_b = np.diag([advance_sd ** 2 + path_sd ** 2, ALONG_FACE_SD ** 2, path_sd ** 2])
    adv_n = advance_direction(points)
    idx = {round(v / 1e-6): k for k, v in enumerate(points.u)}
    out_j, out_llh, out_r, out_adv, skipped = [], [], [], [], []
    for j, m in zip(epochs, marks):
        k = idx.get(round(m / 1e-6))
        if k is None or not rams.u[0] <= m <= rams.u[-1]:
            continue
        d = rams.advance(m, points.t[k], t[j])
        if not np.isfinite(d):
            skipped.append(m)
            continue
        c = points.c_nb[k]
        shift = adv_n * d + c[:, 1] * (u[j] - m)
        lat, lon, h = points.llh[k]
        r_m, r_n = earth.radii(lat)
        out_j.append(j)
        out_llh.append([lat + shift[1] / (r_m + h), lon + shift[0] / ((r_n + h) * np.cos(lat)), h + shift[2]])
        out_r.append(points.cov[k] + c @ path_b @ c.T)
        across = adv_n - (adv_n @ c[:, 1]) * c[:, 1]  # square to the fix's loose axis, which R leaves at 1e3 m
        out_adv.append(across / np.linalg.norm(across))
    if not out_j:
        return np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.array(skipped), np.zeros((0, 3))
    return np.array(out_j, np.int64), np.array(out_llh), np.array(out_r), np.array(skipped), np.array(out_adv)
