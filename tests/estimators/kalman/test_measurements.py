"""Measurement models of the SINS/odometer filters (estimators.kalman.measurements)."""

import numpy as np

from estimators.kalman import error_state as es
from estimators.kalman.measurements import odometer_velocity
from estimators.nav.earth import nav_rates
from estimators.nav.rotations import euler_to_quat, quat_mat


def test_odometer_velocity_takes_the_turn_about_the_lever_arm_out_of_the_imu_velocity():
    """A body turning at 0.01 rad/s in the snake while moving at 0.1 m/s along y; the IMU 0.3 m across and 0.5 m
    ahead of the body point moves at v + w x l. With the exact displacement, angle increment and odometer distance
    the velocity innovation is zero: the odometer counts the body point, not the IMU."""
    lat, h, t_span = np.radians(34.0), 100.0, 0.1
    q = euler_to_quat(0.01, 0.02, 0.3)
    c_nb = quat_mat(q)
    nav = np.zeros(es.N_NAV)
    nav[:3] = lat, 0.0, h
    nav[es.QUAT] = q
    lever = np.array([0.3, 0.5, 0.2])
    w_eb = np.array([0.0, 0.0, 0.01])
    v_body_b = np.array([0.0, 0.1, 0.0])
    v_imu_n = c_nb @ (v_body_b + np.cross(w_eb, lever))
    nav[es.VEL] = v_imu_n
    w_ie, _ = nav_rates(lat, h, v_imu_n)
    w_sum = (w_eb + c_nb.T @ w_ie) * t_span
    x = np.zeros(es.N_STATES)
    nominal = np.zeros(es.N_NOMINAL)
    r_vel = np.eye(3) * 1e-4
    z, h_odo, _ = odometer_velocity(nav, np.zeros(es.N_CAL), v_imu_n * t_span, w_sum, lever, t_span, 0.1 * t_span,
                                    nominal, r_vel, 20.0, es.N_STATES)
    innov = z - h_odo @ x
    assert np.abs(innov).max() < 1e-12
