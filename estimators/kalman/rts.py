"""Rauch-Tung-Striebel fixed-interval smoother (001 eqs. 28-31), the backward pass as a numba kernel.

Forward filtering stores, at every epoch k of the interval, the posterior x_k, P_k, the prediction x_{k+1,k},
P_{k+1,k} and the transition Phi_{k+1,k}; the backward pass starts from the last posterior (eq. 29) and runs

    A_k      = P_k Phi_{k+1,k}^T P_{k+1,k}^-1                      (eq. 31)
    x_rts,k  = x_k + A_k (x_rts,k+1 - x_{k+1,k})                    (eq. 30)
    P_rts,k  = P_k + A_k (P_rts,k+1 - P_{k+1,k}) A_k^T

For a closed-loop error-state filter (estimators.shearer.odometer_filter) the prediction is zero after every reset and x_k is
the update fed back at k, so x_rts,k is the smoothed error relative to the prior solution at k and
x_rts,k - x_k the correction to apply to the posterior solution at k.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.arrays import put
from estimators.kalman.lapack import solve_matrix


@nb.njit(cache=True)
def rts_backward(x_post, p_post, x_pred, p_pred, phi, x_s, p_s):
    """Smooth epochs 0..N-1 in place into (x_s, p_s); row k+1 of x_pred, p_pred, phi is the step k -> k+1."""
    n = x_post.shape[0]
    put(x_s[n - 1], x_post[n - 1])
    put(p_s[n - 1], p_post[n - 1])
    for k in range(n - 2, -1, -1):
        # A_k = P_k Phi^T P_pred^-1, via a solve with the symmetric P_pred: A^T = P_pred^-1 Phi P_k.
        a = solve_matrix(p_pred[k + 1], phi[k + 1] @ p_post[k]).T
        put(x_s[k], x_post[k] + a @ (x_s[k + 1] - x_pred[k + 1]))
        put(p_s[k], p_post[k] + a @ (p_s[k + 1] - p_pred[k + 1]) @ a.T)


def rts_smooth(x_post: np.ndarray, p_post: np.ndarray, x_pred: np.ndarray, p_pred: np.ndarray,
               phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smoothed states (N, n) and covariances (N, n, n) of a stored forward pass (see module docstring)."""
    x_s, p_s = np.empty_like(x_post), np.empty_like(p_post)
    rts_backward(np.ascontiguousarray(x_post), np.ascontiguousarray(p_post), np.ascontiguousarray(x_pred),
                 np.ascontiguousarray(p_pred), np.ascontiguousarray(phi), x_s, p_s)
    return x_s, p_s
