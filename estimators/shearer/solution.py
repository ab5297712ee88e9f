"""A positioning method's output (Solution) at the filter epochs, made from the filter's navigation rows and
state sigmas, and written as the ESTIMATE and ESTIMATE_STATES columns of estimators.io.logformat."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.face.straightness import mat_ft
from estimators.io.logformat import NONORTH_AXES
from estimators.kalman import error_state as es
from estimators.nav import earth
from estimators.nav.rotations import quat_rotate
from estimators.shearer.config import Config

SD_POS, SD_VEL, SD_ATT = slice(0, 3), slice(3, 6), slice(6, 9)
"""Columns of Solution.sd: one-sigma of position, velocity and attitude error (ENU)."""
N_SD = 9


@dataclass
class Solution:
    """One method's output at the filter epochs: body-point navigation, one-sigma, flags, sensor states."""

    t: np.ndarray
    llh: np.ndarray  # (K, 3)
    v_n: np.ndarray  # (K, 3)
    q_nb: np.ndarray  # (K, 4)
    sd: np.ndarray  # (K, N_SD): position ENU, velocity ENU, attitude ENU (NaN without covariance)
    flags: np.ndarray
    cal: np.ndarray | None = None  # (K, N_CAL) estimators.shearer.odometer_filter calibration vector
    sd_cal: np.ndarray | None = None  # (K, N_CAL), in the calibration vector's order
    notes: list[str] = field(default_factory=list)
    fusion: dict[str, np.ndarray] | None = None  # ESTIMATE_FUSION columns of a federated filter
    detectors: dict[str, np.ndarray] | None = None  # ESTIMATE_DETECTORS columns of the rail-model filter


def body_llh(nav: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """Body reference point of IMU-point navigation rows."""
    off = quat_rotate(nav[:, es.QUAT], lever)
    lat, h = nav[:, es.LAT], nav[:, es.HGT]
    r_m, r_n = earth.radii(lat)
    return np.column_stack([lat - off[:, 1] / (r_m + h), nav[:, es.LON] - off[:, 0] / ((r_n + h) * np.cos(lat)),
                            h - off[:, 2]])


def make_solution(t_kf: np.ndarray, cfg: Config, nav: np.ndarray, sd_all: np.ndarray, flags: np.ndarray,
                  cal: np.ndarray, notes: list[str]) -> Solution:
    """A Solution at the filter epochs t_kf from navigation rows and the one-sigma of the error states there."""
    sd = np.column_stack([sd_all[:, es.DP], sd_all[:, es.DV], sd_all[:, es.PHI]])
    sd_cal = np.column_stack([sd_all[:, es.GYRO_BIAS], sd_all[:, es.ACCEL_BIAS], sd_all[:, es.ODO_MOUNT],
                              sd_all[:, es.ODO_SCALE], sd_all[:, es.ACCEL_NONORTH]])
    return Solution(t_kf, body_llh(nav, np.asarray(cfg.lever_arm_m, float)), nav[:, es.VEL].copy(),
                    nav[:, es.QUAT].copy(), sd, flags.copy(), cal.copy(), sd_cal, list(notes))


def join_rows(parts: list[Solution]) -> Solution:
    """Consecutive pieces of a method's solution (calibration where they have it; fusion and detector columns
    where they have them) as one, without notes."""
    sol = Solution(*(None if getattr(parts[0], k) is None else np.concatenate([getattr(p, k) for p in parts])
                     for k in ("t", "llh", "v_n", "q_nb", "sd", "flags", "cal", "sd_cal")))
    for extra in ("fusion", "detectors"):
        have = [getattr(p, extra) for p in parts if getattr(p, extra) is not None]
        if have:
            setattr(sol, extra, {k: np.concatenate([h[k] for h in have]) for k in have[0]})
    return sol


def estimate_columns(sol: Solution, origin_llh: np.ndarray | None = None,
                     azimuth_rad: float | None = None) -> dict[str, np.ndarray]:
    """A Solution as ESTIMATE columns (estimators.io.logformat). With the run's reference point `origin_llh` (lat,
    lon [rad], h [m]: the tangent plane t's origin) and face azimuth [rad], the position in t and in the face frame F
    (estimators.face.straightness.mat_ft) as well, NaN without them."""
    out = {"t": sol.t, "lat": sol.llh[:, 0], "lon": sol.llh[:, 1], "h": sol.llh[:, 2], "flags": sol.flags}
    p_t = np.full(sol.llh.shape, np.nan)
    p_f = np.full(sol.llh.shape, np.nan)
    if origin_llh is not None:
        p_t = earth.lla_to_enu(sol.llh[:, 0], sol.llh[:, 1], sol.llh[:, 2], *origin_llh)
        if azimuth_rad is not None:
            p_f = p_t @ mat_ft(azimuth_rad).T
    for i, (a, x) in enumerate(zip("enu", "xyz")):
        out[f"p_t_{a}"], out[f"p_f_{x}"] = p_t[:, i], p_f[:, i]
    for i, a in enumerate("enu"):
        out[f"v_n_{a}"] = sol.v_n[:, i]
        out[f"sd_pos_{a}"] = sol.sd[:, SD_POS.start + i]
        out[f"sd_vel_{a}"] = sol.sd[:, SD_VEL.start + i]
        out[f"sd_att_{a}"] = sol.sd[:, SD_ATT.start + i]
    for i, a in enumerate("wxyz"):
        out[f"q_nb_{a}"] = sol.q_nb[:, i]
    return out


def state_columns(sol: Solution) -> dict[str, np.ndarray]:
    """A filter Solution's calibration as ESTIMATE_STATES columns."""
    out = {"t": sol.t, "odo_scale": sol.cal[:, es.CAL_SCALE], "sd_odo_scale": sol.sd_cal[:, es.CAL_SCALE]}
    for name, cal, axes in (("gyro_bias", es.CAL_GYRO, "xyz"), ("accel_bias", es.CAL_ACCEL, "xyz"),
                            ("odo_mount", es.CAL_MOUNT, "xyz"), ("accel_nonorth", es.CAL_NONORTH, NONORTH_AXES)):
        for i, a in enumerate(axes):
            out[f"{name}_{a}"] = sol.cal[:, cal.start + i]
            out[f"sd_{name}_{a}"] = sol.sd_cal[:, cal.start + i]
    return out


def rows_of(sol: Solution, rows: slice) -> Solution:
    """Rows of a solution (its navigation, one-sigmas, flags and sensor states; no notes)."""
    return Solution(*(None if getattr(sol, k) is None else getattr(sol, k)[rows]
                      for k in ("t", "llh", "v_n", "q_nb", "sd", "flags", "cal", "sd_cal")))
