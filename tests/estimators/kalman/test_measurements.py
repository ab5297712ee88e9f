"""Measurement models of the SINS/odometer filters (estimators.kalman.measurements)."""

import pytest
import numpy as np

from estimators.kalman import error_state as es
from estimators.kalman.measurements import odometer_velocity
from estimators.nav.earth import nav_rates
from estimators.nav.rotations import euler_to_quat, quat_mat, rotvec_mat

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def test_odometer_velocity_takes_the_turn_about_the_lever_arm_out_of_the_imu_velocity():
    """A body turning at 0.05 rad/s in the snake while moving at 0.1 m/s along y; the IMU 0.3 m across and 0.5 m
    ahead of the body point moves at v + w x l, constant in b, so in n it turns with the body. With the exact
    displacement over the epoch (the integral of C_b^n(s) (v + w x l), here by Simpson's rule), angle increment and
    odometer distance the velocity innovation is zero to second order in the epoch's turn: the odometer counts the
    body point, not the IMU, and the epoch's mean velocity is resolved at mid-epoch. Resolved at the epoch's end it
    would lean by half the turn, 0.1 m/s x 2.5 mrad = 2.9e-4 m/s across."""
    lat, h, t_span = np.radians(34.0), 100.0, 0.1
    q = euler_to_quat(0.01, 0.02, 0.3)
    c_nb = quat_mat(q)  # at the epoch's end
    nav = np.zeros(es.N_NAV)
    nav[:3] = lat, 0.0, h
    nav[es.QUAT] = q
    lever = np.array([0.3, 0.5, 0.2])
    w_nb = np.array([0.0, 0.0, 0.05])  # the body's rate relative to n
    v_imu_b = np.array([0.0, 0.1, 0.0]) + np.cross(w_nb, lever)
    nav[es.VEL] = c_nb @ v_imu_b
    w_ie, w_en = nav_rates(lat, h, nav[es.VEL])
    w_sum = (w_nb + c_nb.T @ (w_ie + w_en)) * t_span
    s = np.linspace(0.0, t_span, 2001)
    v_n = np.array([c_nb @ rotvec_mat(-w_nb * (t_span - si)) @ v_imu_b for si in s])
    disp = (v_n[0] + v_n[-1] + 4 * v_n[1:-1:2].sum(axis=0) + 2 * v_n[2:-1:2].sum(axis=0)) * (s[1] - s[0]) / 3
    x = np.zeros(es.N_STATES)
    nominal = np.zeros(es.N_NOMINAL)
    r_vel = np.eye(3) * 1e-4
    z, h_odo, _ = odometer_velocity(nav, np.zeros(es.N_CAL), disp, w_sum, lever, t_span, 0.1 * t_span,
                                    nominal, r_vel, 20.0, es.N_STATES)
    innov = z - h_odo @ x
    assert np.abs(innov).max() < 2e-7, innov  # second order: (0.1 m/s) (w t)^2 / 24 = 1e-7 m/s
    end = c_nb.T @ (disp / t_span) - np.cross(w_sum / t_span - c_nb.T @ w_ie, lever) - [0.0, 0.1, 0.0]
    assert np.abs(end).max() > 2e-4  # the same epoch resolved at its end
