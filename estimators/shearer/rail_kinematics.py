"""004's rail kinematics model on a prepared log: the federated SINS/odometer + SINS/rail-kinematics-model filter
(``fkf_rail``; kernel estimators.shearer.federated_filter, run pass by pass by estimators.shearer.federated) with
the fault detectors of 004 section IV on the rail model's position fixes and its isolation while a fault holds.

Rail kinematics model (004 section II, eqs. 5-8): the straight cut just finished, recorded every chute length
along the face from the global estimate, moved towards the coal wall and along the floor by the advance the push
rams of the supports at each point measured since (estimators.shearer.cpoem.advance_direction), predicts where the
shearer will run on the next cut; each point is a position fix (004 eq. 9) when the shearer crosses it again, with
the chute geometry between supports (a rigid chute moves as the straight line between its neighbouring supports'
strokes, eqs. 7-8). The first cut's points come from the face survey
(estimators.shearer.position_fixes.face_survey_points).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from estimators.faults.detectors import DetectorConfig, chi2_threshold
from estimators.io.log import Log
from estimators.io.logformat import FLAG_ISOLATED
from estimators.kalman import error_state as es
from estimators.shearer import federated_filter as fk
from estimators.shearer import rail_fix_update as rf
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.cpoem import Points, advance_direction
from estimators.shearer.federated import FederatedRun, PassFixes
from estimators.shearer.position_fixes import (
    face_survey_points,
    fixes_for,
    segment_points,
)
from estimators.shearer.prepare import Prepared
from estimators.shearer.solution import Solution

ARM_FIXES = 3
"""The detectors judge the rail model from the fourth fix of each pass on: the first ones pull the filter onto the
rail, from the start stand's solution (a drift of a few decimetres over a long alignment stand) and after the end
zone and the return run (a few centimetres, several times the innovations' spread on the rail), and are not
faults. A fault flag raised earlier holds over them."""
CAP = 1.25
"""The fading SPRT's statistic is held at or below CAP * t_on: a fault of any size keeps the flag raised, and once
it has gone the statistic falls to t_off in ln(CAP t_on / t_off) / ln(1 / fading) clean fixes (3 at 12, 5, 0.6)."""
STROKE_SD_PER_NOISE = 0.5
"""One-sigma of a measured stroke per unit of the ram reading noise (cfg.ram_noise_sd): each level of a stroke is
the median of 30-60 readings (estimators.shearer.cpoem.ram_stroke), 7.2 mm for 0.02 m readings; against the truth
seed004's strokes spread by 10.4-10.8 mm. Each pass measures its strokes anew, so the filter cannot share this
error: it floors the detectors' variance of every rail fix (at a 5 mm floor a lone 31 mm stroke error read as 5.6
sigma and raised a fault-free alarm, seed004 trial 21)."""
DETECTORS = ("residual", "dual_state", "fsprt")
"""The detectors of 004 section IV in the order of estimators.shearer.rail_fix_update.DET_*: residual chi-square,
dual-state chi-square, fading SPRT."""


def detector_chi2(det: DetectorConfig) -> tuple[float, float]:
    """Thresholds of the residual and the dual-state chi-square tests at det.p_false_alarm."""
    return (chi2_threshold(rf.DET_DOF, det.p_false_alarm), chi2_threshold(rf.DUAL_DOF, det.p_false_alarm))


def detector_params(det: DetectorConfig, isolate_by: str | None) -> np.ndarray:
    """The D_* parameter vector of estimators.shearer.rail_fix_update."""
    if isolate_by is not None and isolate_by not in DETECTORS:
        raise PositioningError(f"detector {isolate_by!r}: use one of {', '.join(DETECTORS)}")
    out = np.zeros(rf.N_DET_PARAMS)
    out[[rf.D_FADING, rf.D_T_ON, rf.D_T_OFF]] = (det.fading, det.t_on, det.t_off)
    out[rf.D_CHI2], out[rf.D_CHI2_DUAL] = detector_chi2(det)
    out[rf.D_ISOLATE_BY] = -1 if isolate_by is None else DETECTORS.index(isolate_by)
    out[rf.D_CAP] = CAP * det.t_on
    out[rf.D_ARM] = ARM_FIXES
    out[[rf.D_WINDOW, rf.D_SD_FLOOR]] = (det.window, det.sd_floor)
    return out


class RailPasses:
    """004's filter a pass at a time, its state carried from pass to pass: `run(prep, log, a, b)` filters epochs
    (a, b] (a the end of the last pass run) with the rail model's fixes from the last pass's points (the face
    survey's for the first pass) and returns the kernel's output over epochs a..b (fk.EpochOutput); the pass's
    estimate gives the next pass its points. run_rail runs it over a whole log (`whole`: the output of every epoch
    gathered for the Solution); an online run pass by pass as the passes end (estimators.shearer.online)."""

    def __init__(self, log: Log, cfg: Config, prep: Prepared, isolate_by: str | None = "fsprt", whole: bool = True):
        det_params = detector_params(cfg.detector, isolate_by)
        if prep.rams is None:
            raise PositioningError("pushram: the rail kinematics model needs the push-ram stream and the support "
                                   "positions along the face")
        self.rail_cfg = dataclasses.replace(cfg, cpoem_spacing_m=cfg.chute_length_m or cfg.cpoem_spacing_m,
                                            advance_sd=cfg.rail_advance_sd or cfg.advance_sd)
        self.notes = list(prep.notes)
        self.filter = FederatedRun(log, cfg, prep, True, det_params=det_params, whole=whole)
        self.points, self.surveyed = face_survey_points(log, prep, self.rail_cfg.cpoem_spacing_m), True

    def run(self, prep: Prepared, log: Log, a: int, b: int) -> fk.EpochOutput:
        fixes, var_floor = _rail_fixes(prep, self.rail_cfg, log, a, b, self.points, self.surveyed, self.notes)
        stats, out = self.filter.run_pass(a, b, (fixes, var_floor))
        cov = np.zeros((b - a + 1, 3, 3))
        cov[:, [0, 1, 2], [0, 1, 2]] = out.sd[:, es.DP] ** 2
        self.points = next_pass_points(segment_points(prep, self.rail_cfg, a, b, out.nav, cov),
                                       prep.t_kf[prep.span(a, b)], out.flags,
                                       prep.t_kf[prep.held(fixes.epoch[np.isfinite(stats[:, rf.DET_FSPRT])])])
        self.surveyed = False
        return out

    def pass_solution(self, prep: Prepared, a: int, out: fk.EpochOutput) -> Solution:
        """The Solution rows of the pass just run over epochs (a, b] (its output `out`), with their fusion columns
        and the pass's rail fixes as detector rows: run_rail's rows over the pass."""
        sol = self.filter.rows(prep.t_kf[prep.span(a + 1, a + out.nav.shape[0] - 1)],
                               fk.EpochOutput(*(f[1:] for f in out)), [])
        epoch, llh, stats, applied = self.filter.pass_fixes
        sol.detectors = detector_rows(prep, epoch, llh, stats, applied, out.flags[epoch - a])
        return sol

    def first_row(self, prep: Prepared) -> Solution:
        """Epoch 0's row as run_rail gives it (no rail fix at it)."""
        sol = self.filter.rows(prep.t_kf[prep.span(0, 0)], self.filter.first_row(), [])
        sol.detectors = detector_rows(prep, np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)),
                                      np.zeros(0, np.int8), np.zeros(0, np.int32))
        return sol

    def finish(self, prep: Prepared) -> list[str]:
        """The run's notes, with the fusion's (run_rail's)."""
        return self.notes + self.filter.notes()


def run_rail(log: Log, cfg: Config, prep: Prepared, isolate_by: str | None = "fsprt") -> Solution:
    """004: the federated SINS/odometer + SINS/rail-kinematics-model filter (RailPasses over the log's passes); the
    rail model's fixes are left out while the `isolate_by` detector holds a fault (None: never)."""
    passes = RailPasses(log, cfg, prep, isolate_by)
    for a, b in prep.segments:
        passes.run(prep, log, a, b)
    sol = passes.filter.solution(passes.notes)
    sol.detectors = detector_columns(prep, passes.filter)
    return sol


def next_pass_points(points: Points, t: np.ndarray, flags: np.ndarray, t_tested: np.ndarray) -> Points:
    """The points of a pass (epochs at t, filter flags) that give the next pass its fixes, t_tested the times of
    the pass's rail fixes the detectors tested. Left out: points recorded while the filter settles back onto the
    rail after the end zone (before the pass's detectors are armed, at its ARM_FIXES-th tested fix), which carry
    the drift it is shedding; and points recorded while the model was isolated, when the push-ram readings were
    held faulty: the strokes to the next pass would start from them."""
    if t_tested.size > ARM_FIXES:
        points = points.take(points.t >= t_tested[ARM_FIXES])
    held = (flags & FLAG_ISOLATED) > 0
    return points.take(~held[np.clip(np.searchsorted(t, points.t), 0, t.size - 1)])


def _rail_fixes(prep: Prepared, cfg: Config, log: Log, a: int, b: int, points: Points, surveyed: bool,
                notes: list[str]) -> PassFixes:
    """The rail kinematics model's fixes over epochs (a, b] (none within cfg.end_zone_m of a face end unless
    `surveyed`: the points are the face survey's, before any push) with the surveyed face ends, and each fix's
    var_floor (estimators.shearer.rail_fix_update), the error the filter does not share: the stroke's
    (STROKE_SD_PER_NOISE), or the smoothed survey point's variance along the advance direction where that is larger;
    zero for the surveyed face ends. Like every point's, a survey point's fix says nothing along the face
    (cpoem.ALONG_FACE_SD): the survey's face coordinate is a distance along the pans, the odometer's the path of
    the body point (on the twin's error-free north-south face the two part by +-1.8 cm as the machine pitches over
    the floor), and an odometer scale error moves the shearer and the point it is compared with alike, so the fix
    cannot see it; the along-face information it seemed to give was that registration noise, which walked the
    filter 13 cm along the face over the first cut at an along-face sigma of 0.44 m."""
    fixes = fixes_for(prep, cfg, log, a, b, points, notes)
    u = prep.odo[prep.held(fixes.epoch)] - prep.odo0  # at each fix
    lo, hi = prep.odo_min - prep.odo0 + cfg.end_zone_m, prep.odo_max - prep.odo0 - cfg.end_zone_m
    keep = ((u >= lo) & (u <= hi)) | ~np.isfinite(fixes.gate) | surveyed
    u = u[keep]
    fixes = fixes.take(keep)
    rail = np.isfinite(fixes.gate)
    var_floor = np.where(rail, (STROKE_SD_PER_NOISE * cfg.ram_noise_sd) ** 2, 0.0)
    if surveyed and points.u.size >= 2 and rail.any():
        # The direction comes from the survey itself: the fixes carry the ram strokes, and a faulty one bends them.
        order = np.argsort(points.u)
        u_fix = u[rail]
        across = advance_direction(points)  # as cpoem.predict_fixes moves the points
        var_point = np.einsum("i,kij,j->k", across, points.cov[order], across)
        var_floor[rail] = np.maximum(var_floor[rail], np.interp(u_fix, points.u[order], var_point))
    return fixes, var_floor


def detector_columns(prep: Prepared, run: FederatedRun) -> dict[str, np.ndarray]:
    """ESTIMATE_DETECTORS columns of a whole run (FederatedRun with `whole`): detector_rows of every pass's fixes."""
    epoch = np.concatenate([f[0] for f in run.fixes]).astype(np.int64)
    return detector_rows(prep, epoch, *(np.concatenate([f[k] for f in run.fixes]) for k in (1, 2, 3)),
                         run.out.flags[epoch])


def detector_rows(prep: Prepared, epoch: np.ndarray, llh: np.ndarray, stats: np.ndarray, applied: np.ndarray,
                  flags: np.ndarray) -> dict[str, np.ndarray]:
    """ESTIMATE_DETECTORS columns: per rail-model fix (at `epoch`) its time, predicted point, the three detector
    statistics and whether it was applied; with the isolation flag of its epoch (its filter `flags`)."""
    llh, stats = np.reshape(llh, (-1, 3)), np.reshape(stats, (-1, 3))
    return {"t": prep.t_kf[prep.held(epoch)], "lat": llh[:, 0], "lon": llh[:, 1], "h": llh[:, 2],
            **{f"{name}": stats[:, i] for i, name in enumerate(DETECTORS)},
            "applied": np.asarray(applied).astype(np.int32),
            "isolated": ((flags & FLAG_ISOLATED) > 0).astype(np.int32)}


def fsprt_alarms(detectors: dict[str, np.ndarray], t_on: float) -> np.ndarray:
    """Times of the tested fixes at which the FSPRT statistic crosses T1 from below and raises the isolation (the
    first fixes, before the detectors are armed, show the statistic but raise nothing: ARM_FIXES)."""
    tested = np.isfinite(detectors["fsprt"])
    above = detectors["fsprt"][tested] > t_on
    raised = above & ~np.concatenate([[False], above[:-1]]) & (detectors["isolated"][tested] > 0)
    return detectors["t"][tested][raised]
