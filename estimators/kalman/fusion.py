"""Federated fusion of sub-filters: information-sharing coefficients (003 section 4.3), global fusion
(004 eqs. 10-11) and the reset of the sub-filters, with fault isolation of a sub-filter whose covariance is
not usable.

Given the sub-filters' estimates x_i and covariances P_i of the common states (the SINS error states every
sub-filter carries; marginals of larger sub-filter states fuse correctly in information form):

    P_g = (sum_i P_i^-1)^-1,   x_g = P_g sum_i P_i^-1 x_i                     (004 eqs. 10-11)
    beta_i = tr(P_i) / sum_j tr(P_j)                                           (003 section 4.3)
    x_i <- x_g,   P_i <- P_g / beta_i    (and, in Carlson's scheme, Q_i <- Q / beta_i)  (003 section 4.3)

The 003 text: a sub-filter with large eigenvalues of P_i is the less accurate one and gets the larger beta_i,
the accurate one the smaller. With the reset P_i = P_g / beta_i this gives the less accurate (for instance the
disturbed magnetometer) sub-filter the tighter prior, so its own measurements move it less, and lets the
accurate one lean on its measurements. The common alternative (beta_i proportional to 1 / tr(P_i), more
information to the more accurate sub-filter) is `rule="inverse_trace"`. Either way the coefficients sum to 1.

Bad input (issue 6): a sub-filter whose x_i or P_i is not finite, or whose P_i is not symmetric positive
definite, gets weight 0 in the fusion and beta_i = 0, is flagged, and is reset to (x_g, P_g): it restarts from
the global solution and rejoins once its covariance is sound again. With no usable sub-filter at all there is
no estimate and `fuse` raises.

Inverses go through the Cholesky factor of the correlation matrix D^-1/2 P D^-1/2 (D = diag P;
estimators.kalman.cholesky.spd_inverse), so error states of very different scales (metres and 1e-5 rad/s) keep
their precision. The numba kernels (`fuse_kernel`, `sharing_kernel`) can be called from a filter kernel; `fuse`,
`sharing_coefficients` and `reset_subfilters` are the validating Python API.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from estimators.kalman.cholesky import spd_inverse

__all__ = [
    "FusionResult",
    "fuse",
    "fuse_kernel",
    "reset_subfilters",
    "sharing_coefficients",
    "sharing_kernel",
]

@nb.njit(cache=True)
def fuse_kernel(xs, ps):
    """Global fusion (004 eqs. 10-11) of xs (N, n), ps (N, n, n) over the usable sub-filters.

    Returns (x_g, P_g, valid (N,) bool, ok): ok False when no sub-filter is usable (then x_g, P_g are zero).
    """
    n_sub, n = xs.shape
    info = np.zeros((n, n))
    info_x = np.zeros(n)
    valid = np.zeros(n_sub, np.bool_)
    for i in range(n_sub):
        inv, ok = spd_inverse(ps[i])
        if ok and np.all(np.isfinite(xs[i])):
            valid[i] = True
            info += inv
            info_x += inv @ xs[i]
    if not valid.any():
        return np.zeros(n), np.zeros((n, n)), valid, False
    p_g, ok = spd_inverse(0.5 * (info + info.T))
    if not ok:
        return np.zeros(n), np.zeros((n, n)), valid, False
    return p_g @ info_x, p_g, valid, True


@nb.njit(cache=True)
def sharing_kernel(ps, valid, inverse):
    """beta (N,) from the traces of ps (N, n, n) over the valid sub-filters (003 section 4.3); 0 elsewhere.

    inverse False: beta_i = tr(P_i) / sum tr(P_j) (003); True: beta_i = tr(P_i)^-1 / sum tr(P_j)^-1.
    """
    n_sub = ps.shape[0]
    beta = np.zeros(n_sub)
    for i in range(n_sub):
        if valid[i]:
            tr = np.trace(ps[i])
            beta[i] = 1.0 / tr if inverse else tr
    total = beta.sum()
    return beta / total if total > 0 else beta


class FusionResult(NamedTuple):
    """The global estimate and what each sub-filter contributed."""

    x: np.ndarray
    """x_g (n,)."""
    p: np.ndarray
    """P_g (n, n)."""
    valid: np.ndarray
    """(N,) bool: the sub-filter's estimate and covariance were usable (finite, symmetric positive definite)."""
    beta: np.ndarray
    """(N,) information-sharing coefficients (003 section 4.3), 0 for an invalid sub-filter, summing to 1."""


def _stack(xs, ps) -> tuple[np.ndarray, np.ndarray]:
    xs = np.asarray(xs, float)
    ps = np.asarray(ps, float)
    if xs.ndim != 2 or ps.shape != (xs.shape[0], xs.shape[1], xs.shape[1]):
        raise ValueError(f"fuse: estimates {xs.shape} and covariances {ps.shape} do not match as (N, n), (N, n, n)")
    return xs, ps


def _rule_is_inverse(rule: str) -> bool:
    if rule not in ("trace", "inverse_trace"):
        raise ValueError(f"sharing rule {rule!r}: use 'trace' (003) or 'inverse_trace'")
    return rule == "inverse_trace"


def fuse(xs, ps, rule: str = "trace") -> FusionResult:
    """Fuse the sub-filters' (x_i, P_i) (004 eqs. 10-11) and give their sharing coefficients (003 section 4.3).

    xs (N, n), ps (N, n, n). A sub-filter whose estimate or covariance is unusable is left out (weight 0,
    beta 0, valid False). Raises ValueError when none is usable.
    """
    xs, ps = _stack(xs, ps)
    inverse = _rule_is_inverse(rule)
    x_g, p_g, valid, ok = fuse_kernel(xs, ps)
    if not ok:
        raise ValueError("fuse: no sub-filter has a finite, positive definite covariance; nothing to fuse")
    return FusionResult(x_g, p_g, valid, sharing_kernel(ps, valid, inverse))


def sharing_coefficients(ps, rule: str = "trace") -> tuple[np.ndarray, np.ndarray]:
    """(beta (N,), valid (N,)): information-sharing coefficients from the traces of ps (N, n, n) (003 section 4.3)."""
    ps = np.asarray(ps, float)
    if ps.ndim != 3 or ps.shape[1] != ps.shape[2]:
        raise ValueError(f"sharing_coefficients: covariances {ps.shape}, expected (N, n, n)")
    inverse = _rule_is_inverse(rule)
    valid = np.array([spd_inverse(p)[1] for p in ps], bool)
    return sharing_kernel(ps, valid, inverse), valid


def reset_subfilters(fusion: FusionResult) -> list[tuple[np.ndarray, np.ndarray]]:
    """(x_i, P_i) per sub-filter after the fusion: (x_g, P_g / beta_i); an invalid one restarts at (x_g, P_g)."""
    return [(fusion.x.copy(), fusion.p / b if ok else fusion.p.copy())
            for b, ok in zip(fusion.beta, fusion.valid)]
