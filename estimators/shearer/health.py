"""The health monitor of every shearer positioning method: a filter that loses track says so (issue 23).

Run on each method's Solution (estimators.shearer.methods.estimate) with what a log holds, no truth. An epoch is
unhealthy when

* its state is not finite (position, velocity, attitude or a one-sigma);
* its speed exceeds Config.health_max_speed_m_s (no shearer hauls at metres per second);
* (the filters with gated position fixes, as they run) the innovations of its fixes over a window sum beyond
  their chi-square bound (`innovations_inconsistent`);
* its position moved from the last epoch's by more than the velocity carries it, by more than
  Config.health_jump_sigma times the last epoch's one-sigma (and by at least Config.health_jump_floor_m): a
  correction its own covariance said could not happen, the sign of a filter whose covariance no longer describes
  its error (a runaway with a sigma of millimetres, a jump at a zero-velocity update).

The filters check each pass as they run (`run_checked`, on the navigation rows and state sigmas of the pass): a
pass that lost track runs again from its start, the last state the monitor found consistent, without the position
fixes the innovation gate let through, then without any position fix (a surveyed face end wrong at the sigma it
states), then (the magnetometer filters) without the magnetometer; the fixes left out are flagged FLAG_SKIPPED and
a note says when the track was lost and what the pass ran again without. What is still lost after that, and what
every method outputs, is checked once more on its Solution (`assess`): unhealthy epochs carry FLAG_UNHEALTHY in
the estimate's flags, and the Solution's notes say when, how often and why, so the summary and metrics.json show
it. (Methods without a covariance, dead reckoning, get the first two checks.)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, TypeVar

import numpy as np

from estimators.faults.detectors import chi2_threshold
from estimators.io.logformat import FLAG_UNHEALTHY
from estimators.kalman import error_state as es
from estimators.nav import earth
from estimators.shearer.config import Config
from estimators.shearer.position_fixes import Fixes
from estimators.shearer.solution import SD_POS, Solution, rows_of


class Track(NamedTuple):
    """The monitor's findings per epoch: not finite, too fast, a jump beyond its sigma; the speed and the ratio of
    each position correction to the last epoch's one-sigma."""

    finite: np.ndarray
    fast: np.ndarray
    jump: np.ndarray
    speed: np.ndarray
    ratio: np.ndarray

    @property
    def lost(self) -> np.ndarray:
        return ~self.finite | self.fast | self.jump


def _corrections(t: np.ndarray, llh: np.ndarray, v_n: np.ndarray) -> np.ndarray:
    """Per epoch k >= 1: the position change from epoch k-1 less the mean velocity's travel, ENU [m] (K-1, 3)."""
    r_m, r_n = earth.radii(llh[:-1, 0])
    h = llh[:-1, 2]
    d = np.column_stack([np.angle(np.exp(1j * np.diff(llh[:, 1]))) * (r_n + h) * np.cos(llh[:-1, 0]),
                         np.diff(llh[:, 0]) * (r_m + h), np.diff(llh[:, 2])])
    return d - 0.5 * (v_n[1:] + v_n[:-1]) * np.diff(t)[:, None]


def check_track(t: np.ndarray, llh: np.ndarray, v_n: np.ndarray, q_nb: np.ndarray, sd: np.ndarray,
                sd_pos: np.ndarray, cfg: Config, has_sd: bool | None = None) -> Track:
    """The checks of the module docstring on epochs t of a track: llh (K, 3), v_n (K, 3), q_nb (K, 4), the
    one-sigmas sd (K, n) (all NaN: a method without a covariance) of which sd_pos (K, 3) the position's; `has_sd`
    whether the method has a covariance (None: whether any position one-sigma is finite)."""
    finite = np.isfinite(llh).all(axis=1) & np.isfinite(v_n).all(axis=1) & np.isfinite(q_nb).all(axis=1)
    if has_sd is None:
        has_sd = bool(np.isfinite(sd_pos).any())
    if has_sd:
        finite &= np.isfinite(sd).all(axis=1)
    speed = np.linalg.norm(np.where(np.isfinite(v_n), v_n, 0.0), axis=1)
    jump = np.zeros(t.size, bool)
    ratio = np.zeros(t.size)
    if has_sd and t.size > 1:
        with np.errstate(invalid="ignore"):
            moved = np.linalg.norm(_corrections(t, llh, v_n), axis=1)
            ratio[1:] = moved / np.maximum(np.linalg.norm(sd_pos[:-1], axis=1), 1e-9)
            jump[1:] = (moved > cfg.health_jump_floor_m) & (ratio[1:] > cfg.health_jump_sigma)
    return Track(finite, speed > cfg.health_max_speed_m_s, jump, speed, ratio)


def track_lost(sol: Solution, cfg: Config, has_sd: bool | None = None) -> np.ndarray:
    """Epochs at which a solution lost track (check_track; `has_sd` as there)."""
    return check_track(sol.t, sol.llh, sol.v_n, sol.q_nb, sol.sd, sol.sd[:, SD_POS], cfg, has_sd).lost


def filter_lost(t: np.ndarray, nav: np.ndarray, sd: np.ndarray, cfg: Config) -> np.ndarray:
    """Epochs at which a filter run lost track (check_track), from its navigation rows (K, N_NAV; the IMU point)
    and the one-sigma of its error states (K, N_STATES): the check a filter makes of each pass as it runs."""
    return check_track(t, nav[:, [es.LAT, es.LON, es.HGT]], nav[:, es.VEL], nav[:, es.QUAT], sd, sd[:, es.DP],
                       cfg).lost


class Assessment:
    """`assess` over a method's solution given in consecutive pieces (an online run's passes): `check` flags each
    piece's unhealthy epochs in place, the last epoch of the piece before carried for the jump check, so the flags
    and `notes` are those of the whole solution's. `covariance`: whether the method has one (its one-sigmas are
    checked); None: whether any one-sigma of the piece is finite (a whole solution's check)."""

    KINDS = ("not finite", "fast", "jump")

    def __init__(self, cfg: Config, name: str, covariance: bool | None = None):
        self.cfg, self.name, self.covariance = cfg, name, covariance
        self.last: Solution | None = None
        self.count = {k: 0 for k in self.KINDS}
        self.t_span = {k: [np.nan, np.nan] for k in self.KINDS}
        self.peak = {k: 0.0 for k in self.KINDS}
        self.bad = 0

    def check(self, sol: Solution) -> None:
        if sol.t.size == 0:
            return
        prev = self.last
        cat = {k: getattr(sol, k) if prev is None else np.concatenate([getattr(prev, k), getattr(sol, k)])
               for k in ("t", "llh", "v_n", "q_nb", "sd")}
        track = check_track(cat["t"], cat["llh"], cat["v_n"], cat["q_nb"], cat["sd"], cat["sd"][:, SD_POS], self.cfg,
                            self.covariance)
        skip = 0 if prev is None else 1
        track = Track(*(a[skip:] for a in track))
        sol.flags[track.lost] |= FLAG_UNHEALTHY
        self.bad += int(track.lost.sum())
        for kind, mask, value in (("not finite", ~track.finite, None), ("fast", track.fast, track.speed),
                                  ("jump", track.jump, track.ratio)):
            if mask.any():
                t = sol.t[mask]
                if not self.count[kind]:
                    self.t_span[kind][0] = t[0]
                self.t_span[kind][1] = t[-1]
                self.count[kind] += int(mask.sum())
                if value is not None:
                    self.peak[kind] = max(self.peak[kind], float(value[mask].max()))
        self.last = rows_of(sol, slice(-1, None))

    def notes(self) -> list[str]:
        """A note per kind of lost track: when, how often, how far."""
        cfg, out = self.cfg, []
        what = {"not finite": ("not finite", ""),
                "fast": (f"faster than {cfg.health_max_speed_m_s:g} m/s", f", up to {self.peak['fast']:.3g} m/s"),
                "jump": (f"moved beyond {cfg.health_jump_sigma:g} sigma of its own covariance",
                         f", up to {self.peak['jump']:.3g} sigma")}
        for kind in self.KINDS:
            n = self.count[kind]
            if n:
                label, detail = what[kind]
                t0, t1 = self.t_span[kind]
                out.append(f"health: {self.name} lost track at {n} epoch{'s' * (n != 1)} ({label}{detail}; t {t0:.1f}-"
                           f"{t1:.1f} s): its estimate and sigma there are not to be trusted")
        return out


def assess(sol: Solution, cfg: Config, name: str) -> int:
    """Flag the unhealthy epochs of `sol` (in place: flags and a note per kind); returns their number."""
    assessment = Assessment(cfg, name)
    assessment.check(sol)
    sol.notes.extend(assessment.notes())
    return assessment.bad


NIS_WINDOW = 10
"""Position fixes over which the innovations' consistency is tested (innovations_inconsistent)."""
NIS_FALSE_ALARM = 1e-4
"""Probability that a window of consistent fixes fails the test."""


def innovations_inconsistent(nis: np.ndarray, gate: np.ndarray, epoch: np.ndarray, n_epochs: int,
                             dof: int = 3) -> np.ndarray:
    """Epochs (n_epochs,) from which a pass's gated position fixes disagree with the filter beyond its covariance:
    from the fix that ends the first window of NIS_WINDOW consecutive applied fixes (NIS nis <= gate, gate finite,
    at epoch in the pass's rows) whose NIS sum above the chi-square bound of NIS_WINDOW * dof degrees of freedom at
    NIS_FALSE_ALARM. Each fix within
    its gate, a run of them can still pull the filter off its track (a biased source of points); consistent ones
    sum to a tenth of the bound and less, their errors shared with the filter's (001's points come from its own
    earlier pass)."""
    out = np.zeros(n_epochs, bool)
    used = np.isfinite(gate) & (nis <= gate)
    if used.sum() < NIS_WINDOW:
        return out
    sums = np.convolve(nis[used], np.ones(NIS_WINDOW), "valid")
    over = np.flatnonzero(sums > chi2_threshold(NIS_WINDOW * dof, NIS_FALSE_ALARM))
    if over.size:
        out[epoch[used][over[0] + NIS_WINDOW - 1]:] = True
    return out


def snapshot(state) -> list:
    """Copies of the arrays of a filter state, a (nested) tuple of arrays, for `restore`."""
    return [snapshot(v) if isinstance(v, tuple) else v.copy() for v in state]


def restore(state, saved: list) -> None:
    """Put a `snapshot` back into the arrays of `state`, in place (the kernels hold references to them)."""
    for v, w in zip(state, saved):
        if isinstance(v, tuple):
            restore(v, w)
        else:
            v[...] = w


Run = TypeVar("Run")
Arg = TypeVar("Arg")


def fix_fallbacks(fixes: Fixes) -> list[tuple[str, np.ndarray]]:
    """What a pass that lost track runs again with (run_checked), as masks on `fixes`: without the fixes that can be
    wrong and let through by the innovation gate (the CPOEM or rail-model points: gate finite), then without any
    position fix (a surveyed face end at a sigma it does not keep); a fallback that leaves nothing out is not
    tried."""
    trusted = ~np.isfinite(fixes.gate)
    out = [(f"without its {int((~trusted).sum())} gated position fixes", trusted),
           ("without any position fix", np.zeros(fixes.epoch.size, bool))]
    sizes = [fixes.epoch.size] + [int(mask.sum()) for _, mask in out]
    return [fb for k, fb in enumerate(out) if sizes[k + 1] < sizes[k]]


def run_checked(run: Callable[[Arg], Run], lost: Callable[[Run], np.ndarray], restore: Callable[[], None],
                first: Arg, fallbacks: list[tuple[str, Arg]], t: np.ndarray, notes: list[str]) -> tuple[Run, Arg]:
    """One pass of a filter over epochs t (row 0 the previous pass's last), checked as it runs and recovered when
    it loses track: `run(arg)` runs the pass from the filter's state with its measurements `arg` (`first`, then
    each of `fallbacks`, (label, arg), until one keeps track), `lost(result)` gives the lost epochs
    (filter_lost), `restore()` puts the filter back in its state at the pass's start, the last one the monitor
    found consistent. What was done is said in `notes`. Returns the result kept and the arg it ran with."""
    result = run(first)
    bad = lost(result)
    if not bad.any():
        return result, first
    t_lost, span = t[np.argmax(bad)], f"(t {t[0]:.0f}-{t[-1]:.0f} s)"
    for label, arg in fallbacks:
        restore()
        del result  # the lost run's arrays go before the next run makes its own (a pass's rows: 30 MB on seed004)
        result = run(arg)
        if not lost(result).any():
            notes.append(f"health: lost track at t {t_lost:.1f} s; the pass {span} was run again from its start "
                         f"{label}")
            return result, arg
    tried = "; ".join(label for label, _ in fallbacks) or "nothing to leave out"
    notes.append(f"health: lost track at t {t_lost:.1f} s in the pass {span}, and run again from its start "
                 f"({tried}) lost it too")
    return result, (fallbacks[-1][1] if fallbacks else first)
