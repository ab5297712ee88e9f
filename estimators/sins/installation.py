"""Installation errors of the shearer's IMU: mounting misalignment and lever arm (000 section 6).

Frames: b the shearer body (DESIGN: x towards the coal wall, y along the face, z up), s the IMU's sensor
frame (the paper's "f" frame, the installation base), n ENU. The mounting matrix is C_s^b = M =
Rz(dyaw) Rx(dpitch) Ry(droll) in the project's Euler order (estimators.nav.rotations.euler_to_mat), so a vector
sensed in s is v^s = M^T v^b (the paper's eq. 31 with C_b^f = M^T).

Mounting (000 6.1-6.2)
----------------------
At rest the accelerometers sense f = -g, i.e. +gamma along Up. With the body level the sensed specific force
is f^s = gamma M^T e_z = gamma [-sin(droll) cos(dpitch), sin(dpitch), cos(droll) cos(dpitch)], hence the
paper's geometric relations (figures 9-10, written in the DESIGN axes where pitch turns about x and roll
about y):

    tan(dpitch) = f_y / sqrt(f_x^2 + f_z^2),        tan(droll) = -f_x / f_z.

The heading deviation dyaw does not change where gravity appears in a levelled sensor and is unobservable
from one attitude (as the paper says). With several known body attitudes C_b^n,k the model
f^s_k = gamma M^T C_n^b,k e_z (+ b_a) is solved by Gauss-Newton for (dpitch, droll) and, when the attitudes
make them observable, dyaw and the accelerometer bias b_a (`mounting_calibration`). Without estimating the
bias, the tilt estimate errs by about |b_a,horizontal| / gamma: the bias-limited accuracy. The resulting
sensing errors of an uncorrected mounting are eqs. 32-34 (`mounting_error_specific_force`).

Lever arm (000 6.3)
-------------------
A sensor at r_p (b) from the body reference point senses, on top of the body's specific force (eqs. 35-41),

    delta_a = dw/dt x r_p + w x (w x r_p) = Q r_p,     Q = [dw/dt x] + [w x]^2      (eqs. 43-44)

with w = w_ib^b. `lever_arm_acceleration` evaluates it from rate samples, `estimate_lever_arm` solves eq. 45
(two epochs; more epochs by least squares), and `lever_arm_dv_two_sample` / `compensate_lever_arm` give the
velocity-increment form from two gyro increments (eqs. 46-53): the rate over a pair of samples (T = 2h) is
fitted as w(tau) = a + 2 b tau (eq. 48) from dtheta_1, dtheta_2 (eqs. 49-51), which gives

    a T = 3 dtheta_1 - dtheta_2,       2 b T^2 = 4 (dtheta_2 - dtheta_1),

and the lever-arm velocity increment of a sub-interval [tau0, tau1] of the pair is the integral of
(2b) x r + w(tau) x (w(tau) x r) over it. The paper's printed eq. 52 keeps the terms of this integral over the
whole pair only up to a truncated Taylor series (eq. 47) and with an unspecified factor 1/delta; here the
integral of the linear fit is taken exactly (it contains eq. 52's terms (4 (dtheta_2 - dtheta_1) / T) x r_p
and (3 dtheta_1 - dtheta_2) x ((3 dtheta_1 - dtheta_2) x r_p) / T as its leading parts), split over the
two samples so the per-sample increments stay usable for sculling compensation. Eq. 53 then subtracts it:
dv_0 = dv_i - dv_lever.
"""

from __future__ import annotations

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import euler_to_mat, skew

__all__ = [
    "compensate_lever_arm",
    "estimate_lever_arm",
    "lever_arm_acceleration",
    "lever_arm_dv_two_sample",
    "lever_arm_q",
    "local_gravity",
    "mounting_calibration",
    "mounting_error_specific_force",
    "tilt_from_specific_force",
]


# --------------------------------------------------------------------------------------------- mounting


def tilt_from_specific_force(f_s):
    """(dpitch, droll) [rad] of the sensor relative to a level body from its mean specific force f_s (..., 3).

    000 section 6.1 (figures 9-10) in the DESIGN axes: tan dpitch = f_y / sqrt(f_x^2 + f_z^2),
    tan droll = -f_x / f_z (pitch about x, roll about y; C_s^b = Rx(dpitch) Ry(droll) when dyaw = 0)."""
    f = np.asarray(f_s, float)
    return np.arctan2(f[..., 1], np.hypot(f[..., 0], f[..., 2])), np.arctan2(-f[..., 0], f[..., 2])


def _model(x, up_b, gamma, fit_yaw, fit_bias):
    """Predicted f^s (K, 3) and its Jacobian (K, 3, n) for the parameters x = [dpitch, droll, (dyaw), (b)]."""
    p, r = x[0], x[1]
    y = x[2] if fit_yaw else 0.0
    m = euler_to_mat(p, r, y)
    pred = gamma * up_b @ m  # rows: (M^T up_b)^T = up_b^T M
    if fit_bias:
        pred = pred + x[-3:]
    cols = []
    eps = 1e-7
    for i in range(2 + int(fit_yaw)):
        dx = np.zeros(3)
        dx[i] = eps
        ang = np.array([p, r, y]) + dx
        mp = euler_to_mat(*ang)
        ang = np.array([p, r, y]) - dx
        mm = euler_to_mat(*ang)
        cols.append(gamma * up_b @ (mp - mm) / (2 * eps))
    jac = np.stack(cols, axis=-1)
    if fit_bias:
        jac = np.concatenate([jac, np.broadcast_to(np.eye(3), (up_b.shape[0], 3, 3))], axis=-1)
    return pred, jac


def mounting_calibration(f_s_mean, c_nb=None, gamma=None, fit_yaw: bool = False, fit_bias: bool = False,
                         iterations: int = 20) -> dict:
    """Static mounting calibration (000 eqs. 31-34, section 6.1) from stationary accelerometer means.

    f_s_mean (K, 3) or (3,): mean specific force [m/s^2] in the sensor frame at K stationary positions;
    c_nb (K, 3, 3): the known body attitudes C_b^n at them (None: the body level, C_b^n = I); gamma: local
    gravity [m/s^2] (None: the mean of |f_s_mean|). Model (eq. 31 with the stationary f^b = C_n^b gamma e_z):

        f^s_k = gamma M^T C_n^b,k e_z (+ b_a),   M = C_s^b = Rz(dyaw) Rx(dpitch) Ry(droll).

    One level position gives the paper's closed form (`tilt_from_specific_force`); otherwise Gauss-Newton
    from it. `fit_yaw` adds dyaw, `fit_bias` the accelerometer bias b_a; both need attitudes whose Up
    directions in b span enough (the heading deviation needs >= 2 distinct tilts, the bias with pitch and
    roll >= 3 positions); an unobservable set raises ValueError. Without `fit_bias` a bias b_a tilts the
    result by about |b_a x e_z| / gamma (the bias-limited accuracy).

    Returns dict: pitch, roll, yaw [rad] (yaw 0 unless fitted), bias (3,) (zeros unless fitted), mat_sb
    (= M, C_s^b), residual (K, 3) [m/s^2].
    """
    f = np.atleast_2d(np.asarray(f_s_mean, float))
    k = f.shape[0]
    if f.shape[1] != 3 or not np.all(np.isfinite(f)):
        raise ValueError(f"f_s_mean must be finite (K, 3); got shape {f.shape}")
    if c_nb is None:
        c = np.broadcast_to(np.eye(3), (k, 3, 3))
    else:
        c = np.asarray(c_nb, float).reshape(-1, 3, 3)
        if c.shape[0] != k:
            raise ValueError(f"c_nb has {c.shape[0]} attitudes for {k} specific-force means")
    up_b = c[:, 2, :]  # C_n^b e_z = third row of C_b^n
    g = float(np.mean(np.linalg.norm(f, axis=1))) if gamma is None else float(gamma)
    # Start: the closed form of the first position's sensor tilt minus its body tilt (exact when level).
    sp, sr = tilt_from_specific_force(f[0])
    bp, br = tilt_from_specific_force(up_b[0])
    n_par = 2 + int(fit_yaw) + 3 * int(fit_bias)
    x = np.zeros(n_par)
    x[0], x[1] = sp - bp, sr - br
    if c_nb is None and k == 1 and not fit_yaw and not fit_bias:
        pred, _ = _model(x, up_b, g, False, False)
        return {"pitch": float(x[0]), "roll": float(x[1]), "yaw": 0.0, "bias": np.zeros(3),
                "mat_sb": euler_to_mat(x[0], x[1], 0.0), "residual": f - pred}
    for _ in range(iterations):
        pred, jac = _model(x, up_b, g, fit_yaw, fit_bias)
        a = jac.reshape(3 * k, n_par)
        s = np.linalg.svd(a, compute_uv=False)
        if s.size < n_par or s[-1] < 1e-6 * s[0]:
            raise ValueError("the attitudes do not make the requested mounting parameters observable "
                             "(add positions with different tilts, or fit fewer parameters)")
        step = np.linalg.lstsq(a, (f - pred).ravel(), rcond=None)[0]
        x = x + step
        if np.max(np.abs(step)) < 1e-14:
            break
    pred, _ = _model(x, up_b, g, fit_yaw, fit_bias)
    yaw = float(x[2]) if fit_yaw else 0.0
    return {"pitch": float(x[0]), "roll": float(x[1]), "yaw": yaw,
            "bias": x[-3:].copy() if fit_bias else np.zeros(3),
            "mat_sb": euler_to_mat(x[0], x[1], yaw), "residual": f - pred}


def mounting_error_specific_force(mat_sb, f_b, c_sn=None):
    """Sensing error of an uncorrected mounting (000 eqs. 31-34): delta f^s = (I - C_b^s) f^b (eq. 32, with
    C_b^s = mat_sb^T the paper's C_b^f) for f^b (..., 3); with c_sn (..., 3, 3) = C_s^n also resolved in n
    (eq. 33). The same expression with w_ib^b instead of f^b is the gyro error (eq. 34)."""
    m = np.asarray(mat_sb, float)
    fb = np.asarray(f_b, float)
    df = fb - fb @ m  # (I - M^T) f^b, row-vector form
    if c_sn is None:
        return df
    return np.einsum("...ij,...j->...i", np.asarray(c_sn, float), df)


# --------------------------------------------------------------------------------------------- lever arm


def lever_arm_q(w_ib_b, w_dot_b):
    """Q = [dw/dt x] + [w x][w x] (000 eqs. 43-44), (..., 3, 3), so that delta_a^b = Q r_p."""
    sw = skew(w_ib_b)
    return skew(w_dot_b) + sw @ sw


def lever_arm_acceleration(w_ib_b, w_dot_b, r_p):
    """delta_a^b = dw/dt x r_p + w x (w x r_p) (000 eqs. 35, 41, 43) for rate samples (..., 3)."""
    w = np.asarray(w_ib_b, float)
    r = np.broadcast_to(np.asarray(r_p, float), w.shape)
    return np.cross(w_dot_b, r) + np.cross(w, np.cross(w, r))


def estimate_lever_arm(c_nb, a_b, w_ib_b, w_dot_b):
    """r_p [m] (3,) from the accelerometer outputs a_b (K, 3) of a stationary (pivoting) shearer at K >= 2
    epochs with attitudes c_nb (K, 3, 3) = C_b^n, rates w_ib_b and rate derivatives w_dot_b (K, 3).

    With a^b = C_n^b g^n + Q r_p (eq. 42-44) and g^n the same at the epochs, two epochs give eq. 45:

        r_p = (C_b1^n Q_1 - C_b2^n Q_2)^-1 (C_b1^n a_1^b - C_b2^n a_2^b).

    K > 2 epochs: the least-squares solution of the same equations for all epochs against their mean
    (g^n eliminated). Raises ValueError when the system is singular (too little rotation)."""
    c = np.asarray(c_nb, float).reshape(-1, 3, 3)
    a = np.asarray(a_b, float).reshape(-1, 3)
    q = lever_arm_q(np.asarray(w_ib_b, float).reshape(-1, 3), np.asarray(w_dot_b, float).reshape(-1, 3))
    cq = c @ q
    ca = np.einsum("kij,kj->ki", c, a)
    if c.shape[0] < 2:
        raise ValueError("the lever arm needs at least two epochs (eq. 45)")
    if c.shape[0] == 2:
        mat, rhs = cq[0] - cq[1], ca[0] - ca[1]
    else:
        mat = (cq - cq.mean(axis=0)).reshape(-1, 3)
        rhs = (ca - ca.mean(axis=0)).ravel()
    s = np.linalg.svd(mat, compute_uv=False)
    if s[-1] < 1e-9 * max(s[0], 1e-300):
        raise ValueError("the epochs do not determine the lever arm (C1 Q1 - C2 Q2 is singular)")
    if c.shape[0] == 2:
        return np.linalg.solve(mat, rhs)
    return np.linalg.lstsq(mat, rhs, rcond=None)[0]


def _segment(a, c, r, t0, t1):
    """Integral over [t0, t1] of c x r + (a + c t) x ((a + c t) x r), rows broadcast (a, c (U, 3))."""
    i0, i1, i2 = t1 - t0, 0.5 * (t1 ** 2 - t0 ** 2), (t1 ** 3 - t0 ** 3) / 3.0
    ar, cr = np.cross(a, r), np.cross(c, r)
    return (i0 * cr + i0 * np.cross(a, ar) + i1 * (np.cross(a, cr) + np.cross(c, ar))
            + i2 * np.cross(c, cr))


def lever_arm_dv_two_sample(dtheta1, dtheta2, r_p, h: float, split: bool = False):
    """Lever-arm velocity increment of sample pairs from two gyro increments (000 eqs. 46-52).

    dtheta1, dtheta2 (U, 3): the increments over [0, h] and [h, 2h] of each pair (T = 2h). The linear fit
    w(tau) = a + 2 b tau (eq. 48) of eqs. 49-51 gives a = (3 dtheta1 - dtheta2) / T and
    2b = 4 (dtheta2 - dtheta1) / T^2; the increment is the integral of 2b x r_p + w x (w x r_p). Returns the
    (U, 3) increment over the pair, or with `split` the two (U, 3) increments over its two samples."""
    th1, th2 = np.atleast_2d(np.asarray(dtheta1, float)), np.atleast_2d(np.asarray(dtheta2, float))
    r = np.asarray(r_p, float)
    big_t = 2.0 * h
    a = (3.0 * th1 - th2) / big_t
    c = 4.0 * (th2 - th1) / big_t ** 2
    if split:
        return _segment(a, c, r, 0.0, h), _segment(a, c, r, h, big_t)
    return _segment(a, c, r, 0.0, big_t)


def compensate_lever_arm(dtheta, dv, r_p, h: float | None = None, t=None):
    """Eq. 53: dv_0 = dv_i - dv_lever, the increments of the body reference point from those of a sensor at
    r_p [m] in b (rows k over (t[k-1], t[k]]; row 0 unused, as in estimators.sins.strapdown.mechanize).

    Rows 1..K-1 are taken in pairs (1, 2), (3, 4), ... and each pair's two-sample fit (eqs. 48-52,
    `lever_arm_dv_two_sample`) gives both of its rows' lever-arm increments; an odd last row uses the fit of
    itself and its predecessor. h is the sample interval (or from t). Returns dv_0 (K, 3).

    Accuracy: over each pair the lever-arm increment is right to O(T^2) (the linear rate fit); its split over
    the pair's two samples is right only to O(|w| h) relative, because the rate derivative is taken constant
    over the pair. Mechanize with an even number of samples per update (n_samples = 2, 4, ...) so the
    updates see whole pairs."""
    dtheta = np.asarray(dtheta, float)
    dv = np.asarray(dv, float)
    if dtheta.shape != dv.shape or dtheta.ndim != 2 or dtheta.shape[1] != 3:
        raise ValueError(f"dtheta and dv must be (K, 3) alike; got {dtheta.shape} and {dv.shape}")
    if h is None:
        if t is None:
            raise ValueError("give the sample interval h or the times t")
        h = float(np.median(np.diff(np.asarray(t, float))))
    out = dv.copy()
    n = dv.shape[0] - 1
    u = n // 2
    if u:
        th = dtheta[1:1 + 2 * u].reshape(u, 2, 3)
        d1, d2 = lever_arm_dv_two_sample(th[:, 0], th[:, 1], r_p, h, split=True)
        lever = np.stack([d1, d2], axis=1).reshape(2 * u, 3)
        out[1:1 + 2 * u] -= lever
    if n % 2 and n >= 2:
        _, d2 = lever_arm_dv_two_sample(dtheta[n - 1], dtheta[n], r_p, h, split=True)
        out[n] -= d2[0]
    elif n == 1:
        # One increment only: the rate taken constant over it (no derivative information).
        w = dtheta[1] / h
        out[1] -= h * np.cross(w, np.cross(w, np.asarray(r_p, float)))
    return out


def local_gravity(lat: float, h: float) -> float:
    """Normal gravity [m/s^2] for the `gamma` of `mounting_calibration` (estimators.nav.earth)."""
    return float(earth.normal_gravity(lat, h))
