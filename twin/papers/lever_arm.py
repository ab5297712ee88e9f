"""000 section 6.4 and Tables 2-3: lever-arm compensation on the sway of eq. 54, beside the paper's figures.

The body's reference point rests at the site while it sways (twin.papers.motions.sway: pitch, roll, yaw 10 deg,
periods 6, 8, 10 s); the sensor sits at the lever arms r_p = [1, 1, 1] and [1.5, 1.5, 1] m. Part 1 mechanizes an
error-free sensor (twin.sensors.imu's exact increments) with and without the two-sample compensation
(estimators.sins.installation.compensate_lever_arm, eqs. 48-53); part 2 (`[closed_loop]`) runs the paper's own
setting as far as it is specified: the closed-loop fine alignment of estimators.sins.lever_arm_filter with
zero-velocity observations and the paper's sensor errors.
"""

from __future__ import annotations

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import mat_to_quat, quat_mul, rotvec_to_quat
from estimators.sins.installation import compensate_lever_arm
from estimators.sins.lever_arm_filter import AtRestSettings, align_at_rest
from estimators.sins.strapdown import mechanize
from twin.config.experiments import LeverArmExperiment
from twin.config.imu_grades import G0
from twin.papers.motions import sway
from twin.papers.sins_results import (
    DEG,
    ExperimentResult,
    Series,
    attitude_error,
    header,
    reduction_pct,
    row,
)
from twin.sensors.imu import sensor_increments
from twin.sensors.vibration import VibrationTones

PAPER_LEVER_ARM = {  # maximum attitude errors [deg] (E, N, U) and reductions [%] per lever arm
    (1.0, 1.0, 1.0): {"table": 2, "uncompensated_deg": [0.45, 0.25, 0.35], "compensated_deg": [0.12, 0.10, 0.05],
                      "reduction_pct": [73.3, 60.0, 85.7]},
    (1.5, 1.5, 1.0): {"table": 3, "uncompensated_deg": [0.90, 0.70, 0.70], "compensated_deg": [0.20, 0.15, 0.08],
                      "reduction_pct": [77.8, 78.6, 88.6]},
}


def _sway_increments(t: np.ndarray, w_ib: np.ndarray, f_b: np.ndarray, lever_arm_b) -> tuple[np.ndarray, ...]:
    """Exact increments of an error-free sensor at lever_arm_b on the swaying body (twin IMU, no vibration)."""
    still = VibrationTones(freq_hz=np.ones((1, 1)), ang_amp=np.zeros((1, 1, 3)), lin_amp=np.zeros((1, 1, 3)),
                           phase_ang=np.zeros((3, 1)), phase_lin=np.zeros((3, 1)))
    return sensor_increments(t, w_ib, f_b, np.zeros((t.size, 1)), still, np.asarray(lever_arm_b, float), np.eye(3))


def _closed_loop(exp: LeverArmExperiment, t, c, dth, dv, r_p, compensated: bool) -> tuple[np.ndarray, np.ndarray]:
    """000 section 6.4's setting: the closed-loop fine alignment (estimators.sins.lever_arm_filter) over the sway
    with the paper's sensor errors (constant bias and white noise on each sample), from the paper's initial
    attitude error. Uncompensated, the sensor's lever-arm velocity enters the zero-velocity observations and is
    taken for tilt. The paper gives no filter tuning; the observation noise is `velocity_sigma_m_s` and the
    absolute errors depend on it. Returns the update times and the attitude errors (E, N, U) [rad] after each
    update."""
    cl, site = exp.closed_loop, exp.site
    rng = np.random.default_rng(exp.seed)
    h = float(t[1] - t[0])
    gyro_bias, gyro_random = cl.gyro_bias_deg_h * DEG / 3600, cl.gyro_random_deg_h * DEG / 3600
    accel_bias, accel_random = cl.accel_bias_g * G0, cl.accel_random_g * G0
    phi0 = np.asarray(cl.initial_error_deg) * DEG
    dth = dth + gyro_bias * h + rng.normal(0, gyro_random * h, dth.shape)
    dv = dv + accel_bias * h + rng.normal(0, accel_random * h, dv.shape)
    dth[0] = dv[0] = 0.0
    if compensated:
        dv = compensate_lever_arm(dth, dv, r_p, h=h)
    q0 = quat_mul(rotvec_to_quat(-phi0), mat_to_quat(c[0]))  # C_est = (I - [phi x]) C_true
    settings = AtRestSettings(attitude_sigma=phi0, gyro_bias_sigma=gyro_bias, gyro_noise=gyro_random,
                              accel_bias_sigma=accel_bias, accel_noise=accel_random, update_hz=cl.update_hz,
                              velocity_sigma=cl.velocity_sigma_m_s)
    k, q_nb = align_at_rest(t, dth, dv, q0, site.lat_deg * DEG, site.lon_deg * DEG, site.height_m, settings)
    return t[k], attitude_error(mat_to_quat(c[k]), q_nb)


def _lever_arm_group(r_p) -> str:
    paper = PAPER_LEVER_ARM.get(tuple(float(x) for x in r_p))
    return f"table{paper['table']}" if paper else "r_p_" + "_".join(f"{x:g}" for x in r_p)


def run_lever_arm(exp: LeverArmExperiment) -> ExperimentResult:
    """Per lever arm: the maximum attitude errors (E, N, U) of the mechanization of an error-free sensor,
    uncompensated and compensated, and (closed_loop.enabled) those of the closed-loop fine alignment over its
    second half (the steady state the paper describes; the initial heading error would dominate otherwise).

    The paper's figures come from its fine-alignment filter, where the lever-arm acceleration is mistaken for
    tilt; in part 1 the sensor is error-free, so the attitude errors are those of the lever arm alone (through
    the velocity error and the transport rate): their size is not comparable with the paper's, the reductions
    are."""
    la, sw, site = exp.lever_arm, exp.sway, exp.site
    lat, lon, hgt = site.lat_deg * DEG, site.lon_deg * DEG, site.height_m
    t = np.arange(round(la.duration_s * la.rate_hz) + 1) / la.rate_hz
    c, w_ib, f_b = sway(t, np.asarray(sw.amplitude_deg) * DEG, sw.period_s, lat, hgt)
    q_true = mat_to_quat(c[::la.samples])
    ours, paper, series = {}, {}, []
    table = [(f"000 section 6.4, lever arm: eq. 54 sway ({', '.join(f'{a:g}' for a in sw.amplitude_deg)} deg, "
             f"periods {', '.join(f'{p:g}' for p in sw.period_s)} s), {la.duration_s:g} s at {la.rate_hz:g} Hz; "
             "maximum attitude errors (E, N, U)")]
    for r_p in la.lever_arms_m:
        group = _lever_arm_group(r_p)
        p_ref = PAPER_LEVER_ARM.get(tuple(float(x) for x in r_p))
        dtheta, dv = _sway_increments(t, w_ib, f_b, r_p)
        res = {"lever_arm_m": list(r_p)}
        for variant, dv_used in (("uncompensated", dv), ("compensated", compensate_lever_arm(dtheta, dv, r_p, t=t))):
            nav = mechanize(t, dtheta, dv_used, lat, lon, hgt, np.zeros(3), q_true[0], n_samples=la.samples,
                            hold_height=la.hold_height)
            att = attitude_error(q_true[:nav.t.size], nav.q_nb)
            pos = earth.lla_to_enu(nav.lat, nav.lon, nav.h, lat, lon, hgt)
            res[f"{variant}_deg"] = np.degrees(np.abs(att).max(axis=0)).tolist()
            res[f"{variant}_velocity_m_s"] = np.abs(nav.v_n).max(axis=0).tolist()
            res[f"{variant}_position_m"] = np.abs(pos).max(axis=0).tolist()
            series += [Series(group, "attitude", variant, nav.t, att),
                       Series(group, "velocity", variant, nav.t, nav.v_n),
                       Series(group, "position", variant, nav.t, pos)]
        res["reduction_pct"] = reduction_pct(res["uncompensated_deg"], res["compensated_deg"]).tolist()
        table += [f"r_p = {list(r_p)} m" + (f" (paper Table {p_ref['table']})" if p_ref else ""),
                  header(["dphi_E", "dphi_N", "dphi_U"]),
                  row("ours uncompensated [deg]", res["uncompensated_deg"], ".3e"),
                  row("ours compensated [deg]", res["compensated_deg"], ".3e"),
                  row("ours reduction [%]", res["reduction_pct"], ".2f")]
        if exp.closed_loop.enabled:
            loop = {}
            for variant in ("uncompensated", "compensated"):
                tk, att = _closed_loop(exp, t, c, dtheta, dv, r_p, variant == "compensated")
                loop[f"{variant}_deg"] = np.degrees(np.abs(att[att.shape[0] // 2:]).max(axis=0)).tolist()
                loop[f"{variant}_final_deg"] = np.degrees(att[-1]).tolist()
                series.append(Series(f"closed_loop/{group}", "attitude", variant, tk, att))
            loop["reduction_pct"] = reduction_pct(loop["uncompensated_deg"], loop["compensated_deg"]).tolist()
            res["closed_loop"] = loop
            table += [row("closed loop uncompensated [deg]", loop["uncompensated_deg"], ".4f"),
                      row("closed loop compensated [deg]", loop["compensated_deg"], ".4f"),
                      row("closed loop reduction [%]", loop["reduction_pct"], ".2f")]
        if p_ref:
            paper[group] = {"lever_arm_m": list(r_p), **{k: v for k, v in p_ref.items() if k != "table"}}
            table += [row("paper uncompensated [deg]", p_ref["uncompensated_deg"], ".2f"),
                      row("paper compensated [deg]", p_ref["compensated_deg"], ".2f"),
                      row("paper reduction [%]", p_ref["reduction_pct"], ".1f")]
            line = "  reductions >= paper's: mechanization "
            for part in (res, res.get("closed_loop")):
                if part is not None:
                    part["meets_paper"] = bool(np.all(np.array(part["reduction_pct"]) >= p_ref["reduction_pct"]))
                    line += f"{'yes' if part['meets_paper'] else 'no'}{', closed loop ' if part is res else ''}"
            table.append(line.removesuffix(", closed loop "))
        ours[group] = res
    if exp.closed_loop.enabled:
        cl = exp.closed_loop
        table.append(f"  closed loop: the paper's sensor errors, R = ({cl.velocity_sigma_m_s:g} m/s)^2, maximum over "
                     f"the second half ({la.duration_s / 2:g}-{la.duration_s:g} s)")
    return ExperimentResult(exp.name, exp.experiment, ours, paper, table, series)
