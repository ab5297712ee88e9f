"""The mechanization against the linear SINS error model: 24 h stationary with a z-gyro bias, vertical held."""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

from estimators import earth
from estimators.error_model import DLAT, DLON, PHI, system_matrix, sensor_input
from estimators.rotations import quat_conj, quat_mul, quat_to_rotvec
from estimators.strapdown import mechanize


def test_error_model_has_the_schuler_and_earth_rate_modes():
    lat, gamma = np.radians(34.0), earth.normal_gravity(np.radians(34.0), 0.0)
    f = system_matrix(lat, 0.0, np.zeros(3), np.array([0.0, 0.0, gamma]))
    keep = np.r_[0:5, DLAT, DLON]  # horizontal channels (vertical held)
    freqs = np.sort(np.abs(np.linalg.eigvals(f[np.ix_(keep, keep)]).imag))
    r_m, r_n = earth.radii(lat)
    schuler = np.sqrt(gamma / np.sqrt(r_m * r_n))
    # Schuler (84.4 min) split by the Foucault frequency W sin L into two modes, and the Earth-rate mode.
    fast = np.unique(np.round(freqs[freqs > 1e-4], 12))
    assert fast.size == 2
    assert np.isclose(fast.mean(), schuler, rtol=1e-3) and np.isclose(2 * np.pi / fast.mean() / 60, 84.4, rtol=2e-3)
    assert np.isclose(np.diff(fast)[0] / 2, earth.OMEGA_IE * np.sin(lat), rtol=1e-2)
    assert np.any(np.isclose(freqs, earth.OMEGA_IE, rtol=1e-6))


def test_stationary_day_with_a_gyro_bias_matches_the_linear_model():
    """34 deg latitude, 24 h, 0.01 deg/h z-gyro bias, height held: position errors (Schuler 84.4 min on the
    24 h oscillation, km-level) and attitude errors within 5 % of the linear model's."""
    lat0, h0, rate, hours = np.radians(34.0), 0.0, 10.0, 24.0
    bias = np.radians(0.01) / 3600
    n = int(hours * 3600 * rate) + 1
    t = np.arange(n) / rate
    gamma = earth.normal_gravity(lat0, h0)
    dtheta = np.tile((earth.earth_rate_n(lat0) + [0.0, 0.0, bias]) / rate, (n, 1))
    dv = np.tile([0.0, 0.0, gamma / rate], (n, 1))
    dtheta[0] = dv[0] = 0.0
    q0 = np.array([1.0, 0.0, 0.0, 0.0])  # level, body y north: b = n
    nav = mechanize(t, dtheta, dv, lat0, 0.0, h0, np.zeros(3), q0, n_samples=1, hold_height=True)
    r_m, r_n = earth.radii(lat0)
    step = 600
    idx = np.arange(0, n, step)
    north = (nav.lat[idx] - lat0) * (r_m + h0)
    east = nav.lon[idx] * (r_n + h0) * np.cos(lat0)
    phi = -quat_to_rotvec(quat_mul(nav.q_nb[idx], quat_conj(q0)))  # C_n^n' = I - [phi x]
    # Linear model: x' = F x + G_gyro b, the bias as a constant augmented state, vertical channel removed.
    keep = np.r_[0:5, DLAT, DLON]
    f = system_matrix(lat0, h0, np.zeros(3), np.array([0.0, 0.0, gamma]))
    g_gyro, _ = sensor_input(q0)
    a = np.zeros((8, 8))
    a[:7, :7] = f[np.ix_(keep, keep)]
    a[:7, 7] = (g_gyro @ [0.0, 0.0, bias])[keep]
    transition = expm(a * step / rate)
    x = np.zeros(8)
    x[7] = 1.0
    lin = [x.copy()]
    for _ in range(idx.size - 1):
        x = transition @ x
        lin.append(x.copy())
    lin = np.array(lin)
    lin_north, lin_east = lin[:, 5] * (r_m + h0), lin[:, 6] * (r_n + h0) * np.cos(lat0)
    assert np.abs(north - lin_north).max() <= 0.05 * np.abs(lin_north).max()
    assert np.abs(east - lin_east).max() <= 0.05 * np.abs(lin_east).max()
    lin_phi = lin[:, PHI]
    assert np.linalg.norm(phi - lin_phi, axis=1).max() <= 0.05 * np.linalg.norm(lin_phi, axis=1).max()
    assert np.abs(lin_east).max() > 1000.0  # km-level errors: the comparison is not trivial
