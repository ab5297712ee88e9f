"""Fine-alignment benchmark on the setup of 000 section 5.3 / Table 1: EKF, UKF and optimized UKF.

Setup (000 section 5.3): latitude 34.27 deg, height 36 m, pitch = roll = 0, heading 270 deg (yaw -90 deg ENU),
initial attitude errors phi_E, phi_N, phi_U = 3, 3, 5 deg, 200 Hz, stationary. 000 names no IMU and no
alignment time, so both grades the project has for the shearer are run, each for as long as it needs:

* mti-g-700 (300 s): the MEMS MIMU of the shearer papers (001 Table 1), the class of sensor a shearer carries;
  its 720 deg/h gyro bias makes gyrocompassing impossible (heading floor tens of degrees): the heading keeps
  its start error and sigma, the level goes to accel bias / g;
* nav-004 (1800 s): the navigation-grade INS of 004 Table 1 (heading floor ~0.005 deg, reached by averaging the
  gyro ARW down).

Floors of the draw (estimators.sins.fine_alignment `alignment_floors`, signed, per axis, the tilt about the axes of
the estimate once its heading error is taken out): the errors no stationary
alignment can beat for the biases actually drawn (turn-on bias plus non-orthogonality times gravity). "classical"
is -nabla_N / g, nabla_E / g and the gyrocompassing floor; the level floor of phi_E also weighs the north and up
gyros' view of the Earth-rate direction (a sixth of the weight for nav-004, nothing for MEMS), every angle the
start attitude (3, 3, 5 deg at one sigma of the filter's prior), and the gyro verdicts the ARW not yet
averaged down: a MEMS heading floor is its start error.

Printed per filter: final phi_E, phi_N, phi_U [deg] of the mean attitude over the last WINDOW seconds (C_true = E(phi) C_est, the filter's convention and 000
Table 1's angles), the filter's one-sigma, each error / its floor, the level deviation |phi_EN - floor_EN| /
|floor_EN|, pitch, roll, yaw error (estimate - truth), the settling times (from then on the level stays within
10 % of its floor, the heading within 10 % of its floor plus 3 ARW sigma, or within 3 sigma of its start error
where it cannot gyrocompass) and the run time. 000 Table 1 is printed as the reference (its units are not
stated; copied as written: "Error" and "Variance" of phi_E, phi_N, phi_U).

Run: python benchmarks/bench_alignment.py [seed] [nav-004 seconds]  (7200 s averages the ARW below a tenth of
most heading floors; the UKFs then take ~15 s each)
"""

from __future__ import annotations

import sys
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
from estimators.sins.fine_alignment import METHODS, alignment_floors, fine_align
from twin.config.imu_grades import grade
from twin.sensors.imu_errors import apply_imu_errors

LAT = np.radians(34.27)
H = 36.0
RATE = 200.0
YAW = np.radians(270.0 - 360.0)
ERR0 = np.radians([3.0, 3.0, 5.0])
SECONDS = {"mti-g-700": 300.0, "nav-004": 1800.0}
WINDOW = 10.0  # [s] the result is the mean attitude over the last 10 s (FineAlignment.attitude)

# 000 Table 1 "Filtering Results of error angle" (units not stated in the paper): (error, variance) per angle.
TABLE1 = {
    "ekf": ((-0.510, 0.0103), (0.325, 0.0056), (-18.478, 9.4679)),
    "ukf": ((0.302, 0.0118), (-0.253, 0.0068), (8.935, 7.6143)),
    "optimized_ukf": ((-0.123, 0.0127), (0.102, 0.0059), (-4.239, 4.8291)),
}
NAMES = {"ekf": "EKF", "ukf": "UKF", "optimized_ukf": "optimized UKF"}


def settled(ok: np.ndarray, t: np.ndarray) -> float:
    """First time from which `ok` holds to the end (nan if it does not hold at the end)."""
    if not ok[-1]:
        return float("nan")
    bad = np.flatnonzero(~ok)
    return float(t[bad[-1] + 1]) if bad.size else float(t[0])


def run_grade(gname: str, seed: int) -> dict:
    """Print the grade's rows; return per filter its figures (final errors [deg], ratios to the floors, level
    deviation, whether the level and heading settled by the end, settling and run times)."""
    g, seconds = grade(gname), SECONDS[gname]
    q_true = euler_to_quat(0.0, 0.0, YAW)
    c_true = quat_to_mat(q_true)
    gamma = earth.normal_gravity(LAT, H)
    w_b, f_b = quat_rotate(quat_conj(q_true), earth.earth_rate_n(LAT)), c_true.T @ [0.0, 0.0, gamma]
    n = int(seconds * RATE)
    dtheta, dv, info = apply_imu_errors(np.tile(w_b / RATE, (n, 1)), np.tile(f_b / RATE, (n, 1)), 1 / RATE, g,
                                        np.random.default_rng(seed))
    acc = info.accel_bias + (info.accel_matrix - np.eye(3)) @ f_b
    gyr = info.gyro_bias + (info.gyro_matrix - np.eye(3)) @ w_b
    acc_sigma = float(np.hypot(g.accel_bias, gamma * g.accel_nonorth))
    q0 = quat_mul(rotvec_to_quat(-ERR0), q_true)
    kw = {"arw": g.gyro_arw, "seconds": seconds, "start_error": ERR0, "start_sigma": ERR0}
    fl, cl = alignment_floors(c_true, acc, gyr, LAT, acc_sigma, g.gyro_bias, H, **kw)
    arw_angle = g.gyro_arw / np.sqrt(seconds) / (earth.OMEGA_IE * np.cos(LAT))
    print(f"\n{gname}, {seconds:.0f} s: accel sigma {acc_sigma / 9.80665e-3:.3f} mg, gyro bias sigma "
          f"{np.degrees(g.gyro_bias) * 3600:g} deg/h, ARW {np.degrees(g.gyro_arw) * 60:g} deg/sqrt(h)")
    print(f"  floors of this draw [deg] (in the true axes; each filter's ratios use its final axes, which differ by its"
          f" heading error): phi_E {np.degrees(fl[0]):+.5f} (classical -nabla_N/g "
          f"{np.degrees(cl[0]):+.5f}), phi_N {np.degrees(fl[1]):+.5f}, phi_U {np.degrees(fl[2]):+.5f} "
          f"(3 ARW sigma {np.degrees(3 * arw_angle):.5f}; gyrocompassing floor {np.degrees(cl[2]):+.5f})")
    print(f"  {'filter':14s} {'phi_E':>9s} {'phi_N':>9s} {'phi_U':>9s} | {'sig_E':>8s} {'sig_N':>8s} {'sig_U':>8s} |"
          f" {'E/fl':>5s} {'N/fl':>5s} {'U/fl':>6s} {'lvl dev':>7s} | {'pitch':>9s} {'roll':>9s} {'yaw':>9s} |"
          f" {'t_lvl':>6s} {'t_hdg':>6s} {'run':>5s}   [deg, s]")
    gyrocompass = abs(fl[2]) < ERR0[2]
    figures = {}
    for m in METHODS:
        t0 = time.perf_counter()
        res = fine_align(dtheta, dv, 1 / RATE, LAT, q0, (g.gyro_arw, g.accel_vrw), ERR0, m, h=H,
                         gyro_bias_sigma=g.gyro_bias, accel_bias_sigma=acc_sigma, update_rate=10.0,
                         gyro_bias_psd=g.gyro_bias_psd,
                         accel_bias_psd=g.accel_bias_psd)
        el = time.perf_counter() - t0
        fl, _ = alignment_floors(quat_to_mat(res.attitude(WINDOW)), acc, gyr, LAT, acc_sigma, g.gyro_bias, H, **kw)
        phi_t = np.stack(mat_to_euler(c_true @ np.swapaxes(quat_to_mat(res.q_nb), -1, -2)), axis=-1)
        n_w = round(WINDOW / (res.t[1] - res.t[0]))
        cum = np.cumsum(np.vstack([np.zeros(3), phi_t]), axis=0)
        phi_t[n_w - 1:] = (cum[n_w:] - cum[:-n_w]) / n_w  # the running WINDOW mean (small angles)
        dev_t = np.hypot(*(phi_t[:, :2] - fl[:2]).T) / np.hypot(*fl[:2])
        if gyrocompass:
            hdg_ok = np.abs(phi_t[:, 2] - fl[2]) <= 0.1 * abs(fl[2]) + 3 * arw_angle
        else:
            hdg_ok = np.abs(phi_t[:, 2] - ERR0[2]) <= 3 * res.attitude_sigma[:, 2]
        d, phi = res.errors(q_true, window_s=WINDOW)
        s = res.attitude_sigma[-1]
        r = phi / fl
        print(f"  {NAMES[m]:14s} {np.degrees(phi[0]):+9.5f} {np.degrees(phi[1]):+9.5f} {np.degrees(phi[2]):+9.4f} |"
              f" {np.degrees(s[0]):8.5f} {np.degrees(s[1]):8.5f} {np.degrees(s[2]):8.4f} | {r[0]:5.2f} {r[1]:5.2f}"
              f" {r[2]:6.2f} {dev_t[-1]:7.3f} | {np.degrees(d[0]):+9.5f} {np.degrees(d[1]):+9.5f}"
              f" {np.degrees(d[2]):+9.4f} | {settled(dev_t <= 0.1, res.t):6.0f} {settled(hdg_ok, res.t):6.0f}"
              f" {el:5.2f}")
        figures[m] = {"phi_deg": np.degrees(phi).tolist(), "sigma_deg": np.degrees(s).tolist(), "ratio": r.tolist(),
                      "level_dev": float(dev_t[-1]), "level_ok": bool(dev_t[-1] <= 0.1), "heading_ok": bool(hdg_ok[-1]),
                      "t_level": settled(dev_t <= 0.1, res.t), "t_heading": settled(hdg_ok, res.t), "seconds": el}
    return figures


def main(seed: int = 0, nav_seconds: float = SECONDS["nav-004"]) -> dict:
    """Print 000 Table 1 and every grade's rows; return {grade: run_grade's figures}."""
    SECONDS["nav-004"] = nav_seconds
    print(f"000 Table 1 setup: L = 34.27 deg, h = {H:.0f} m, heading 270 deg, initial errors 3, 3, 5 deg, 200 Hz, "
          f"stationary, seed {seed}")
    print("\n000 Table 1 (reference, units as in the paper, not stated; no IMU, no alignment time given):")
    print(f"  {'filter':14s} {'phi_E err':>10s} {'var':>8s} {'phi_N err':>10s} {'var':>8s} {'phi_U err':>10s} "
          f"{'var':>8s}")
    for m in METHODS:
        (e1, v1), (e2, v2), (e3, v3) = TABLE1[m]
        print(f"  {NAMES[m]:14s} {e1:10.3f} {v1:8.4f} {e2:10.3f} {v2:8.4f} {e3:10.3f} {v3:8.4f}")
    dtheta, dv = np.zeros((200, 3)), np.tile([0.0, 0.0, 9.8 / RATE], (200, 1))
    for m in METHODS:  # compile the numba kernels before anything is timed
        fine_align(dtheta, dv, 1 / RATE, LAT, euler_to_quat(0.0, 0.0, 0.0), (1e-4, 1e-4), ERR0, m, on_motion="flag")
    return {gname: run_grade(gname, seed) for gname in SECONDS}


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 0, float(sys.argv[2]) if len(sys.argv) > 2 else SECONDS["nav-004"])
