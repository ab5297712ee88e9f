"""Position fixes of a segment for the shearer filters: the surveyed face ends, and the CPOEM points of the
last straight cut (001 eqs. 6, 21-22; estimators.shearer.cpoem) moved by the push-ram advance, which 004's rail
kinematics model uses with a point per chute; and the points a pass records for the next one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.io.log import Log
from estimators.kalman import error_state as es
from estimators.nav.rotations import quat_to_mat
from estimators.shearer.config import Config
from estimators.shearer.cpoem import (
    Points,
    crossings,
    predict_fixes,
    record,
)
from estimators.shearer.face_line import fit_face_line
from estimators.shearer.prepare import Prepared
from estimators.shearer.solution import body_llh


@dataclass
class Fixes:
    """Position fixes of a segment, in epoch order: epoch, lat/lon/h, ENU covariance, NIS gate, and the advance
    direction in n (unit; zero for a surveyed face end), along which a push-ram stroke moved a predicted point."""

    epoch: np.ndarray
    llh: np.ndarray
    r: np.ndarray
    gate: np.ndarray
    advance: np.ndarray

    @classmethod
    def empty(cls) -> Fixes:
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0), np.zeros((0, 3)))

    def take(self, keep: np.ndarray) -> Fixes:
        """The fixes selected by `keep` (a mask or indices)."""
        return Fixes(self.epoch[keep], self.llh[keep], self.r[keep], self.gate[keep], self.advance[keep])


def fixes_for(prep: Prepared, cfg: Config, log: Log, a: int, b: int, points: Points | None,
              notes: list[str], face_ends: bool = True) -> Fixes:
    """Position fixes of epochs (a, b]: surveyed face ends (trusted: never gated; with `face_ends`), then CPOEM
    points crossed on a straight cut (gated at cfg.fix_gate)."""
    sel = np.flatnonzero((prep.survey_epochs > a) & (prep.survey_epochs <= b) & face_ends)
    j = list(prep.survey_epochs[sel])
    llh = [log.survey_llh[1 + k] for k in sel]
    r = [np.diag([log.survey_sd[1 + k, 0] ** 2] * 2 + [log.survey_sd[1 + k, 1] ** 2]) for k in sel]
    gate = [np.inf] * len(j)
    advance = [np.zeros(3)] * len(j)
    if points is not None and points.u.size and prep.rams is not None:
        u = prep.odo - prep.odo0  # of the epochs held
        for first, last in prep.cuts:
            if first > b or last <= a:
                continue
            lo, hi = max(first - 1, a), min(last, b)
            epochs, marks = crossings(u, points.spacing, prep.held(lo), prep.held(hi))
            fj, fllh, fr, skipped, fadv = predict_fixes(points, u, prep.t_kf, epochs, marks, prep.rams,
                                                        cfg.advance_sd, cfg.path_sd)
            j += list(fj + prep.first_epoch)
            llh += list(fllh)
            r += list(fr)
            gate += [cfg.fix_gate] * fj.size
            advance += list(fadv)
            if skipped.size:
                notes.append(f"CPOEM: no push-ram stroke at u = {', '.join(f'{v:.1f}' for v in skipped)} m "
                             f"(t {prep.t_kf[prep.held(lo)]:.0f}-{prep.t_kf[prep.held(hi)]:.0f} s): points skipped")
    if not j:
        return Fixes.empty()
    order = np.argsort(j, kind="stable")
    return Fixes(np.array(j, np.int64), np.array(llh), np.array(r), np.array(gate), np.array(advance)).take(order)


def face_survey_points(log: Log, prep: Prepared, spacing: float | None = None) -> Points:
    """The installed face line (FACE_SURVEY) as CPOEM points of the first cut at the survey's step (`spacing`; None:
    the median step of its face coordinates), smoothed by a local quadratic fit
    along the face (estimators.shearer.face_line: the survey's independent point errors averaged over a window its
    noise and the line's undulation choose, with tricube weights), with the fit's covariance, and the line's own
    frame at each point (`line_frames`: y along the fitted line, x level and square to it), in which a fix's
    along-face sigma lies."""
    if log.face_u.size == 0 or not prep.cuts:
        return Points.empty()
    first, last = prep.cuts[0]
    # The odometer counts the first cut this way:
    sign = 1.0 if prep.odo[prep.held(last)] >= prep.odo[prep.held(first - 1)] else -1.0
    order = np.argsort(log.face_u, kind="stable")
    u = sign * log.face_u[order]
    line = fit_face_line(log.face_llh[order], log.face_u[order], log.face_sd[order])
    c_nb = line_frames(sign * line.direction, quat_to_mat(prep.nav0[es.QUAT])[:, 0])
    sd_h, sd_v = log.face_sd[order, 0], log.face_sd[order, 1]
    cov = np.zeros((u.size, 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = line.gain[:, None] * np.column_stack([sd_h ** 2, sd_h ** 2, sd_v ** 2])
    if spacing is None:  # the survey's own step (one point has none, and gives no crossing)
        spacing = float(np.median(np.diff(log.face_u[order]))) if u.size >= 2 else np.nan
    return Points(u, np.full(u.size, prep.t_kf[prep.held(0)]), line.llh(), cov, c_nb, spacing)


def line_frames(direction: np.ndarray, x_n: np.ndarray) -> np.ndarray:
    """Body-like frames (K, 3, 3) along a line, C_b^n with y along `direction` (K, 3; d enu / d u in the sense of
    travel), x square to it and level, on the side of x_n (the start attitude's body x, towards the coal wall),
    z = x cross y. A point without a direction (a one-point line) takes y level and square to x_n."""
    y = np.where(np.isfinite(direction), direction, np.array([-x_n[1], x_n[0], 0.0]))
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    x = np.column_stack([y[:, 1], -y[:, 0], np.zeros(len(y))])
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    x *= np.where(x @ x_n >= 0, 1.0, -1.0)[:, None]
    return np.stack([x, y, np.cross(x, y)], axis=2)


def segment_points(prep: Prepared, cfg: Config, a: int, b: int, nav: np.ndarray, cov_enu: np.ndarray) -> Points:
    """CPOEM points of the straight cut inside epochs [a, b] from navigation rows nav and position covariances
    cov_enu (3, 3) (epochs a..b), from the pass's rows alone."""
    u = prep.odo[prep.span(a, b)] - prep.odo0
    for first, last in prep.cuts:
        if first > a and last <= b:
            return record(u, prep.t_kf[prep.span(a, b)], body_llh(nav, np.asarray(cfg.lever_arm_m, float)), cov_enu,
                          quat_to_mat(nav[:, es.QUAT]), cfg.cpoem_spacing_m, first - 1 - a, last - a)
    return Points.empty()
