"""The health monitor of every shearer positioning method: a filter that loses track says so (issue 23).

Run on each method's Solution (estimators.shearer.methods.estimate) with what a log holds, no truth. An epoch is
unhealthy when

* its state is not finite (position, velocity, attitude or a one-sigma);
* its speed exceeds Config.health_max_speed_m_s (no shearer hauls at metres per second);
* its position moved from the last epoch's by more than the velocity carries it, by more than
  Config.health_jump_sigma times the last epoch's one-sigma (and by at least Config.health_jump_floor_m): a
  correction its own covariance said could not happen, the sign of a filter whose covariance no longer describes
  its error (a runaway with a sigma of millimetres, a jump at a zero-velocity update).

Unhealthy epochs carry FLAG_UNHEALTHY in the estimate's flags, and the Solution's notes say when, how often and
why, so the summary and metrics.json show it. (Methods without a covariance, dead reckoning, get the first two.)
"""

from __future__ import annotations

import numpy as np

from estimators.io.logformat import FLAG_UNHEALTHY
from estimators.nav import earth
from estimators.shearer.config import Config
from estimators.shearer.solution import SD_POS, Solution


def _corrections(sol: Solution) -> np.ndarray:
    """Per epoch k >= 1: the position change from epoch k-1 less the mean velocity's travel, ENU [m] (K-1, 3)."""
    r_m, r_n = earth.radii(sol.llh[:-1, 0])
    h = sol.llh[:-1, 2]
    d = np.column_stack([np.angle(np.exp(1j * np.diff(sol.llh[:, 1]))) * (r_n + h) * np.cos(sol.llh[:-1, 0]),
                         np.diff(sol.llh[:, 0]) * (r_m + h), np.diff(sol.llh[:, 2])])
    return d - 0.5 * (sol.v_n[1:] + sol.v_n[:-1]) * np.diff(sol.t)[:, None]


def assess(sol: Solution, cfg: Config, name: str) -> int:
    """Flag the unhealthy epochs of `sol` (in place: flags and a note per kind); returns their number."""
    finite = (np.isfinite(sol.llh).all(axis=1) & np.isfinite(sol.v_n).all(axis=1)
              & np.isfinite(sol.q_nb).all(axis=1))
    has_sd = np.isfinite(sol.sd[:, SD_POS]).any()
    if has_sd:
        finite &= np.isfinite(sol.sd).all(axis=1)
    speed = np.linalg.norm(np.where(np.isfinite(sol.v_n), sol.v_n, 0.0), axis=1)
    fast = speed > cfg.health_max_speed_m_s
    jump = np.zeros(sol.t.size, bool)
    ratio = np.zeros(sol.t.size)
    if has_sd and sol.t.size > 1:
        with np.errstate(invalid="ignore"):
            moved = np.linalg.norm(_corrections(sol), axis=1)
            prior = np.linalg.norm(sol.sd[:-1, SD_POS], axis=1)
            ratio[1:] = moved / np.maximum(prior, 1e-9)
            jump[1:] = (moved > cfg.health_jump_floor_m) & (ratio[1:] > cfg.health_jump_sigma)
    bad = ~finite | fast | jump
    sol.flags[bad] |= FLAG_UNHEALTHY
    for kind, mask, what in (
            ("not finite", ~finite, ""),
            (f"faster than {cfg.health_max_speed_m_s:g} m/s", fast, f", up to {speed[fast].max(initial=0):.3g} m/s"),
            (f"moved beyond {cfg.health_jump_sigma:g} sigma of its own covariance", jump,
             f", up to {ratio[jump].max(initial=0):.3g} sigma")):
        if mask.any():
            t = sol.t[mask]
            n = int(mask.sum())
            sol.notes.append(f"health: {name} lost track at {n} epoch{'s' * (n != 1)} ({kind}{what}; t {t[0]:.1f}-"
                             f"{t[-1]:.1f} s): its estimate and sigma there are not to be trusted")
    return int(bad.sum())
