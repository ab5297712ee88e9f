"""Linear SINS error model in the local-level ENU frame (psi-angle form; 001 eqs. 12-17 without the sensor and
odometer states, which later filters append).

Error state x = [phi (attitude error of the computed n frame, C_n^n' = I - [phi x]), dv_n (ENU), dlat, dlon, dh]:

    dphi/dt = -w_in x phi + dw_in - C_nb dw_ib
    ddv/dt  = f_n x phi + C_nb df - (2 w_ie + w_en) x dv - (2 dw_ie + dw_en) x v + dg
    dlat/dt = dv_N / (R_M + h) - v_N dh / (R_M + h)^2
    dlon/dt = dv_E / ((R_N + h) cos L) + v_E tan L dlat / ((R_N + h) cos L) - v_E dh / ((R_N + h)^2 cos L)
    dh/dt   = dv_U

with dw_ie = [0, -w sin L dlat, w cos L dlat], dw_en from the errors of the transport rate, and the free-air
gravity error dg_U = 2 g dh / R. The named slices below address the blocks. The filters' 22-state layout
(estimators.kalman.error_state) holds the same navigation error in 001 eq. 12's order (velocity first, position in
ENU metres, the partials of the Earth and transport rates dropped); this model keeps the attitude-first order and the
geodetic position whose partials the Schuler check (stationary_day) needs.
"""

from __future__ import annotations

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import quat_to_mat, skew

PHI = slice(0, 3)
DV = slice(3, 6)
DLAT, DLON, DH = 6, 7, 8
DPOS = slice(6, 9)
N_STATES = 9


def system_matrix(lat: float, h: float, v_n: np.ndarray, f_n: np.ndarray) -> np.ndarray:
    """F (9 x 9) of the error dynamics at one state."""
    r_m, r_n = earth.radii(lat)
    rm, rn = r_m + h, r_n + h
    w = earth.OMEGA_IE
    sl, cl, tl = np.sin(lat), np.cos(lat), np.tan(lat)
    ve, vn, _vu = v_n
    w_ie = earth.earth_rate_n(lat)
    w_en = earth.transport_rate_n(lat, h, v_n)
    # Partial derivatives of w_ie and w_en with respect to (dv, dlat, dh).
    dwie_dlat = np.array([0.0, -w * sl, w * cl])
    dwen_dv = np.array([[0.0, -1.0 / rm, 0.0], [1.0 / rn, 0.0, 0.0], [tl / rn, 0.0, 0.0]])
    dwen_dlat = np.array([0.0, 0.0, ve / (rn * cl ** 2)])
    dwen_dh = np.array([vn / rm ** 2, -ve / rn ** 2, -ve * tl / rn ** 2])
    f = np.zeros((N_STATES, N_STATES))
    f[PHI, PHI] = -skew(w_ie + w_en)
    f[PHI, DV] = dwen_dv
    f[PHI, DLAT] = dwie_dlat + dwen_dlat
    f[PHI, DH] = dwen_dh
    f[DV, PHI] = skew(f_n)
    f[DV, DV] = -skew(2 * w_ie + w_en) + skew(v_n) @ dwen_dv
    f[DV, DLAT] = -np.cross(2 * dwie_dlat + dwen_dlat, v_n)
    f[DV, DH] = -np.cross(dwen_dh, v_n)
    f[DV.start + 2, DH] += 2 * earth.normal_gravity(lat, h) / np.sqrt(rm * rn)
    f[DLAT, DV.start + 1] = 1.0 / rm
    f[DLAT, DH] = -vn / rm ** 2
    f[DLON, DV.start] = 1.0 / (rn * cl)
    f[DLON, DLAT] = ve * tl / (rn * cl)
    f[DLON, DH] = -ve / (rn ** 2 * cl)
    f[DH, DV.start + 2] = 1.0
    return f


def sensor_input(q_nb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """G_gyro, G_accel (9 x 3): how body-frame gyro and accelerometer errors drive the error state."""
    mat_nb = quat_to_mat(q_nb)
    g_gyro = np.zeros((N_STATES, 3))
    g_accel = np.zeros((N_STATES, 3))
    g_gyro[PHI] = -mat_nb
    g_accel[DV] = mat_nb
    return g_gyro, g_accel


def stationary_day(lat: float = np.radians(34.0), hours: float = 24.0, gyro_bias_z: float = np.radians(0.01) / 3600,
                   rate: float = 10.0, step: int = 600) -> dict[str, np.ndarray]:
    """The mechanization (estimators.sins.strapdown, height held) of a level stationary IMU with a z-gyro bias [rad/s]
    beside this linear model (vertical channel removed, the bias a constant augmented state), every `step`
    samples: north, east [m] and attitude error phi (3,) [rad] of each, as `north`, `east`, `phi` and
    `lin_north`, `lin_east`, `lin_phi`. The Schuler (84.4 min) and 24 h oscillations of both must agree."""
    from scipy.linalg import expm

    from estimators.nav.rotations import quat_conj, quat_mul, quat_to_rotvec
    from estimators.sins.strapdown import mechanize

    n = int(hours * 3600 * rate) + 1
    t = np.arange(n) / rate
    gamma = earth.normal_gravity(lat, 0.0)
    dtheta = np.tile((earth.earth_rate_n(lat) + [0.0, 0.0, gyro_bias_z]) / rate, (n, 1))
    dv = np.tile([0.0, 0.0, gamma / rate], (n, 1))
    dtheta[0] = dv[0] = 0.0
    q0 = np.array([1.0, 0.0, 0.0, 0.0])  # level, body y north: b = n
    nav = mechanize(t, dtheta, dv, lat, 0.0, 0.0, np.zeros(3), q0, n_samples=1, hold_height=True)
    r_m, r_n = earth.radii(lat)
    idx = np.arange(0, n, step)
    keep = np.r_[0:5, DLAT, DLON]
    a = np.zeros((8, 8))
    a[:7, :7] = system_matrix(lat, 0.0, np.zeros(3), np.array([0.0, 0.0, gamma]))[np.ix_(keep, keep)]
    a[:7, 7] = (sensor_input(q0)[0] @ [0.0, 0.0, gyro_bias_z])[keep]
    transition = expm(a * step / rate)
    lin = np.zeros((idx.size, 8))
    lin[0, 7] = 1.0
    for k in range(1, idx.size):
        lin[k] = transition @ lin[k - 1]
    return {"north": (nav.lat[idx] - lat) * r_m, "east": nav.lon[idx] * r_n * np.cos(lat),
            "phi": -quat_to_rotvec(quat_mul(nav.q_nb[idx], quat_conj(q0))),  # C_n^n' = I - [phi x]
            "lin_north": lin[:, 5] * r_m, "lin_east": lin[:, 6] * r_n * np.cos(lat), "lin_phi": lin[:, PHI]}

