"""The mechanization against the linear SINS error model: 24 h stationary with a z-gyro bias, vertical held."""

from __future__ import annotations

import numpy as np

from estimators.nav import earth
from estimators.sins.error_model import DLAT, DLON, stationary_day, system_matrix


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
    d = stationary_day()
    assert np.abs(d["north"] - d["lin_north"]).max() <= 0.05 * np.abs(d["lin_north"]).max()
    assert np.abs(d["east"] - d["lin_east"]).max() <= 0.05 * np.abs(d["lin_east"]).max()
    lin_phi = d["lin_phi"]
    assert np.linalg.norm(d["phi"] - lin_phi, axis=1).max() <= 0.05 * np.linalg.norm(lin_phi, axis=1).max()
    assert np.abs(d["lin_east"]).max() > 1000.0  # km-level errors: the comparison is not trivial
