"""Fine-alignment benchmark on the setup of 000 section 5.3 / Table 1: EKF, UKF and optimized UKF.

Setup (000 section 5.3): latitude 34.27 deg, height 36 m, pitch = roll = 0, heading 270 deg (yaw -90 deg ENU),
initial attitude errors phi_E, phi_N, phi_U = 3, 3, 5 deg, 200 Hz, stationary. 000 names no IMU and no
alignment time, so both grades the project has for the shearer are run, for ALIGN_SECONDS:

* mti-g-700: the MEMS MIMU of the shearer papers (001 Table 1), the class of sensor a shearer carries;
  its 720 deg/h gyro bias makes gyrocompassing impossible (heading floor tens of degrees);
* nav-004: the navigation-grade INS of 004 Table 1 (heading floor ~0.005 deg).

Printed per filter: final pitch, roll, yaw errors [deg] (estimate - truth), the filter's one-sigma of
phi_E, phi_N, phi_U [deg], and run time. 000 Table 1 is printed as the reference (its units are not stated;
copied as written: "Error" and "Variance" of phi_E, phi_N, phi_U).

Run: python benchmarks/bench_alignment.py [seconds] [seed]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from estimators import earth
from estimators.alignment import heading_limit, level_limit
from estimators.fine_alignment import METHODS, fine_align
from estimators.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    quat_to_mat,
    rotvec_to_quat,
)
from twin.imu_errors import apply_imu_errors
from twin.imu_grades import grade

LAT = np.radians(34.27)
H = 36.0
RATE = 200.0
YAW = np.radians(270.0 - 360.0)
ERR0 = np.radians([3.0, 3.0, 5.0])
ALIGN_SECONDS = 300.0

# 000 Table 1 "Filtering Results of error angle" (units not stated in the paper): (error, variance) per angle.
TABLE1 = {
    "ekf": ((-0.510, 0.0103), (0.325, 0.0056), (-18.478, 9.4679)),
    "ukf": ((0.302, 0.0118), (-0.253, 0.0068), (8.935, 7.6143)),
    "optimized_ukf": ((-0.123, 0.0127), (0.102, 0.0059), (-4.239, 4.8291)),
}
NAMES = {"ekf": "EKF", "ukf": "UKF", "optimized_ukf": "optimized UKF"}


def psd(sigma: float, tau: float) -> float:
    """Random-walk PSD for the bias states matching a Gauss-Markov in-run bias: 2 sigma^2 / tau."""
    return 2 * sigma ** 2 / tau if sigma > 0 else 0.0


def main(seconds: float = ALIGN_SECONDS, seed: int = 0) -> None:
    q_true = euler_to_quat(0.0, 0.0, YAW)
    n = int(seconds * RATE)
    w_b = quat_rotate(quat_conj(q_true), earth.earth_rate_n(LAT))
    f_b = quat_rotate(quat_conj(q_true), np.array([0.0, 0.0, earth.normal_gravity(LAT, H)]))
    q0 = quat_mul(rotvec_to_quat(-ERR0), q_true)
    print(f"000 Table 1 setup: L = 34.27 deg, h = {H:.0f} m, heading 270 deg, initial errors 3, 3, 5 deg, "
          f"200 Hz, {seconds:.0f} s stationary, seed {seed}")
    print("\n000 Table 1 (reference, units as in the paper, not stated):")
    print(f"{'filter':15s} {'phi_E err':>10s} {'var':>8s} {'phi_N err':>10s} {'var':>8s} {'phi_U err':>10s} {'var':>8s}")
    for m in METHODS:
        (e1, v1), (e2, v2), (e3, v3) = TABLE1[m]
        print(f"{NAMES[m]:15s} {e1:10.3f} {v1:8.4f} {e2:10.3f} {v2:8.4f} {e3:10.3f} {v3:8.4f}")
    for gname in ("mti-g-700", "nav-004"):
        g = grade(gname)
        dtheta, dv, info = apply_imu_errors(np.tile(w_b / RATE, (n, 1)), np.tile(f_b / RATE, (n, 1)), 1 / RATE, g,
                                            np.random.default_rng(seed))
        c = quat_to_mat(q_true)
        acc_n, gyr_n = c @ info.accel_bias, c @ info.gyro_bias
        lev = np.degrees(level_limit(float(np.hypot(acc_n[0], acc_n[1])), LAT, H))
        hdg = np.degrees(abs(heading_limit(float(gyr_n[0]), LAT)))
        print(f"\n{gname}: floors of this draw: level {lev:.4f} deg, heading (east gyro) {hdg:.4f} deg")
        print(f"{'filter':15s} {'pitch err':>10s} {'roll err':>10s} {'yaw err':>10s} {'sig_E':>9s} {'sig_N':>9s} "
              f"{'sig_U':>9s} {'time':>7s}   [deg, s]")
        for m in METHODS:
            t0 = time.perf_counter()
            res = fine_align(dtheta, dv, 1 / RATE, LAT, q0, (g.gyro_arw, g.accel_vrw), ERR0, m, h=H,
                             gyro_bias_sigma=g.gyro_bias, accel_bias_sigma=g.accel_bias, update_rate=10.0,
                             gyro_bias_psd=psd(g.gyro_bias_instability, g.gyro_bias_tau),
                             accel_bias_psd=psd(g.accel_bias_instability, g.accel_bias_tau))
            el = time.perf_counter() - t0
            d, _ = res.errors(q_true)
            d, s = np.degrees(d), np.degrees(res.attitude_sigma[-1])
            print(f"{NAMES[m]:15s} {d[0]:10.5f} {d[1]:10.5f} {d[2]:10.5f} {s[0]:9.5f} {s[1]:9.5f} {s[2]:9.5f} "
                  f"{el:7.2f}")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else ALIGN_SECONDS, int(sys.argv[2]) if len(sys.argv) > 2 else 0)
