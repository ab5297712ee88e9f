"""Linear SINS error model in the local-level ENU frame (psi-angle form; 001 eqs. 12-17), on the shared layout of
estimators.kalman.error_state: the navigation block (DV, PHI, DP) of F, the IMU-bias blocks, and the feedback of a
navigation error estimate. The 001 filter (estimators.shearer.odometer_filter), the 000 section 6.4 loop
(estimators.sins.lever_arm_filter) and the Schuler check below use it.

Navigation error (estimate - truth): dv_n (ENU), phi (C_b^n' = (I - [phi x]) C_b^n), dp (ENU metres):

    d(dv)/dt  = f_n x phi - (2 w_ie + w_en) x dv - (2 dw_ie + dw_en) x v + dg + C_b^n nabla
    d(phi)/dt = -(w_ie + w_en) x phi + dw_ie + dw_en - C_b^n eps
    d(dp)/dt  = dv + (position-rate terms below)

with the free-air gravity error dg_U = 2 g dp_U / R. The Earth- and transport-rate errors dw_ie, dw_en and the
position-rate terms are the partials of 001 eqs. 13-16 in (dv, dlat, dh), taken to ENU metres by 001 eq. 7's
diagonal C (dlat = dp_N / (R_M + h), dlon = dp_E / ((R_N + h) cos L), dh = dp_U) with its rate:

    d(dp_E)/dt = dv_E + v_E tan L dp_N / (R_M + h) - v_E dp_U / (R_N + h) + (v_U / (R_N + h) - v_N tan L / (R_M + h)) dp_E
    d(dp_N)/dt = dv_N - v_N dp_U / (R_M + h) + v_U dp_N / (R_M + h)

(the radii's own rates, of order e^2 v / R, dropped). `earth_partials=False` leaves all of them out, as the 001
filter does: at a shearer's speed they are below 1e-9 of the kept terms.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.arrays import add, put, sub
from estimators.kalman.error_state import (
    ACCEL_BIAS,
    DP,
    DV,
    GYRO_BIAS,
    HGT,
    LAT,
    LON,
    PHI,
    QUAT,
    VEL,
)
from estimators.nav import earth
from estimators.nav.earth import gravity_nb, nav_rates, radii_nb
from estimators.nav.rotations import cross3, qexp, qmul, quat_mat, skew3

N_NAV_ERRORS = DP.stop
"""The navigation error states (DV, PHI, DP), the first blocks of the layout."""
_E, _N, _U = 0, 1, 2


@nb.njit(cache=True)
def navigation_block(f, nav, f_n):
    """Write F's navigation block (rows and columns DV, PHI, DP) at the navigation state `nav`
    (estimators.kalman.error_state's LAT .. QUAT) with specific force f_n (ENU) into f (in place), without the
    Earth- and transport-rate partials (earth_partial_blocks adds them)."""
    lat, h = nav[LAT], nav[HGT]
    v = nav[VEL]
    w_ie, w_en = nav_rates(lat, h, v)
    r_m, r_n = radii_nb(lat)
    put(f[DV, DV], -skew3(2 * w_ie + w_en))
    put(f[DV, PHI], skew3(f_n))
    f[DV.start + _U, DP.start + _U] = 2 * gravity_nb(lat, h) / np.sqrt((r_m + h) * (r_n + h))
    put(f[PHI, PHI], -skew3(w_ie + w_en))
    for i in range(3):
        f[DP.start + i, DV.start + i] = 1.0


@nb.njit(cache=True)
def earth_partial_blocks(f, nav):
    """Add the Earth- and transport-rate partials and the position-rate terms (module docstring) to F's navigation
    block written by navigation_block (in place). A kernel of its own, so that the filters, which leave them out,
    do not compile them."""
    lat, h = nav[LAT], nav[HGT]
    v = nav[VEL]
    r_m, r_n = radii_nb(lat)
    rm, rn = r_m + h, r_n + h
    sl, cl, tl = np.sin(lat), np.cos(lat), np.tan(lat)
    ve, vn, vu = v[_E], v[_N], v[_U]
    # Partials of w_ie and w_en in dv, in dp_N (through dlat = dp_N / rm) and in dp_U (= dh).
    dwen_dv = np.array([[0.0, -1.0 / rm, 0.0], [1.0 / rn, 0.0, 0.0], [tl / rn, 0.0, 0.0]])
    dwie_dpn = np.array([0.0, -earth.OMEGA_IE * sl, earth.OMEGA_IE * cl]) / rm
    dwen_dpn = np.array([0.0, 0.0, ve / (rn * cl ** 2)]) / rm
    dwen_dpu = np.array([vn / rm ** 2, -ve / rn ** 2, -ve * tl / rn ** 2])
    put(f[PHI, DV], dwen_dv)
    put(f[PHI, DP.start + _N], dwie_dpn + dwen_dpn)
    put(f[PHI, DP.start + _U], dwen_dpu)
    add(f[DV, DV], skew3(v) @ dwen_dv)
    put(f[DV, DP.start + _N], -cross3(2 * dwie_dpn + dwen_dpn, v))
    sub(f[DV, DP.start + _U], cross3(dwen_dpu, v))
    f[DP.start + _E, DP.start + _E] = vu / rn - vn * tl / rm
    f[DP.start + _E, DP.start + _N] = ve * tl / rm
    f[DP.start + _E, DP.start + _U] = -ve / rn
    f[DP.start + _N, DP.start + _N] = vu / rm
    f[DP.start + _N, DP.start + _U] = -vn / rm


@nb.njit(cache=True)
def bias_blocks(f, c_nb):
    """Write how the gyro bias eps and accelerometer bias nabla (body axes) drive phi and dv into f (in place)."""
    put(f[DV, ACCEL_BIAS], c_nb)
    put(f[PHI, GYRO_BIAS], -c_nb)


@nb.njit(cache=True)
def feed_back_navigation(nav, x):
    """Correct the navigation state (in place) by the error estimate x (estimate - truth)."""
    lat, h = nav[LAT], nav[HGT]
    r_m, r_n = radii_nb(lat)
    nav[LAT] -= x[DP.start + _N] / (r_m + h)
    nav[LON] -= x[DP.start + _E] / ((r_n + h) * np.cos(lat))
    nav[HGT] -= x[DP.start + _U]
    sub(nav[VEL], x[DV])
    q = qmul(qexp(x[PHI]), nav[QUAT])
    put(nav[QUAT], q / np.sqrt(np.sum(q * q)))


def system_matrix(nav: np.ndarray, f_n: np.ndarray, earth_partials: bool = True) -> np.ndarray:
    """F (N_NAV_ERRORS + the two bias blocks, i.e. ACCEL_BIAS.stop square) at one navigation state."""
    f = np.zeros((ACCEL_BIAS.stop, ACCEL_BIAS.stop))
    nav = np.asarray(nav, float)
    navigation_block(f, nav, np.asarray(f_n, float))
    if earth_partials:
        earth_partial_blocks(f, nav)
    bias_blocks(f, quat_mat(nav[QUAT]))
    return f


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
    idx = np.arange(0, n, step)
    keep = horizontal_channels()
    f = system_matrix(np.r_[lat, 0.0, 0.0, np.zeros(3), q0], np.array([0.0, 0.0, gamma]))
    a = np.zeros((keep.size + 1, keep.size + 1))
    a[:-1, :-1] = f[np.ix_(keep, keep)]
    a[:-1, -1] = (f[:, GYRO_BIAS] @ [0.0, 0.0, gyro_bias_z])[keep]
    transition = expm(a * step / rate)
    lin = np.zeros((idx.size, keep.size + 1))
    lin[0, -1] = 1.0
    for k in range(1, idx.size):
        lin[k] = transition @ lin[k - 1]
    lin_full = np.zeros((idx.size, N_NAV_ERRORS))
    lin_full[:, keep] = lin[:, :-1]
    r_m, r_n = earth.radii(lat)
    return {"north": (nav.lat[idx] - lat) * r_m, "east": nav.lon[idx] * r_n * np.cos(lat),
            "phi": -quat_to_rotvec(quat_mul(nav.q_nb[idx], quat_conj(q0))),  # C_n^n' = I - [phi x]
            "lin_north": lin_full[:, DP.start + _N], "lin_east": lin_full[:, DP.start + _E],
            "lin_phi": lin_full[:, PHI]}


def horizontal_channels() -> np.ndarray:
    """Indices of the navigation errors without the vertical channel (dv_U, dp_U): the Schuler loop's states."""
    return np.r_[DV.start + _E, DV.start + _N, PHI.start:PHI.stop, DP.start + _E, DP.start + _N]
