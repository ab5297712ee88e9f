"""Closed-loop fine alignment at rest with zero-velocity observations: the filter of 000 section 6.4.

000 section 6.4 runs its initial alignment on a swaying body (eq. 54) whose reference point rests: the sensor
at a lever arm r_p sees the lever-arm acceleration (000 eq. 41), which the filter takes for tilt unless the
increments are compensated first (estimators.sins.installation.compensate_lever_arm, eqs. 48-53). The paper
gives no filter; this is the one its setting implies:

* 15 error states, the first five blocks of estimators.kalman.error_state (ENU velocity, attitude phi with
  C_b^n' = (I - [phi x]) C_b^n, ENU position in metres, gyro drift, accelerometer bias);
* propagation per update interval T: the strapdown mechanization of the increments less the estimated
  biases (estimators.sins.strapdown, two-sample updates), Phi = I + F T + (F T)^2 / 2 with F of
  estimators.sins.error_model (with the Earth-rate partials) at the new state, P <- Phi P Phi^T + G Q G^T;
* observation: the computed velocity, which is the velocity error of a resting reference point, with noise
  `velocity_sigma` (000 eqs. 28-30 through estimators.kalman.update.joseph_update);
* closed loop: the estimate is fed back after each update (estimators.sins.error_model.feed_back_navigation, the biases
  accumulated and removed from later increments) and the error state restarts at zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.kalman.error_state import (
    ACCEL_BIAS,
    DP,
    DV,
    GYRO_BIAS,
    HGT,
    LAT,
    LON,
    N_NAV,
    PHI,
    QUAT,
    VEL,
)
from estimators.kalman.update import joseph_update
from estimators.nav.rotations import quat_to_mat
from estimators.sins import error_model
from estimators.sins.strapdown import mechanize

N_STATES = ACCEL_BIAS.stop
"""Navigation errors, gyro drift and accelerometer bias: the shared layout up to the IMU biases."""

VELOCITY_SIGMA0 = 0.01
"""Initial sigma of the velocity error [m/s] (the body starts at rest, its velocity known)."""
POSITION_SIGMA0 = 0.1
"""Initial sigma of each position error [m] (the reference point's position is surveyed)."""
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
    p = np.zeros((N_STATES, N_STATES))
    p[PHI, PHI] = np.diag(np.asarray(s.attitude_sigma, float) ** 2)
    p[DV, DV] = np.eye(3) * VELOCITY_SIGMA0 ** 2
    p[DP, DP] = np.eye(3) * POSITION_SIGMA0 ** 2
    p[GYRO_BIAS, GYRO_BIAS] = np.eye(3) * s.gyro_bias_sigma ** 2
    p[ACCEL_BIAS, ACCEL_BIAS] = np.eye(3) * s.accel_bias_sigma ** 2
    hm = np.zeros((3, N_STATES))
    hm[:, DV] = np.eye(3)
    r = np.eye(3) * s.velocity_sigma ** 2
    g = np.zeros((N_STATES, 6))  # white sensor noise (gyro, accelerometer) into phi and dv
    qn = np.diag(np.r_[[s.gyro_noise ** 2 * dt * NOISE_INFLATION] * 3,
                       [s.accel_noise ** 2 * dt * NOISE_INFLATION] * 3])
    nav = np.zeros(N_NAV)
    nav[LAT], nav[LON], nav[HGT], nav[QUAT] = lat, lon, h, q0_nb
    bg, ba = np.zeros(3), np.zeros(3)
    k_out, q_out = [], []
    for k0 in range(0, t.size - chunk, chunk):
        sl = slice(k0, k0 + chunk + 1)
        sol = mechanize(t[sl], dtheta[sl] - bg * step, dv[sl] - ba * step, nav[LAT], nav[LON], nav[HGT], nav[VEL],
                        nav[QUAT], n_samples=SAMPLES_PER_STEP)
        nav[LAT], nav[LON], nav[HGT], nav[VEL], nav[QUAT] = sol.lat[-1], sol.lon[-1], sol.h[-1], sol.v_n[-1], sol.q_nb[-1]
        f = error_model.system_matrix(nav, quat_to_mat(nav[QUAT]) @ (dv[sl][1:].sum(axis=0) / dt - ba))
        phi = np.eye(N_STATES) + f * dt + f @ f * dt * dt / 2
        g[:, :3], g[:, 3:] = f[:, GYRO_BIAS], f[:, ACCEL_BIAS]
        p = phi @ p @ phi.T + g @ qn @ g.T
        x = np.zeros(N_STATES)
        joseph_update(x, p, nav[VEL].copy(), hm, r)  # z: the computed velocity minus the zero of the resting point
        error_model.feed_back_navigation(nav, x)
        bg, ba = bg + x[GYRO_BIAS], ba + x[ACCEL_BIAS]
        k_out.append(k0 + chunk)
        q_out.append(nav[QUAT].copy())
    return np.array(k_out), np.array(q_out)
