"""Our error-state filter of a canopy unit's attitude (estimators.support.error_state): disturbed field flagged,
yaw kept, gyro bias learnt."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.nav.rotations import quat_conj, quat_rotate
from estimators.support.error_state import (
    FLAG_DIP,
    FLAG_GATE,
    FLAG_NORM,
    FLAG_STATIC,
    OursSettings,
    ours,
)
from estimators.support.unit_model import euler_errors
from tests.estimators.support.conftest import DT, exact_unit, model

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


def test_ours_flags_disturbed_field_and_keeps_yaw():
    """A field disturbance on the magnetometer for 20 s: flagged, and the yaw holds; the gyro bias is estimated."""
    rng = np.random.default_rng(5)
    k = 6000
    _q0, q, w, f, m = exact_unit(k, w_b=(0.0, 0.0, 0.01))
    bias = np.array([0.003, -0.002, 0.004])
    f = f + rng.normal(0, 0.007, f.shape)
    m = m + rng.normal(0, 1e-7, m.shape)
    t = np.arange(1, k + 1) * DT
    hit = (t > 30) & (t < 50)
    m_dist = m.copy()
    m_dist[hit] += quat_rotate(quat_conj(q[hit]), np.array([4e-6, -3e-6, 2e-6]))
    res = ours(w + bias, f, m_dist, DT, model(5e-5, 1e-14), OursSettings(gyro_bias_sigma0=0.01))
    ts = t[res.sample]
    flagged = (res.flags[0] & (FLAG_NORM | FLAG_DIP | FLAG_GATE)) > 0
    inside = (ts > 30.5) & (ts < 49.5)
    assert flagged[inside].all()
    assert not flagged[(ts > 10) & ~((ts > 29) & (ts < 52))].any()
    err = euler_errors(q[res.sample], res.q_nb[0])
    assert np.abs(err[ts > 10]).max() < np.radians(0.1)
    np.testing.assert_allclose(res.gyro_bias[0, -1], bias, atol=2e-4)


def test_ours_zero_rate_updates_hold_the_yaw_of_a_static_unit_through_a_long_disturbance():
    """A canopy unit switched on next to a standing shearer: the field is disturbed for the first 40 s and the
    uncalibrated gyro's z bias is 0.5 deg/s. The zero-rate updates learn the bias, so the yaw holds its start
    error instead of drifting 20 deg; once the field is clean the yaw comes back."""
    rng = np.random.default_rng(6)
    k = 6000
    _q0, q, w, f, m = exact_unit(k, w_b=(0.0, 0.0, 0.0))
    bias = np.array([0.003, -0.002, np.radians(0.5)])
    f = f + rng.normal(0, 0.007, f.shape)
    t = np.arange(1, k + 1) * DT
    m = m + rng.normal(0, 1e-7, m.shape) + np.where(t[:, None] < 40, quat_rotate(quat_conj(q), [3e-6, -2e-6, 2e-6]), 0)
    runs = {gate: ours(w + bias + rng.normal(0, 1e-3, w.shape), f, m, DT, model(5e-5, 1e-14),
                       OursSettings(gyro_bias_sigma0=0.02, relock_updates=30, zaru_gate=gate))
            for gate in (16.27, 0.0)}
    res = runs[16.27]
    ts = t[res.sample]
    yaw = np.degrees(euler_errors(q[res.sample], res.q_nb[0])[:, 2])
    during = (ts > 5) & (ts < 39)
    assert (res.flags[0][during] & FLAG_STATIC).all()
    assert np.ptp(yaw[during]) < 0.3
    assert np.abs(yaw[ts > 48]).max() < 0.2
    assert res.gyro_bias[0, np.searchsorted(ts, 30.0), 2] == pytest.approx(bias[2], abs=2e-4)
    without = np.degrees(euler_errors(q[res.sample], runs[0.0].q_nb[0])[:, 2])
    assert np.ptp(without[during]) > 10

