"""SINS/odometer/magnetometer positioning of 003 on a sensor log: the adaptive federated filter (``afkf``) and the
centralized filter it is compared with (``ckf_mag``), run by estimators.shearer_positioning.estimate.

The log's magnetometer readings are calibrated (MagSettings: hard and soft iron of an earlier calibration, e.g.
estimators.magnetic.fit_ellipsoid), saturated or non-finite ones dropped, and averaged over each filter epoch; the
geomagnetic reference (declination, dip, strength) is the World Magnetic Model at the surveyed start position on
MagSettings.date. The kernel is estimators.federated_kf.
"""

from __future__ import annotations

import numpy as np

from estimators import federated_kf as fk
from estimators import shearer_kf as kf
from estimators import shearer_positioning as sp
from estimators.logformat import FLAG_MAG
from estimators.magnetic import (
    GeomagneticReference,
    geomagnetic_reference,
    yaw_h_phi,
    yaw_noise_variance,
)


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
    """The M_* parameter vector of estimators.federated_kf."""
    if mag.sharing not in ("trace", "inverse_trace"):
        raise sp.PositioningError(f"mag.sharing {mag.sharing!r}: use 'trace' (003) or 'inverse_trace'")
    white = yaw_noise_variance(ref, mag.noise_t) / max(per_epoch, 1.0)
    out = np.zeros(fk.N_MAG_PARAMS)
    out[fk.M_DECLINATION] = ref.declination
    out[fk.M_H_PHI:fk.M_H_PHI + 3] = yaw_h_phi(ref.field_n)
    out[[fk.M_INTENSITY, fk.M_INCLINATION, fk.M_NORM_TOL, fk.M_DIP_TOL]] = (ref.intensity, ref.inclination,
                                                                             mag.norm_tol, mag.dip_tol)
    nominal = white + mag.extra_sigma ** 2
    out[[fk.M_R_YAW, fk.M_R_MIN, fk.M_MIN_SAMPLES, fk.M_GATE]] = (nominal, nominal,
                                                                   mag.min_samples, mag.gate)
    out[[fk.M_CHECK, fk.M_ADAPT, fk.M_INVERSE_SHARING]] = (mag.field_check, 1.0, mag.sharing == "inverse_trace")
    return out


def run(log: sp.Log, cfg: sp.Config, prep, federated: bool) -> sp.Solution:
    """The federated (003 section 4) or centralized filter over the whole log; a Solution with its fusion columns."""
    name = "afkf" if federated else "ckf_mag"
    if log.mag_t.size == 0:
        raise sp.PositioningError(f"mag: no magnetometer readings; the {name} method needs the mag stream")
    lat, lon, h = log.survey_llh[0]
    try:
        ref = geomagnetic_reference(lat, lon, h, cfg.mag.date)
    except ValueError as err:
        raise sp.PositioningError(f"mag.date: {err}") from None
    mag_b, count, dropped = mag_per_epoch(log, prep.t_kf, cfg.mag)
    params = mag_params(cfg.mag, ref, float(np.median(count[count > 0])) if np.any(count > 0) else 1.0)
    n = prep.t_kf.size
    nav, cal = np.zeros((n, kf.N_NAV)), np.zeros((n, kf.N_CAL))
    nav[0], cal[0] = prep.nav0, prep.cal0
    sd = np.zeros((n, kf.N_STATES))
    flags, mag_flags = np.zeros(n, np.int32), np.zeros(n, np.int32)
    beta = np.full((n, fk.N_SUB), np.nan)
    r_yaw = np.full(n, params[fk.M_R_YAW])
    innov = np.full(n, np.nan)
    delta = np.full((n, fk.N_SUB, 6), np.nan)
    fk.run_afkf(fk.FEDERATED if federated else fk.CENTRALIZED, prep.steps, prep.t_mech, prep.phi_b, prep.dv_b,
                prep.odo, prep.mode, mag_b, sp._q_psd(cfg), sp.kf_params(cfg), params, cfg.mag.window,
                prep.nav0.copy(), prep.cal0.copy(), sp._p0(cfg, log), nav, cal, sd, flags, mag_flags, beta, r_yaw,
                innov, delta)
    flags |= np.where(mag_flags & fk.MAG_USED, FLAG_MAG, 0).astype(np.int32)
    notes = list(prep.notes)
    if dropped:
        notes.append(f"mag: {dropped} readings saturated or not finite, left out")
    disturbed = int(np.sum(mag_flags & fk.MAG_DISTURBED > 0))
    if disturbed:
        first = prep.t_kf[np.argmax(mag_flags & fk.MAG_DISTURBED > 0)]
        notes.append(f"mag: {disturbed} epochs ({disturbed / cfg.filter_rate_hz:.1f} s, first at t = {first:.1f} s) "
                     f"disturbed (field strength or dip off the model's), yaw updates left out")
    invalid = int(np.sum(mag_flags & fk.SUB_INVALID > 0))
    if invalid:
        notes.append(f"fusion: a sub-filter's covariance was unusable at {invalid} epochs (weight 0, restarted)")
    sol = sp._solution(prep, cfg, nav, sd, flags, cal, notes)
    sol.fusion = fusion_columns(prep.t_kf, beta, r_yaw, innov, mag_flags, delta)
    return sol


def fusion_columns(t, beta, r_yaw, innov, mag_flags, delta) -> dict[str, np.ndarray]:
    """ESTIMATE_FUSION columns (estimators.logformat). delta (K, 2, 6): x_i - x_g of position and attitude error;
    a sub-filter's position is the global one minus its position-error difference, its yaw the global one plus
    the difference of the attitude error about up."""
    out = {"t": t, "beta_odometer": beta[:, fk.SUB_ODOMETER], "beta_mag": beta[:, fk.SUB_MAG], "r_yaw": r_yaw,
           "yaw_innovation": innov, "mag_flags": mag_flags}
    for k, sub in ((fk.SUB_ODOMETER, "odometer"), (fk.SUB_MAG, "mag")):
        for i, a in enumerate("enu"):
            out[f"{sub}_d_pos_{a}"] = -delta[:, k, i]
        out[f"{sub}_d_yaw"] = delta[:, k, 5]
    return out
