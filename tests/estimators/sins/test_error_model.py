"""The mechanization against the linear SINS error model (estimators.sins.error_model): its Schuler and Earth-rate
modes, 24 h stationary with a z-gyro bias (vertical held), and a moving solution error over a minute."""

from __future__ import annotations

import pytest
import numpy as np

from estimators.kalman.error_state import DP, DV, HGT, LAT, LON, N_NAV, PHI, QUAT, VEL
from estimators.nav import earth
from estimators.nav.rotations import (
    quat_conj,
    quat_mul,
    quat_to_mat,
    quat_to_rotvec,
    rotvec_to_quat,
)
from estimators.sins.error_model import (
    N_NAV_ERRORS,
    horizontal_channels,
    stationary_day,
    system_matrix,
)
from estimators.sins.strapdown import mechanize

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def test_error_model_has_the_schuler_and_earth_rate_modes():
    lat, gamma = np.radians(34.0), earth.normal_gravity(np.radians(34.0), 0.0)
    nav = np.r_[lat, 0.0, 0.0, np.zeros(3), 1.0, 0.0, 0.0, 0.0]
    f = system_matrix(nav, np.array([0.0, 0.0, gamma]))
    keep = horizontal_channels()  # vertical held
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
    d = stationary_day()
    assert np.abs(d["north"] - d["lin_north"]).max() <= 0.05 * np.abs(d["lin_north"]).max()
    assert np.abs(d["east"] - d["lin_east"]).max() <= 0.05 * np.abs(d["lin_east"]).max()
    lin_phi = d["lin_phi"]
    assert np.linalg.norm(d["phi"] - lin_phi, axis=1).max() <= 0.05 * np.linalg.norm(lin_phi, axis=1).max()
    assert np.abs(d["lin_east"]).max() > 1000.0  # km-level errors: the comparison is not trivial


def _error_vector(est, true, k: int) -> np.ndarray:
    """The navigation error (DV, PHI, DP of estimators.kalman.error_state) of solution `est` against `true` at k."""
    r_m, r_n = earth.radii(true.lat[k])
    x = np.zeros(N_NAV_ERRORS)
    x[DV] = est.v_n[k] - true.v_n[k]
    x[PHI] = -quat_to_rotvec(quat_mul(est.q_nb[k], quat_conj(true.q_nb[k])))  # C_b^n' = (I - [phi x]) C_b^n
    x[DP] = [(est.lon[k] - true.lon[k]) * (r_n + true.h[k]) * np.cos(true.lat[k]),
             (est.lat[k] - true.lat[k]) * (r_m + true.h[k]), est.h[k] - true.h[k]]
    return x


def test_error_model_propagates_a_moving_solution_error_as_the_mechanization_does():
    """Linearized against nonlinear: two mechanizations of the same increments (a body at 100 m/s, climbing and
    turning) from states that differ by x0 (velocity, attitude, ENU position errors); their difference after 60 s
    matches the product of Phi = I + F T + (F T)^2 / 2 along the true solution to 5e-5 of its size. Without the
    Earth- and transport-rate partials in (dv, dp) the model is off by more than twenty times as much."""
    lat0, h0, rate, seconds = np.radians(55.0), 300.0, 100.0, 60.0
    t = np.arange(round(seconds * rate) + 1) / rate
    w_b = np.array([0.0, 0.002, 0.02])  # pitching up slowly, turning
    f_b = np.array([0.3, 0.8, earth.normal_gravity(lat0, h0) + 0.05])
    dtheta, dv = np.tile(w_b / rate, (t.size, 1)), np.tile(f_b / rate, (t.size, 1))
    dtheta[0] = dv[0] = 0.0
    v0, q0 = np.array([80.0, 60.0, 2.0]), np.array([1.0, 0.0, 0.0, 0.0])
    x0 = np.zeros(N_NAV_ERRORS)
    x0[DV], x0[PHI], x0[DP] = [0.05, -0.03, 0.02], [2e-4, -1e-4, 5e-4], [40.0, -30.0, 5.0]
    r_m, r_n = earth.radii(lat0)
    true = mechanize(t, dtheta, dv, lat0, 0.0, h0, v0, q0, n_samples=1)
    est = mechanize(t, dtheta, dv, lat0 + x0[DP][1] / (r_m + h0), x0[DP][0] / ((r_n + h0) * np.cos(lat0)),
                    h0 + x0[DP][2], v0 + x0[DV], quat_mul(rotvec_to_quat(-x0[PHI]), q0), n_samples=1)
    nonlinear = _error_vector(est, true, t.size - 1)
    assert np.allclose(_error_vector(est, true, 0), x0)
    linear = {}
    for partials in (True, False):
        x = x0.copy()
        for k in range(1, t.size):
            nav = np.zeros(N_NAV)
            nav[LAT], nav[LON], nav[HGT], nav[VEL], nav[QUAT] = (true.lat[k - 1], true.lon[k - 1], true.h[k - 1],
                                                                 true.v_n[k - 1], true.q_nb[k - 1])
            f_n = quat_to_mat(0.5 * (true.q_nb[k - 1] + true.q_nb[k])) @ f_b
            ft = system_matrix(nav, f_n, earth_partials=partials)[:N_NAV_ERRORS, :N_NAV_ERRORS] / rate
            x = (np.eye(N_NAV_ERRORS) + ft + ft @ ft / 2) @ x
        linear[partials] = x
    err_full = np.linalg.norm(linear[True] - nonlinear) / np.linalg.norm(nonlinear)
    err_bare = np.linalg.norm(linear[False] - nonlinear) / np.linalg.norm(nonlinear)
    assert err_full < 5e-5, err_full  # measured 2.2e-5
    assert err_bare > 20 * err_full, (err_bare, err_full)  # measured 1.7e-3
