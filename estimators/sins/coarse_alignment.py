"""Coarse alignment of a stationary IMU (000 eqs. 6-8, in the double-vector form).

At rest the accelerometers sense the specific force f = -g (up in n) and the gyros the Earth rate
w_ie = [0, W cos L, W sin L] (n). From their means over the window, the n axes in the body frame are

    up_b    = f_b / |f_b|
    east_b  = (w_b x up_b) / |w_b x up_b|
    north_b = up_b x east_b

and C_n^b = [east_b north_b up_b]. Level is limited by the accelerometer bias (bias / g) and heading by the
east gyro bias (bias / (W cos L)), the gyrocompassing floor. Before trusting the result the data are checked
for motion: the mean specific force must be gravity within STATIONARY_GRAVITY_TOL and the samples must not
spread more than the sensor noise allows; a moving shearer raises `AlignmentError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import mat_to_quat, quat_to_euler

STATIONARY_GRAVITY_TOL = 0.005
"""Relative tolerance of |mean specific force| against normal gravity for a stationary window."""
STATIONARY_ACCEL_SPREAD = 0.05
"""Largest standard deviation of the specific force [m/s^2] (over 0.1 s means) of a stationary window."""


class AlignmentError(ValueError):
    """The data cannot give an alignment (moving, too short, not finite); the message says which."""


@dataclass(frozen=True)
class Alignment:
    q_nb: np.ndarray
    pitch: float
    roll: float
    yaw: float
    f_b: np.ndarray  # mean specific force [m/s^2]
    w_b: np.ndarray  # mean angular rate [rad/s]


def coarse_align(dtheta: np.ndarray, dv: np.ndarray, dt: float, lat: float, h: float = 0.0) -> Alignment:
    """Attitude of a stationary IMU from increments over a window (rows over equal intervals dt)."""
    dtheta, dv = np.asarray(dtheta, float), np.asarray(dv, float)
    if dtheta.shape != dv.shape or dtheta.ndim != 2 or dtheta.shape[1] != 3:
        raise AlignmentError(f"increments must be two (N, 3) arrays; got {dtheta.shape} and {dv.shape}")
    if dtheta.shape[0] < 10:
        raise AlignmentError(f"{dtheta.shape[0]} samples are too few for an alignment (need >= 10)")
    bad = np.flatnonzero(~(np.isfinite(dtheta).all(axis=1) & np.isfinite(dv).all(axis=1)))
    if bad.size:
        raise AlignmentError(f"increment row {bad[0]} is not finite")
    earth.check_latitude(lat)
    span = dtheta.shape[0] * dt
    f_b, w_b = dv.sum(axis=0) / span, dtheta.sum(axis=0) / span
    gamma = earth.normal_gravity(lat, h)
    if abs(np.linalg.norm(f_b) / gamma - 1) > STATIONARY_GRAVITY_TOL:
        raise AlignmentError(f"mean specific force {np.linalg.norm(f_b):.4f} m/s^2 is not gravity "
                             f"{gamma:.4f} m/s^2: the IMU moves during the alignment window")
    block = max(1, int(round(0.1 / dt)))
    n_blocks = dv.shape[0] // block
    if n_blocks >= 2:
        means = dv[: n_blocks * block].reshape(n_blocks, block, 3).sum(axis=1) / (block * dt)
        spread = means.std(axis=0).max()
        if spread > STATIONARY_ACCEL_SPREAD:
            raise AlignmentError(f"specific force spreads {spread:.3f} m/s^2 (0.1 s means) over the window: the "
                                 f"IMU moves or vibrates; align while the shearer stands")
    up = f_b / np.linalg.norm(f_b)
    east = np.cross(w_b, up)
    if np.linalg.norm(east) < 1e-3 * earth.OMEGA_IE:
        raise AlignmentError("the Earth rate is not resolved (at a pole, or gyro errors swamp it)")
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    mat_bn = np.column_stack([east, north, up])  # columns: n axes in b
    q_nb = mat_to_quat(mat_bn.T)
    pitch, roll, yaw = quat_to_euler(q_nb)
    return Alignment(q_nb, float(pitch), float(roll), float(yaw), f_b, w_b)


def level_limit(accel_bias: float, lat: float, h: float = 0.0) -> float:
    """Physical limit of the level (pitch, roll) error [rad]: accelerometer bias / g."""
    return accel_bias / earth.normal_gravity(lat, h)


def heading_limit(east_gyro_bias: float, lat: float) -> float:
    """Gyrocompassing floor of the heading error [rad]: east gyro bias / (Earth rate cos L)."""
    return east_gyro_bias / (earth.OMEGA_IE * np.cos(lat))
