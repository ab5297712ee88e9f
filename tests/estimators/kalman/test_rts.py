"""The RTS smoother against filterpy's on a discretized linear model (the issue asks for 1e-9)."""

import numpy as np
from filterpy.kalman import KalmanFilter

from estimators.kalman.rts import rts_smooth


def test_rts_equals_filterpy_on_a_linear_model():
    rng = np.random.default_rng(3)
    n, m, steps, dt = 6, 2, 400, 0.1
    f_c = rng.normal(0, 0.3, (n, n)) - np.eye(n)
    phi = np.eye(n) + f_c * dt + (f_c * dt) @ (f_c * dt) / 2
    q = np.diag(rng.uniform(1e-4, 1e-2, n))
    h = rng.normal(size=(m, n))
    r = np.diag([0.05, 0.2])
    kf = KalmanFilter(dim_x=n, dim_z=m)
    kf.F, kf.Q, kf.H, kf.R = phi, q, h, r
    kf.x, kf.P = np.zeros(n), np.eye(n)
    x_true = rng.normal(size=n)
    zs = []
    for _ in range(steps):
        x_true = phi @ x_true + rng.multivariate_normal(np.zeros(n), q)
        zs.append(h @ x_true + rng.multivariate_normal(np.zeros(m), r))
    xs, ps, _, _ = kf.batch_filter(np.array(zs))
    x_ref, p_ref, _, _ = kf.rts_smoother(xs, ps, Fs=[phi] * steps, Qs=[q] * steps)
    x_pred = np.einsum("ij,kj->ki", phi, xs)
    p_pred = np.einsum("ij,kjl,ml->kim", phi, ps, phi) + q
    # Row k+1 of the predictions is the step k -> k+1.
    x_pred = np.concatenate([np.zeros((1, n)), x_pred[:-1]])
    p_pred = np.concatenate([np.eye(n)[None], p_pred[:-1]])
    x_s, p_s = rts_smooth(xs, ps, x_pred, p_pred, np.broadcast_to(phi, (steps, n, n)))
    assert np.abs(x_s - x_ref).max() < 1e-9
    assert np.abs(p_s - p_ref).max() < 1e-9
    # Smoothing must change something: the smoothed covariance is smaller than the filtered one.
    assert np.trace(p_s[0]) < np.trace(ps[0]) - 1e-3
