"""Federated shearer positioning on a sensor log (kernel: estimators.shearer.federated_filter), run by
estimators.shearer.positioning.estimate:

* ``afkf``     003's adaptive federated filter: SINS/odometer and SINS/magnetometer sub-filters;
* ``ckf_mag``  003's centralized filter with the same measurements (its comparison baseline);
* ``fkf_rail`` 004's federated filter: SINS/odometer and SINS/rail-kinematics-model sub-filters, with the fault
               detectors of 004 section IV on the rail model's position fixes and isolation while a fault holds.

Magnetometer: the log's readings are calibrated (MagSettings: hard and soft iron of an earlier calibration, e.g.
estimators.nav.geomagnetic.fit_ellipsoid), saturated or non-finite ones dropped, and averaged over each filter epoch; the
geomagnetic reference (declination, dip, strength) is the World Magnetic Model at the surveyed start position on
MagSettings.date.

Rail kinematics model (004 section II, eqs. 5-8): the straight cut just finished, recorded every chute length
along the face from the global estimate, moved towards the coal wall by the advance the push rams of the
supports at each point measured since (estimators.shearer.cpoem), predicts where the shearer will run on the next cut;
each point is a position fix (004 eq. 9) when the shearer crosses it again, with the chute geometry between
supports (a rigid chute moves as the straight line between its neighbouring supports' strokes, eqs. 7-8).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from estimators.faults.detectors import DetectorConfig, chi2_threshold, fsprt_state
from estimators.io.logformat import FLAG_ISOLATED, FLAG_MAG
from estimators.nav.geomagnetic import (
    GeomagneticReference,
    geomagnetic_reference,
    yaw_h_phi,
    yaw_noise_variance,
)
from estimators.shearer import federated_filter as fk
from estimators.shearer import odometer_filter as kf
from estimators.shearer import positioning as sp
from estimators.shearer.cpoem import Points

ARM_FIXES = 3
"""The detectors judge the rail model from the fourth fix of each pass on: the first ones pull the filter onto the
rail, from the start stand's solution (a drift of a few decimetres over a long alignment stand) and after the end
zone and the return run (a few centimetres, several times the innovations' spread on the rail), and are not
faults. A fault flag raised earlier holds over them."""
CAP = 1.25
"""The fading SPRT's statistic is held at or below CAP * t_on: a fault of any size keeps the flag raised, and once
it has gone the statistic falls to t_off in ln(CAP t_on / t_off) / ln(1 / fading) clean fixes (3 at 12, 5, 0.6)."""
ALONG_FACE_SD = 1e3
"""One-sigma [m] along the face of a rail-model fix from an earlier pass's point: none of its information is along
the face. The point's along-face position is the filter's own of that pass, from the same odometer; taken at
cpoem's path_along_sd (0.05 m) it held each pass to the last one's along-face error, which the first cut makes
(seed004 trial 5: 0.2-0.3 m east rms in cycles 2-5 from a first cut's 1.3 m; 0.03-0.06 m without). Along the face
the shearer is placed by the odometer, its scale calibrated by the face-end fixes of every cut."""
STROKE_SD_PER_NOISE = 0.5
"""One-sigma of a measured stroke per unit of the ram reading noise (cfg.ram_noise_sd): each level of a stroke is
the median of 30-60 readings (estimators.shearer.cpoem.ram_stroke), 7.2 mm for 0.02 m readings; against the truth seed004's
strokes spread by 10.4-10.8 mm. Each pass measures its strokes anew, so the filter cannot share this error: it
floors the detectors' variance of every rail fix (at a 5 mm floor a lone 31 mm stroke error read as 5.6 sigma and
raised a fault-free alarm, seed004 trial 21)."""
DETECTORS = ("residual", "dual_state", "fsprt")
"""The detectors of 004 section IV in the order of federated_kf.DET_*: residual chi-square, dual-state
chi-square, fading SPRT."""


def mag_per_epoch(log: sp.Log, t_kf: np.ndarray, mag: sp.MagSettings) -> tuple[np.ndarray, np.ndarray, int]:
    """(mean calibrated reading over each epoch (t[j-1], t[j]] (K, 3), NaN where none; readings per epoch (K,);
    number of readings dropped as saturated or not finite)."""
    b = (log.mag_b - np.asarray(mag.hard_iron_t)) @ np.asarray(mag.soft_iron_correction).T
    usable = np.all(np.isfinite(b), axis=1) & np.all(np.abs(log.mag_b) < mag.saturation_t, axis=1)
    k = np.searchsorted(t_kf, log.mag_t[usable], side="left")
    inside = (k >= 1) & (k < t_kf.size)
    k, b = k[inside], b[usable][inside]
    count = np.bincount(k, minlength=t_kf.size)
    sums = np.column_stack([np.bincount(k, weights=b[:, i], minlength=t_kf.size) for i in range(3)])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = sums / count[:, None]
    mean[count == 0] = np.nan
    return mean, count, int(np.sum(~usable))


def mag_params(mag: sp.MagSettings, ref: GeomagneticReference, per_epoch: float) -> np.ndarray:
    """The M_* parameter vector of estimators.shearer.federated_filter. The window estimate of the yaw noise (003 section
    4.2) is floored at the nominal variance: the magnetic yaw error is mostly a slowly varying bias (calibration
    residual, motor field) that the innovations do not show, so the window only raises R (a disturbance)."""
    if mag.sharing not in ("trace", "inverse_trace"):
        raise sp.PositioningError(f"mag.sharing {mag.sharing!r}: use 'trace' (003) or 'inverse_trace'")
    white = yaw_noise_variance(ref, mag.noise_t) / max(per_epoch, 1.0)
    nominal = white + mag.extra_sigma ** 2
    out = np.zeros(fk.N_MAG_PARAMS)
    out[fk.M_DECLINATION] = ref.declination
    out[fk.M_H_PHI:fk.M_H_PHI + 3] = yaw_h_phi(ref.field_n)
    out[[fk.M_INTENSITY, fk.M_INCLINATION, fk.M_NORM_TOL, fk.M_DIP_TOL]] = (ref.intensity, ref.inclination,
                                                                             mag.norm_tol, mag.dip_tol)
    out[[fk.M_R_YAW, fk.M_R_MIN, fk.M_MIN_SAMPLES, fk.M_GATE]] = (nominal, nominal, mag.min_samples, mag.gate)
    out[[fk.M_CHECK, fk.M_ADAPT, fk.M_INVERSE_SHARING]] = (mag.field_check, 1.0, mag.sharing == "inverse_trace")
    return out


def detector_chi2(det: DetectorConfig) -> tuple[float, float]:
    """Thresholds of the residual and the dual-state chi-square tests at det.p_false_alarm."""
    return (chi2_threshold(fk.DET_DOF, det.p_false_alarm), chi2_threshold(fk.DUAL_DOF, det.p_false_alarm))


def detector_params(det: DetectorConfig, isolate_by: str | None) -> np.ndarray:
    """The D_* parameter vector of estimators.shearer.federated_filter."""
    if isolate_by is not None and isolate_by not in DETECTORS:
        raise sp.PositioningError(f"detector {isolate_by!r}: use one of {', '.join(DETECTORS)}")
    out = np.zeros(fk.N_DET_PARAMS)
    out[[fk.D_FADING, fk.D_T_ON, fk.D_T_OFF]] = (det.fading, det.t_on, det.t_off)
    out[fk.D_CHI2], out[fk.D_CHI2_DUAL] = detector_chi2(det)
    out[fk.D_ISOLATE_BY] = -1 if isolate_by is None else DETECTORS.index(isolate_by)
    out[fk.D_CAP] = CAP * det.t_on
    out[fk.D_ARM] = ARM_FIXES
    out[[fk.D_WINDOW, fk.D_SD_FLOOR]] = (det.window, det.sd_floor)
    return out


class _Run:
    """Storage of one federated run over all epochs."""

    def __init__(self, prep):
        n = prep.t_kf.size
        self.nav, self.cal = np.zeros((n, kf.N_NAV)), np.zeros((n, kf.N_CAL))
        self.nav[0], self.cal[0] = prep.nav0, prep.cal0
        self.sd = np.zeros((n, kf.N_STATES))
        self.flags, self.mag_flags = np.zeros(n, np.int32), np.zeros(n, np.int32)
        self.beta = np.full((n, fk.N_SUB), np.nan)
        self.r_yaw = np.zeros(n)
        self.innov = np.full(n, np.nan)
        self.delta = np.full((n, fk.N_SUB, 6), np.nan)
        self.fixes: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []  # epoch, llh, stats, applied


def _run(log: sp.Log, cfg: sp.Config, prep, federated: bool, use_mag: bool, rail: bool,
         isolate_by: str | None) -> sp.Solution:
    notes = list(prep.notes)
    if use_mag:
        if log.mag_t.size == 0:
            raise sp.PositioningError("mag: no magnetometer readings; the magnetometer filters need the mag stream")
        try:
            ref = geomagnetic_reference(*log.survey_llh[0], cfg.mag.date)
        except ValueError as err:
            raise sp.PositioningError(f"mag.date: {err}") from None
        mag_b, count, dropped = mag_per_epoch(log, prep.t_kf, cfg.mag)
        params_m = mag_params(cfg.mag, ref, float(np.median(count[count > 0])) if np.any(count > 0) else 1.0)
        if dropped:
            notes.append(f"mag: {dropped} readings saturated or not finite, left out")
    else:
        mag_b = np.full((prep.t_kf.size, 3), np.nan)
        params_m = np.zeros(fk.N_MAG_PARAMS)
    params_d = detector_params(cfg.detector, isolate_by)
    if rail and prep.rams is None:
        raise sp.PositioningError("pushram: the rail kinematics model needs the push-ram stream and the support "
                                  "positions along the face")
    rail_cfg = dataclasses.replace(cfg, cpoem_spacing_m=cfg.chute_length_m or cfg.cpoem_spacing_m,
                                   advance_sd=cfg.rail_advance_sd or cfg.advance_sd)
    run = _Run(prep)
    run.r_yaw[:] = params_m[fk.M_R_YAW]
    p0 = sp.initial_covariance(cfg, log, prep.nav0[kf.QUAT])
    p_sub, beta = fk.initial_covariances(p0, federated)
    nominal = np.zeros(kf.N_NOMINAL)
    r_buf = np.zeros((cfg.mag.window, 1, 1))
    counters = np.zeros(3, np.int64)
    det_buf = np.zeros((max(cfg.detector.window, 1), 2))
    fsprt = fsprt_state(fk.DET_DOF)
    isolated = np.zeros(1, np.int8)
    nav, cal = prep.nav0.copy(), prep.cal0.copy()
    q_psd, params = sp.process_noise_psd(cfg), sp.kf_params(cfg)
    points, direction = sp.face_survey_points(log, prep) if rail else (Points.empty(), np.zeros((0, 3)))
    mode = fk.FEDERATED if federated else fk.CENTRALIZED
    for a, b in prep.segments:
        counters[1] = 0  # rail fixes tested in this pass (ARM_FIXES)
        fixes, scale_h, var_floor = _rail_fixes(prep, rail_cfg, log, a, b, points, direction, notes) if rail \
            else (sp.Fixes.empty(), np.zeros((0, 3)), np.zeros(0))
        stats = np.full((fixes.epoch.size, 3), np.nan)
        applied = np.zeros(fixes.epoch.size, np.int8)
        fk.run_afkf(mode, a, b, prep.steps, prep.t_mech, prep.phi_b, prep.dv_b, prep.odo, prep.mode, mag_b,
                    fixes.epoch, fixes.llh, fixes.r, scale_h, fixes.advance, var_floor, ~np.isfinite(fixes.gate),
                    q_psd, params, params_m, params_d, nav, cal, p_sub, beta, nominal, r_buf, counters, fsprt,
                    isolated, det_buf, run.nav, run.cal, run.sd, run.flags, run.mag_flags, run.beta, run.r_yaw,
                    run.innov, run.delta, stats, applied)
        run.fixes.append((fixes.epoch, fixes.llh, stats, applied))
        if rail:
            cov = np.zeros((b - a + 1, 3, 3))
            cov[:, [0, 1, 2], [0, 1, 2]] = run.sd[a:b + 1, kf.DP] ** 2
            points = next_pass_points(sp.segment_points(prep, rail_cfg, a, b, run.nav[a:b + 1], cov),
                                      prep.t_kf[a:b + 1], run.flags[a:b + 1],
                                      prep.t_kf[fixes.epoch[np.isfinite(stats[:, fk.DET_FSPRT])]])
            direction = np.zeros((0, 3))
    run.sd[0] = np.sqrt(np.diag(p0))
    run.flags |= np.where(run.mag_flags & fk.MAG_USED, FLAG_MAG, 0).astype(np.int32)
    notes += _notes(prep, cfg, run)
    sol = sp.make_solution(prep, cfg, run.nav, run.sd, run.flags, run.cal, notes)
    sol.fusion = fusion_columns(prep.t_kf, run.beta, run.r_yaw, run.innov, run.mag_flags, run.delta)
    if rail:
        sol.detectors = detector_columns(prep, run)
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


def _rail_fixes(prep, cfg: sp.Config, log: sp.Log, a: int, b: int, points: Points, direction: np.ndarray,
                notes: list[str]) -> tuple[sp.Fixes, np.ndarray, np.ndarray]:
    """The rail kinematics model's fixes over epochs (a, b] (none within cfg.end_zone_m of a face end unless from
    the face survey, before any push; along the face at ALONG_FACE_SD unless from the face survey) with the
    surveyed face ends, and each fix's scale_h and var_floor (federated_kf._fix_update): for points of the face
    survey, which come with the line's `direction` d enu / d u at each point (K, 3; empty for points of an earlier
    pass), that direction times the odometer travel (zero for the others); var_floor, the error the filter does not
    share: the stroke's (STROKE_SD_PER_NOISE), or the smoothed survey point's variance along the advance direction
    where that is larger; zero for the surveyed face ends."""
    surveyed = direction.shape[0] > 0
    if not surveyed:
        cfg = dataclasses.replace(cfg, path_along_sd=ALONG_FACE_SD)
    fixes = sp.fixes_for(prep, cfg, log, a, b, points, notes)
    u = prep.odo - prep.odo[0]
    lo, hi = u.min() + cfg.end_zone_m, u.max() - cfg.end_zone_m
    keep = ((u[fixes.epoch] >= lo) & (u[fixes.epoch] <= hi)) | ~np.isfinite(fixes.gate) | surveyed
    fixes = fixes.take(keep)
    scale_h = np.zeros((fixes.epoch.size, 3))
    rail = np.isfinite(fixes.gate)
    var_floor = np.where(rail, (STROKE_SD_PER_NOISE * cfg.ram_noise_sd) ** 2, 0.0)
    if surveyed and points.u.size >= 2 and rail.any():
        # The direction comes from the survey itself: the fixes carry the ram strokes, and a faulty one bends them.
        order = np.argsort(points.u)
        u_fix = u[fixes.epoch[rail]]
        along = np.column_stack([np.interp(u_fix, points.u[order], direction[order, i]) for i in range(3)])
        scale_h[rail] = along * u_fix[:, None]
        across = points.c_bn[order, :, 0]  # the advance direction at each point (cpoem.predict_fixes)
        var_point = np.einsum("ki,kij,kj->k", across, points.cov[order], across)
        var_floor[rail] = np.maximum(var_floor[rail], np.interp(u_fix, points.u[order], var_point))
    return fixes, scale_h, var_floor


def _notes(prep, cfg: sp.Config, run: _Run) -> list[str]:
    notes = []
    disturbed = int(np.sum(run.mag_flags & fk.MAG_DISTURBED > 0))
    if disturbed:
        first = prep.t_kf[np.argmax(run.mag_flags & fk.MAG_DISTURBED > 0)]
        notes.append(f"mag: {disturbed} epochs ({disturbed / cfg.filter_rate_hz:.1f} s, first at t = {first:.1f} s) "
                     f"disturbed (field strength or dip off the model's), yaw updates left out")
    invalid = int(np.sum(run.mag_flags & fk.SUB_INVALID > 0))
    if invalid:
        notes.append(f"fusion: a sub-filter's covariance was unusable at {invalid} epochs (weight 0, restarted)")
    return notes


def run_mag(log: sp.Log, cfg: sp.Config, prep, federated: bool) -> sp.Solution:
    """003: the adaptive federated (federated=True) or centralized SINS/odometer/magnetometer filter."""
    return _run(log, cfg, prep, federated, use_mag=True, rail=False, isolate_by=None)


def run_rail(log: sp.Log, cfg: sp.Config, prep, isolate_by: str | None = "fsprt") -> sp.Solution:
    """004: the federated SINS/odometer + SINS/rail-kinematics-model filter; the rail model's fixes are left out
    while the `isolate_by` detector holds a fault (None: never)."""
    return _run(log, cfg, prep, True, use_mag=False, rail=True, isolate_by=isolate_by)


def fusion_columns(t, beta, r_yaw, innov, mag_flags, delta) -> dict[str, np.ndarray]:
    """ESTIMATE_FUSION columns (estimators.io.logformat). delta (K, 2, 6): x_i - x_g of position and attitude error;
    a sub-filter's position is the global one minus its position-error difference, its yaw the global one plus
    the difference of the attitude error about up."""
    out = {"t": t, "beta_odometer": beta[:, fk.SUB_ODOMETER], "beta_aiding": beta[:, fk.SUB_AIDING], "r_yaw": r_yaw,
           "yaw_innovation": innov, "mag_flags": mag_flags}
    for k, sub in ((fk.SUB_ODOMETER, "odometer"), (fk.SUB_AIDING, "aiding")):
        for i, a in enumerate("enu"):
            out[f"{sub}_d_pos_{a}"] = -delta[:, k, i]
        out[f"{sub}_d_yaw"] = delta[:, k, 5]
    return out


def detector_columns(prep, run: _Run) -> dict[str, np.ndarray]:
    """ESTIMATE_DETECTORS columns: per rail-model fix its time, predicted point, the three detector statistics
    and whether it was applied; with the isolation flag of its epoch."""
    epoch = np.concatenate([f[0] for f in run.fixes]).astype(np.int64)
    llh = np.concatenate([f[1] for f in run.fixes]).reshape(-1, 3)
    stats = np.concatenate([f[2] for f in run.fixes]).reshape(-1, 3)
    applied = np.concatenate([f[3] for f in run.fixes])
    return {"t": prep.t_kf[epoch], "lat": llh[:, 0], "lon": llh[:, 1], "h": llh[:, 2],
            **{f"{name}": stats[:, i] for i, name in enumerate(DETECTORS)}, "applied": applied.astype(np.int32),
            "isolated": ((run.flags[epoch] & FLAG_ISOLATED) > 0).astype(np.int32)}
