"""The surveyed face line, smoothed: a local quadratic least-squares fit of the survey's points along the face.

A face survey gives the installed line one point per chute with independent errors (a few centimetres). The line
itself is smooth on the scale of a few chutes: the shearer's body point rides the pans on shoes several metres
apart, and the seam's undulation has wavelengths of tens of metres. So at each point a quadratic in the face
coordinate u is fitted to the points within +-half_window_m, weighted by the tricube kernel of LOESS (Cleveland
1979), and the fit's value and slope at the point are taken:

    p(u) ~ a + b (u - u_k) + c (u - u_k)^2     over |u_j - u_k| < h, weights (1 - |u_j - u_k|^3 / h^3)^3,
    point_k = a,   direction_k = b = d position / d u.

Both are linear in the points: value = G @ enu, slope = G' @ enu, so the smoothed point's error variance is the
survey's variance times sum_j G_kj^2 (the noise gain, 0.18 in the middle of the face with h = 14.5 m and 1.8 m
chutes, more at the face ends where the window is one-sided). The fit takes a 0.05 m survey noise to about
0.021 m, and bends with a 0.2 m, 40 m undulation to within 3 mm. The weights let a point enter and leave the
window gradually, so neighbouring smoothed points' errors differ by 8 mm rms (an unweighted fit over +-9 m, of
the same bias: 12 mm): a rail-model fix from the survey then changes little from one chute to the next, and its
innovations stay small where the filter follows it (estimators.shearer.rail_fix_update.rail_fix_update).
"""

from __future__ import annotations

import numpy as np

from estimators.nav import earth

__all__ = ["FaceLine", "fit_face_line"]

DEGREE = 2
"""Degree of the local polynomial."""


class FaceLine:
    """The fitted line at the survey's points: enu (K, 3) smoothed points and direction (K, 3) = d enu / d u, in
    the local ENU frame at the first point, with gain (K,) the noise gain sum_j G_kj^2 of each smoothed point."""

    def __init__(self, enu: np.ndarray, direction: np.ndarray, gain: np.ndarray, origin: np.ndarray):
        self.enu, self.direction, self.gain, self.origin = enu, direction, gain, origin

    def llh(self) -> np.ndarray:
        """(K, 3) geodetic latitude, longitude [rad] and height [m] of the smoothed points."""
        return np.column_stack(earth.enu_to_lla(self.enu, *self.origin))


def tricube(du: np.ndarray, half_window_m: float) -> np.ndarray:
    """LOESS weights (1 - |du / h|^3)^3 inside |du| < h; points at the window's edge (or a window widened to take
    DEGREE + 1 points) keep a small weight, so that every point of the fit counts."""
    return np.maximum(1.0 - np.minimum(np.abs(du) / half_window_m, 1.0) ** 3, 0.05) ** 3


def fit_face_line(llh: np.ndarray, u: np.ndarray, half_window_m: float = 14.5) -> FaceLine:
    """Local quadratic fit of a surveyed face line: llh (K, 3) points in order along the line, u (K,) their
    face coordinates (increasing). A window with fewer than DEGREE + 1 points takes the nearest DEGREE + 1 (a
    line of 2 points is fitted by a straight line, of 1 point kept as it is, with no direction)."""
    llh = np.asarray(llh, float)
    u = np.asarray(u, float)
    origin = llh[0].copy()
    enu = earth.lla_to_enu(llh[:, 0], llh[:, 1], llh[:, 2], *origin)
    k_pts = u.size
    degree = min(DEGREE, k_pts - 1)
    value_w = np.zeros((k_pts, k_pts))
    slope_w = np.zeros((k_pts, k_pts))
    for k in range(k_pts):
        near = np.flatnonzero(np.abs(u - u[k]) < half_window_m)
        if near.size < degree + 1:
            near = np.sort(np.argsort(np.abs(u - u[k]), kind="stable")[:degree + 1])
        du = u[near] - u[k]
        basis = np.vander(du, degree + 1, increasing=True)  # columns 1, du, du^2
        root_w = np.sqrt(tricube(du, half_window_m))[:, None]
        weights = np.linalg.pinv(root_w * basis) * root_w.T  # rows: the coefficients a, b, c as weights on the points
        value_w[k, near] = weights[0]
        if degree >= 1:
            slope_w[k, near] = weights[1]
    direction = slope_w @ enu if degree >= 1 else np.full((k_pts, 3), np.nan)
    return FaceLine(value_w @ enu, direction, np.sum(value_w ** 2, axis=1), origin)
