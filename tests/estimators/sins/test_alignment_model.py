"""The fine-alignment state (000 section 5.2) is a selection of the shared error-state layout: its blocks are the
shared blocks of their names, in the shared order, and at a stand its A and H are the shared filter's F
(estimators.shearer.odometer_filter) and zero-velocity / zero-rate H (estimators.kalman.measurements) restricted
to the selection, signs included."""

from __future__ import annotations

import numpy as np

from estimators.kalman import error_state as es
from estimators.kalman.measurements import zero_rate, zero_velocity
from estimators.nav import earth
from estimators.nav.rotations import euler_to_quat, quat_to_mat
from estimators.shearer.odometer_filter import system_matrix
from estimators.sins import alignment_model as am

LAT = np.radians(34.27)
SEL = np.ix_(am.SHARED_INDEX, am.SHARED_INDEX)


def stand():
    """A tilted, turned IMU standing at LAT: the shared navigation vector and its C_b^n (every entry non-zero, so
    a gyro bias is told from an accelerometer bias and x from y)."""
    q_nb = euler_to_quat(np.radians(4.0), np.radians(-7.0), np.radians(-100.0))
    nav = np.zeros(es.N_NAV)
    nav[es.LAT] = LAT
    nav[es.QUAT] = q_nb
    return nav, quat_to_mat(q_nb)


def test_the_alignment_state_is_the_shared_layout_s_selection_in_its_order():
    assert list(am.SHARED_INDEX) == [*range(es.DV.start, es.DV.start + 2), *range(es.PHI.start, es.PHI.stop),
                                     *range(es.GYRO_BIAS.start, es.GYRO_BIAS.stop),
                                     *range(es.ACCEL_BIAS.start, es.ACCEL_BIAS.start + 2)]
    assert np.all(np.diff(am.SHARED_INDEX) > 0)  # the shared order (000 eq. 19 has the accelerometers first)
    for own, shared, n in ((am.DV, es.DV, 2), (am.PHI, es.PHI, 3), (am.GYRO_BIAS, es.GYRO_BIAS, 3),
                           (am.ACCEL_BIAS, es.ACCEL_BIAS, 2)):
        assert list(am.SHARED_INDEX[own]) == list(range(shared.start, shared.start + n))
    assert am.N_STATES == am.SHARED_INDEX.size == 10
    assert am.BIASES == slice(am.GYRO_BIAS.start, am.ACCEL_BIAS.stop)


def test_transition_is_the_shared_system_matrix_on_the_selection():
    """Phi of 000 eq. 26 (third order) from A equals the same series of the shared F restricted to the states."""
    nav, c_nb = stand()
    gamma = float(earth.normal_gravity(LAT, 0.0))
    T = 0.1
    phi, _ = am.transition(c_nb, earth.earth_rate_n(LAT), gamma, T, np.zeros(am.N_STATES))
    ft = system_matrix(nav, np.array([0.0, 0.0, gamma]))[SEL] * T
    ft2 = ft @ ft
    assert np.allclose(phi, np.eye(am.N_STATES) + ft + ft2 / 2 + ft2 @ ft / 6, rtol=0.0, atol=1e-14)


def test_measurements_are_the_shared_zero_velocity_and_zero_rate_on_the_selection():
    """Zero velocity: the shared H's east and north rows; zero vertical rate: the up row of the shared zero-rate H
    resolved in n, over the block T."""
    nav, c_nb = stand()
    w, T = earth.earth_rate_n(LAT), 0.1
    _, hm, _ = am.measurement(c_nb, c_nb, np.zeros(2), c_nb.T @ w * T, w, T, 1.0, 1.0, True)
    _, h_zv, _ = zero_velocity(np.zeros(3), T, np.zeros(es.N_NOMINAL), 1.0, es.N_STATES)
    _, h_zr, _ = zero_rate(nav, c_nb.T @ w * T, T, 1.0, es.N_STATES)
    assert np.array_equal(hm[:2], h_zv[:2][:, am.SHARED_INDEX])
    assert np.allclose(hm[2], T * (c_nb @ h_zr)[2, am.SHARED_INDEX], rtol=0.0, atol=1e-15)
