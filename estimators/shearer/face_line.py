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

How far to smooth depends on the survey: the half-window h is the one of HALF_WINDOWS_M whose smoothed points have
the least expected squared error by Mallows' C_p (Stein's unbiased risk estimate) from the residuals and the
survey's stated sigmas, so a 5 cm survey is smoothed over +-14.5 m and a 5 mm survey of a floor undulating 0.3 m
over 30 m over +-9 m, where +-14.5 m flattened the undulation by 4 mm, which the rail-model filter took for the
line and walked 1.7 cm along the face (tests/estimators/shearer/test_independent_trajectories.py, az45_eq).

A survey's stated sigma is what its points may scatter; where they scatter far less (`scatter_ratio`: the residuals
of the fit over +-SCATTER_WINDOW_M, which follows any undulation of the seam, against the stated sigma), the window is
chosen for the scatter seen. Stated at 5 mm, an error-free survey of a 0.3 m, 40 m undulation was smoothed over
+-11.5 m as a 5 mm one would be, leaving it 2.7 mm rms off the floor, whose slope the rail-model filter took for
1.2e-4 of odometer scale before the first face end; chosen for the scatter, +-6.5 m: 0.5 mm and 2.6e-5. The
points' variances stay the stated ones.
"""

from __future__ import annotations

import numpy as np

from estimators.nav import earth

__all__ = ["FaceLine", "fit_face_line"]

DEGREE = 2
"""Degree of the local polynomial."""
HALF_WINDOWS_M = (2.0, 3.0, 4.5, 6.5, 9.0, 11.5, 14.5)
"""The half-windows tried, narrowest first: from three chutes of 1.75-2 m (the narrowest a quadratic fits) to the
+-14.5 m that takes a 5 cm survey to 2 cm (the widest: the shearer rides the pans on shoes a few metres apart,
and the seam undulates over tens of metres)."""
SCATTER_WINDOW_M = 4.5
"""Half-window of the fit whose residuals show the survey's scatter: two to three chutes each side, over which a
quadratic follows the seam's undulation (0.2 mm rms off a 0.3 m, 40 m wave) and leaves about a third of the points'
degrees of freedom to the residuals."""
SCATTER_RATIO = 0.5
"""A component whose points scatter less than this share of their stated sigma is smoothed as if stated at its scatter.
A survey that scatters as stated falls under it by chance with a probability (chi-square) of 0.7 % in height for the
35 points of a 60 m face, 4e-4 for 60 points, 1e-10 for 200; it is then smoothed over a narrower window, not a
wider one."""
SD_FLOOR_M = 1e-3
"""The survey sigma below which a point is taken as 1 mm (a survey stated exact is smoothed no more than one of
1 mm would be)."""


class FaceLine:
    """The fitted line at the survey's points: enu (K, 3) smoothed points and direction (K, 3) = d enu / d u, in
    the local ENU frame at the first point, with gain (K,) the noise gain sum_j G_kj^2 of each smoothed point, and
    the half-window chosen [m]."""

    def __init__(self, enu: np.ndarray, direction: np.ndarray, gain: np.ndarray, origin: np.ndarray,
                 half_window_m: float):
        self.enu, self.direction, self.gain, self.origin = enu, direction, gain, origin
        self.half_window_m = half_window_m

    def llh(self) -> np.ndarray:
        """(K, 3) geodetic latitude, longitude [rad] and height [m] of the smoothed points."""
        return np.column_stack(earth.enu_to_lla(self.enu, *self.origin))


def tricube(du: np.ndarray, half_window_m: float) -> np.ndarray:
    """LOESS weights (1 - |du / h|^3)^3 inside |du| < h; points at the window's edge (or a window widened to take
    DEGREE + 1 points) keep a small weight, so that every point of the fit counts."""
    return np.maximum(1.0 - np.minimum(np.abs(du) / half_window_m, 1.0) ** 3, 0.05) ** 3


def local_fit_weights(u: np.ndarray, half_window_m: float) -> tuple[np.ndarray, np.ndarray, int]:
    """The smoother as matrices on the points: value_w (K, K) and slope_w (K, K), value = value_w @ points and
    slope = slope_w @ points, and the degree fitted. A window with fewer than DEGREE + 1 points takes the nearest
    DEGREE + 1 (a line of 2 points is fitted by a straight line, of 1 point kept as it is, with no slope). All
    points at once: the weighted normal equations N_k = V_k^T W_k V_k (DEGREE + 1 square) of every point k."""
    k_pts = u.size
    degree = min(DEGREE, k_pts - 1)
    du = u[None, :] - u[:, None]  # (k, j): u_j - u_k
    inside = np.abs(du) < half_window_m
    nearest = np.argsort(np.abs(du), axis=1, kind="stable")[:, :degree + 1]
    few = inside.sum(axis=1) < degree + 1
    inside[few] = False
    inside[np.flatnonzero(few)[:, None], nearest[few]] = True
    w = np.where(inside, tricube(du, half_window_m), 0.0)
    basis_t = du[:, None, :] ** np.arange(degree + 1)[None, :, None]  # (k, 1 + du + du^2, j)
    weighted_t = basis_t * w[:, None, :]
    coef = np.linalg.pinv(weighted_t @ basis_t.transpose(0, 2, 1))  # rows: the coefficients a, b, c
    weights = coef @ weighted_t
    slope_w = weights[:, 1] if degree >= 1 else np.zeros((k_pts, k_pts))
    return weights[:, 0], slope_w, degree


def fit_risk(enu: np.ndarray, sd: np.ndarray, value_w: np.ndarray) -> float:
    """Mallows' C_p (Stein's unbiased risk estimate) of the smoothed points, in the points' sigmas: the residuals
    normalized by each point's sigma, summed in square, plus twice the fit's degrees of freedom tr(value_w) per
    component, less one per point and component. Its expectation is the sum over the points of the squared error of
    the smoothed point (bias and noise), in the same sigmas."""
    m = np.eye(value_w.shape[0]) - value_w
    sig = np.column_stack([sd[:, 0], sd[:, 0], sd[:, 1]])
    return float(np.sum((m @ enu / sig) ** 2) + 3 * (2.0 * np.trace(value_w) - value_w.shape[0]))


def scatter_ratio(enu: np.ndarray, sd: np.ndarray, value_w: np.ndarray) -> np.ndarray:
    """(horizontal, vertical) rms of the points' residuals from a fit (value_w) in their stated sigmas sd (K, 2),
    each residual's expected square taken out (the residual degrees of freedom tr((I - W)^T (I - W)) per component);
    1 where the fit leaves fewer than two degrees of freedom."""
    m = np.eye(value_w.shape[0]) - value_w
    dof = float(np.sum(m ** 2))
    if dof < 2.0:
        return np.ones(2)
    z = m @ enu / np.column_stack([sd[:, 0], sd[:, 0], sd[:, 1]])
    return np.sqrt(np.array([np.sum(z[:, :2] ** 2) / 2.0, np.sum(z[:, 2] ** 2)]) / dof)


def fit_face_line(llh: np.ndarray, u: np.ndarray, sd: np.ndarray) -> FaceLine:
    """Local quadratic fit of a surveyed face line: llh (K, 3) points in order along the line, u (K,) their
    face coordinates (increasing), sd (K, 2) their horizontal and vertical one-sigma [m] (floored at SD_FLOOR_M).

    The half-window is the one of HALF_WINDOWS_M of least `fit_risk` at the stated sigmas, or at the scatter seen
    where it is under SCATTER_RATIO of them (`scatter_ratio`)."""
    llh = np.asarray(llh, float)
    u = np.asarray(u, float)
    sd = np.maximum(np.asarray(sd, float).reshape(-1, 2), SD_FLOOR_M)
    origin = llh[0].copy()
    enu = earth.lla_to_enu(llh[:, 0], llh[:, 1], llh[:, 2], *origin)
    ratio = scatter_ratio(enu, sd, local_fit_weights(u, SCATTER_WINDOW_M)[0])
    sd_seen = np.maximum(sd * np.where(ratio < SCATTER_RATIO, ratio, 1.0), SD_FLOOR_M)
    fits = [(h, *local_fit_weights(u, h)) for h in HALF_WINDOWS_M]
    half_window_m, value_w, slope_w, degree = min(fits, key=lambda f: fit_risk(enu, sd_seen, f[1]))
    direction = slope_w @ enu if degree >= 1 else np.full((u.size, 3), np.nan)
    return FaceLine(value_w @ enu, direction, np.sum(value_w ** 2, axis=1), origin, half_window_m)
