"""Closed-loop fine alignment at rest with zero-velocity observations: the filter of 000 section 6.4.

000 section 6.4 runs its initial alignment on a swaying body (eq. 54) whose reference point rests: the sensor
at a lever arm r_p sees the lever-arm acceleration (000 eq. 41), which the filter takes for tilt unless the
increments are compensated first (estimators.sins.installation.compensate_lever_arm, eqs. 48-53). The paper
gives no filter; this is the one its setting implies:

* 15 error states: the navigation errors of estimators.sins.error_model (attitude phi with
  C_est = (I - [phi x]) C_true, ENU velocity, latitude, longitude, height), the gyro drift and the
  accelerometer bias (body axes);
* propagation per update interval T: the strapdown mechanization of the increments less the estimated
  biases (estimators.sins.strapdown, two-sample updates), Phi = I + F T + (F T)^2 / 2 with F of the error model
  at the new state and the sensor blocks of error_model.sensor_input, P <- Phi P Phi^T + G Q G^T;
* observation: the computed velocity, which is the velocity error of a resting reference point, with noise
  `velocity_sigma` (000 eqs. 28-30 through estimators.kalman.update.joseph_update);
* closed loop: the estimate is fed back after each update (attitude, velocity, position corrected, the biases
  accumulated and removed from later increments) and the error state restarts at zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.kalman.update import joseph_update
from estimators.nav.rotations import quat_mul, quat_to_mat, rotvec_to_quat
from estimators.sins import error_model
from estimators.sins.strapdown import mechanize

NAV = slice(0, error_model.N_STATES)
"""The navigation error states of estimators.sins.error_model: phi, dv_n, dlat, dlon, dh."""
PHI, DV, DLAT, DLON, DH = error_model.PHI, error_model.DV, error_model.DLAT, error_model.DLON, error_model.DH
BG = slice(9, 12)
"""Gyro drift [rad/s], body axes."""
BA = slice(12, 15)
"""Accelerometer bias [m/s^2], body axes."""
N_STATES = 15

VELOCITY_SIGMA0 = 0.01
"""Initial sigma of the velocity error [m/s] (the body starts at rest, its velocity known)."""
POSITION_VAR0 = (1e-14, 1e-14, 1e-2)
"""Initial variances of dlat, dlon [rad^2] and dh [m^2] (the reference point's position is surveyed)."""
NOISE_INFLATION = 1e3
"""Process noise: the sensors' white noise over an update interval, times this (000 gives no tuning)."""
SAMPLES_PER_STEP = 2
"""Increments per mechanization step within an update interval (two-sample coning and sculling)."""


@dataclass(frozen=True)
class AtRestSettings:
    """The filter's priors and noise (SI; angles in rad)."""

    attitude_sigma: np.ndarray
    """Initial sigma of phi (E, N, U) [rad]."""
    gyro_bias_sigma: float
    """Initial sigma of the gyro drift [rad/s]."""
    gyro_noise: float
    """White noise on each gyro sample's rate [rad/s]."""
    accel_bias_sigma: float
    """Initial sigma of the accelerometer bias [m/s^2]."""
    accel_noise: float
    """White noise on each accelerometer sample [m/s^2]."""
    update_hz: float
    velocity_sigma: float
    """Noise of the zero-velocity observation [m/s]."""


def align_at_rest(t: np.ndarray, dtheta: np.ndarray, dv: np.ndarray, q0_nb: np.ndarray, lat: float, lon: float,
                  h: float, s: AtRestSettings) -> tuple[np.ndarray, np.ndarray]:
    """Run the filter over increments (row k over (t[k-1], t[k]]; row 0 unused) from the attitude q0_nb at the
    resting reference point (lat, lon, h); returns the sample index of each update (U,) and q_nb (U, 4) after it."""
    step = float(t[1] - t[0])
    chunk = max(1, round(1.0 / (s.update_hz * step)))
    dt = chunk * step
    p = np.diag(np.r_[np.asarray(s.attitude_sigma) ** 2, [VELOCITY_SIGMA0 ** 2] * 3, list(POSITION_VAR0),
                      [s.gyro_bias_sigma ** 2] * 3, [s.accel_bias_sigma ** 2] * 3])
    hm = np.zeros((3, N_STATES))
    hm[:, DV] = np.eye(3)
    r = np.eye(3) * s.velocity_sigma ** 2
    qn = np.diag(np.r_[[s.gyro_noise ** 2 * dt * NOISE_INFLATION] * 3,
                       [s.accel_noise ** 2 * dt * NOISE_INFLATION] * 3])
    q, v, bg, ba = np.asarray(q0_nb, float), np.zeros(3), np.zeros(3), np.zeros(3)
    k_out, q_out = [], []
    for k0 in range(0, t.size - chunk, chunk):
        sl = slice(k0, k0 + chunk + 1)
        nav = mechanize(t[sl], dtheta[sl] - bg * step, dv[sl] - ba * step, lat, lon, h, v, q,
                        n_samples=SAMPLES_PER_STEP)
        lat, lon, h, v, q = nav.lat[-1], nav.lon[-1], nav.h[-1], nav.v_n[-1], nav.q_nb[-1]
        f_n = quat_to_mat(q) @ (dv[sl][1:].sum(axis=0) / dt - ba)
        g_gyro, g_accel = error_model.sensor_input(q)
        f = np.zeros((N_STATES, N_STATES))
        f[NAV, NAV] = error_model.system_matrix(lat, h, v, f_n)
        f[NAV, BG], f[NAV, BA] = g_gyro, g_accel
        phi = np.eye(N_STATES) + f * dt + f @ f * dt * dt / 2
        g = np.zeros((N_STATES, 6))
        g[NAV, :3], g[NAV, 3:] = g_gyro, g_accel
        p = phi @ p @ phi.T + g @ qn @ g.T
        x = np.zeros(N_STATES)
        joseph_update(x, p, v, hm, r)  # z = v: the computed velocity minus the zero of the resting point
        q = quat_mul(rotvec_to_quat(x[PHI]), q)
        q = q / np.linalg.norm(q)
        v = v - x[DV]
        lat, lon, h = lat - x[DLAT], lon - x[DLON], h - x[DH]
        bg, ba = bg + x[BG], ba + x[BA]
        k_out.append(k0 + chunk)
        q_out.append(q)
    return np.array(k_out), np.array(q_out)
