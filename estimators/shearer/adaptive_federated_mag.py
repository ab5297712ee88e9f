"""003's SINS/odometer/magnetometer filters on a prepared log (kernel estimators.shearer.federated_filter, run
pass by pass by estimators.shearer.federated):

* ``afkf``     003's adaptive federated filter: SINS/odometer and SINS/magnetometer sub-filters, the yaw noise
               estimated from the innovations (003 section 4.2) and the magnetic disturbance test;
* ``ckf_mag``  003's centralized filter with the same measurements (its comparison baseline, 003 section 5.2).

The log's readings are calibrated (MagSettings: hard and soft iron of an earlier calibration, e.g.
estimators.nav.geomagnetic.fit_ellipsoid), saturated or non-finite ones dropped, and averaged over each filter
epoch; the geomagnetic reference (declination, dip, strength) is the World Magnetic Model at the surveyed start
position on MagSettings.date.
"""

from __future__ import annotations

import numpy as np

from estimators.io.log import Log
from estimators.nav.geomagnetic import (
    GeomagneticReference,
    geomagnetic_reference,
    yaw_h_phi,
    yaw_noise_variance,
)
from estimators.shearer import federated_filter as fk
from estimators.shearer.config import Config, MagSettings, PositioningError
from estimators.shearer.federated import FederatedRun
from estimators.shearer.prepare import Prepared
from estimators.shearer.solution import Solution


def mag_per_epoch(log: Log, t_kf: np.ndarray, mag: MagSettings) -> tuple[np.ndarray, np.ndarray, int]:
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


def mag_params(mag: MagSettings, ref: GeomagneticReference, per_epoch: float) -> np.ndarray:
    """The M_* parameter vector of estimators.shearer.federated_filter. The window estimate of the yaw noise (003
    section 4.2) is floored at the nominal variance: the magnetic yaw error is mostly a slowly varying bias
    (calibration residual, motor field) that the innovations do not show, so the window only raises R (a
    disturbance)."""
    if mag.sharing not in ("trace", "inverse_trace"):
        raise PositioningError(f"mag.sharing {mag.sharing!r}: use 'trace' (003) or 'inverse_trace'")
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


def run_mag(log: Log, cfg: Config, prep: Prepared, federated: bool) -> Solution:
    """003: the adaptive federated (federated=True) or centralized SINS/odometer/magnetometer filter."""
    if log.mag_t.size == 0:
        raise PositioningError("mag: no magnetometer readings; the magnetometer filters need the mag stream")
    try:
        ref = geomagnetic_reference(*log.survey_llh[0], cfg.mag.date)
    except ValueError as err:
        raise PositioningError(f"mag.date: {err}") from None
    mag_b, count, dropped = mag_per_epoch(log, prep.t_kf, cfg.mag)
    params_m = mag_params(cfg.mag, ref, float(np.median(count[count > 0])) if np.any(count > 0) else 1.0)
    notes = list(prep.notes)
    if dropped:
        notes.append(f"mag: {dropped} readings saturated or not finite, left out")
    run = FederatedRun(log, cfg, prep, federated, mag=(mag_b, params_m))
    for a, b in prep.segments:
        run.run_pass(a, b)
    return run.solution(notes)
