"""The RTS smoother against filterpy's on a discretized linear model (the issue asks for 1e-9)."""

import os

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from estimators.kalman.rts import StoredInterval, rts_smooth, rts_stored


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


def _closed_loop_interval(rng, n=5, steps=300):
    """A closed-loop error-state interval's smoother inputs (zero prediction): updates, posterior and predicted
    covariances and transitions of a filter with a measurement every third step."""
    f_c = rng.normal(0, 0.3, (n, n)) - np.eye(n)
    q, h, r = np.diag(rng.uniform(1e-4, 1e-2, n)), rng.normal(size=(2, n)), np.diag([0.05, 0.2])
    p = np.eye(n)
    x_post, p_post = np.zeros((steps, n)), np.zeros((steps, n, n))
    p_pred, phi = np.zeros((steps, n, n)), np.zeros((steps, n, n))
    p_post[0], p_pred[0], phi[0] = p, p, np.eye(n)
    for k in range(1, steps):
        phi[k] = np.eye(n) + f_c * 0.1 * (1 + 0.1 * np.sin(k))
        p = phi[k] @ p @ phi[k].T + q
        p_pred[k] = p
        if k % 3 == 0:
            gain = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
            x_post[k] = gain @ rng.normal(size=2)
            p = (np.eye(n) - gain @ h) @ p
            p = 0.5 * (p + p.T)
        p_post[k] = p
    return x_post, p_post, p_pred, phi


@pytest.mark.parametrize("block", [1, 7, 299, 1000])  # rows of each block read back
@pytest.mark.parametrize("with_known", [False, True])
def test_stored_interval_smoothed_in_blocks_equals_the_whole_backward_pass_bit_for_bit(block, with_known):
    rng = np.random.default_rng(11)
    x_post, p_post, p_pred, phi = _closed_loop_interval(rng)
    n_rows, n = x_post.shape
    known = (rng.normal(size=n) * 0.01, p_post[-1] * 0.5) if with_known else None
    stored = StoredInterval(n)
    stored.append(*(np.full((500, n, n), np.nan),) * 3)  # an earlier interval's rows, written over
    stored.restart()
    for r0 in range(0, n_rows, 64):  # appended in blocks other than the ones read back
        stored.append(p_post[r0:r0 + 64], p_pred[r0:r0 + 64], phi[r0:r0 + 64])
    stored.close()
    blocks = tuple(np.full((block + 1, n, n), np.nan) for _ in range(3))
    x_s, sd, p_keep, p_first = rts_stored(stored, x_post, blocks, known, keep=slice(1, 3))

    x_run, p_whole = x_post.copy(), p_post.copy()
    if known is not None:
        x_run[-1], p_whole[-1] = known
    x_ref, p_ref = rts_smooth(x_run, p_whole, np.zeros_like(x_post), p_pred, phi)
    assert np.array_equal(x_s, x_ref)
    assert np.array_equal(sd, np.sqrt(np.diagonal(p_ref, axis1=1, axis2=2)))
    assert np.array_equal(p_keep, p_ref[:, 1:3, 1:3])
    assert np.array_equal(p_first, p_ref[0])
    assert np.trace(p_ref[0]) < np.trace(p_post[0]) - 1e-3  # the smoother changed something


def test_stored_interval_removes_its_files_and_refuses_a_mismatched_interval(tmp_path):
    stored = StoredInterval(3, tmp_path)
    stored.append(*(np.zeros((4, 3, 3)),) * 3)
    stored.close()
    with pytest.raises(ValueError, match="4 stored epochs for 5 updates"):
        rts_stored(stored, np.zeros((5, 3)), tuple(np.zeros((9, 3, 3)) for _ in range(3)))
    assert sorted(os.listdir(tmp_path)) == sorted(os.path.basename(p) for p in stored.paths) and len(stored.paths) == 3
    del stored
    assert os.listdir(tmp_path) == []


def test_an_unnamed_stored_interval_leaves_no_file_however_the_process_ends():
    stored = StoredInterval(3)
    stored.append(*(np.ones((2, 3, 3)),) * 3)
    assert stored.paths is None
    assert all(os.fstat(fd).st_nlink == 0 for fd in stored._fds)  # unlinked while open
    assert np.array_equal(stored.read_into(0, 2, tuple(np.zeros((2, 3, 3)) for _ in range(3)))[2], np.ones((2, 3, 3)))
