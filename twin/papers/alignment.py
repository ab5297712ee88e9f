"""000 section 5.3 and Table 1: fine alignment of a standing IMU by each filter on each grade, beside the paper.

A standing IMU at 000's site and heading (270 deg), initial attitude errors 3, 3, 5 deg, 200 Hz:
estimators.sins.fine_alignment.fine_align with each filter (EKF, UKF, optimized UKF) on each IMU grade named
(twin.config.imu_grades, errors drawn by twin.sensors.imu_errors); the series are the attitude errors and the
filter's one-sigma uncertainty ("sigma").
"""

from __future__ import annotations

import time

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_quat,
    mat_to_euler,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_mat,
    rotvec_to_quat,
)
from estimators.sins.fine_alignment import alignment_floors, fine_align
from twin.config.experiments import AlignmentExperiment, AlignmentParams
from twin.config.imu_grades import grade
from twin.papers.sins_results import DEG, ExperimentResult, Series, header, row
from twin.sensors.imu_errors import apply_imu_errors

PAPER_TABLE1 = {  # "Filtering Results of error angle" (units not stated in 000): error, variance per angle
    "units": "not stated in 000; copied as written",
    "ekf": {"error": [-0.510, 0.325, -18.478], "variance": [0.0103, 0.0056, 9.4679]},
    "ukf": {"error": [0.302, -0.253, 8.935], "variance": [0.0118, 0.0068, 7.6143]},
    "optimized_ukf": {"error": [-0.123, 0.102, -4.239], "variance": [0.0127, 0.0059, 4.8291]},
}


ALIGN_WINDOW_S = 10.0
"""Window of the mean attitude reported as a fine alignment's result [s]."""


def _fine_align(p: AlignmentParams, g, dtheta, dv, lat: float, h: float, q0, method: str):
    """The one call of estimators.sins.fine_alignment.fine_align (the grade's noise and bias priors)."""
    return fine_align(dtheta, dv, 1 / p.rate_hz, lat, q0, (g.gyro_arw, g.accel_vrw),
                      np.asarray(p.initial_error_deg) * DEG, method, h=h, gyro_bias_sigma=g.gyro_bias,
                      accel_bias_sigma=g.accel_bias, velocity_sigma=p.velocity_sigma_m_s, update_rate=p.update_hz,
                      gyro_bias_psd=g.gyro_bias_psd,
                      accel_bias_psd=g.accel_bias_psd)


def run_alignment(exp: AlignmentExperiment) -> ExperimentResult:
    """Per grade and filter: the final attitude errors and the filter's sigma, with their convergence."""
    p, site = exp.alignment, exp.site
    lat, h = site.lat_deg * DEG, site.height_m
    q_true = euler_to_quat(p.pitch_deg * DEG, p.roll_deg * DEG, p.yaw_deg * DEG)
    c_true = quat_to_mat(q_true)
    n = round(p.duration_s * p.rate_hz)
    w_b = quat_rotate(quat_conj(q_true), earth.earth_rate_n(lat))
    f_b = quat_rotate(quat_conj(q_true), np.array([0.0, 0.0, earth.normal_gravity(lat, h)]))
    q0 = quat_mul(rotvec_to_quat(-np.asarray(p.initial_error_deg) * DEG), q_true)
    ours, series, timing = {}, [], {}
    table = [(f"000 section 5.3 / Table 1: L = {site.lat_deg:g} deg, h = {h:g} m, yaw {p.yaw_deg:g} deg, initial "
             f"errors {', '.join(f'{e:g}' for e in p.initial_error_deg)} deg, {p.rate_hz:g} Hz, {p.duration_s:g} s "
             f"stationary, seed {exp.seed}"),
             "  000 Table 1 (units not stated):  error and variance of phi_E, phi_N, phi_U",
             header(["phi_E", "var", "phi_N", "var", "phi_U", "var"])]
    for m in p.methods:
        ref = PAPER_TABLE1[m]
        table.append(row(f"paper {m}", [x for pair in zip(ref["error"], ref["variance"]) for x in pair],
                          [".4f", ".4g"] * 3))
    for gname in p.grades:
        g = grade(gname)
        dtheta, dv, info = apply_imu_errors(np.tile(w_b / p.rate_hz, (n, 1)), np.tile(f_b / p.rate_hz, (n, 1)),
                                            1 / p.rate_hz, g, np.random.default_rng(exp.seed))
        # Effective biases (turn-on bias and non-orthogonality times what the sensors see) and the floors of an
        # ideal stationary alignment for this draw (estimators.sins.fine_alignment.alignment_floors).
        acc = info.accel_bias + (info.accel_matrix - np.eye(3)) @ f_b
        gyr = info.gyro_bias + (info.gyro_matrix - np.eye(3)) @ w_b
        acc_sigma = float(np.hypot(g.accel_bias, np.linalg.norm(f_b) * g.accel_nonorth))
        start = np.asarray(p.initial_error_deg) * DEG
        fl, _ = alignment_floors(c_true, acc, gyr, lat, acc_sigma, g.gyro_bias, h, arw=g.gyro_arw,
                                 seconds=p.duration_s, start_error=start, start_sigma=start)
        floors = {"level_deg": float(np.degrees(np.hypot(fl[0], fl[1]))), "heading_deg": float(np.degrees(abs(fl[2]))),
                  "phi_deg": np.degrees(fl).tolist()}
        ours[gname] = {"floors": floors}
        table += [(f"{gname}: floors of this draw: level {floors['level_deg']:.4f} deg, heading "
                   f"{floors['heading_deg']:.4f} deg; ours [deg, deg^2]: final error and variance (sigma^2) of phi_E, "
                   "phi_N, phi_U"),
                  header(["phi_E", "var", "phi_N", "var", "phi_U", "var", "time [s]"])]
        for m in p.methods:
            start = time.perf_counter()
            res = _fine_align(p, g, dtheta, dv, lat, h, q0, m)
            elapsed = time.perf_counter() - start
            # phi of the filter's convention (C_true = E(phi) C_est, estimators.sins.fine_alignment) at every update.
            phi = np.stack(mat_to_euler(c_true @ np.swapaxes(quat_to_mat(res.q_nb), -1, -2)), axis=-1)
            # The final estimate is the mean over the last ALIGN_WINDOW_S (the update-to-update tracking noise
            # removed, FineAlignment.attitude).
            d, phi_end = res.errors(q_true, window_s=ALIGN_WINDOW_S)
            err, var = np.degrees(phi_end), np.degrees(res.attitude_sigma[-1]) ** 2
            ours[gname][m] = {"error_deg": err.tolist(), "variance_deg2": var.tolist(),
                              "sigma_deg": np.sqrt(var).tolist(), "pitch_roll_yaw_error_deg": np.degrees(d).tolist()}
            timing[f"{gname}/{m}_s"] = elapsed
            series += [Series(f"{gname}/{m}", "attitude", "", res.t, phi),
                       Series(f"{gname}/{m}", "sigma", "", res.t, res.attitude_sigma)]
            table.append(row(f"ours {m}", [*[x for pair in zip(err, var) for x in pair], elapsed],
                              [".4f", ".4g"] * 3 + [".2f"]))
    paper = {k: v for k, v in PAPER_TABLE1.items() if k == "units" or k in p.methods}
    return ExperimentResult(exp.name, exp.experiment, ours, paper, table, series, timing)
