"""Shearer positioning of 001 on a prepared sensor log (estimators.shearer.prepare): the SINS/odometer Kalman
filter (001 eqs. 12-20, kernel estimators.shearer.odometer_filter) with zero-velocity and zero-rate updates at
stands, its P0 and Q (001 Appendix A), CPOEM position fixes (001 eqs. 6, 21-22; estimators.shearer.position_fixes),
RTS smoothing at each face end and over the whole run (001 eqs. 28-31, Fig. 4); the dead-reckoning baseline is
estimators.shearer.dead_reckoning.

Methods (estimators.shearer.methods runs them by name, each an estimates/NAME stream):

* ``dr``            the "traditional method" of 001 section 4: free SINS attitude and odometer distance;
* ``dr_compensated``  the same with the sensor biases, odometer scale and mounting estimated by ``kf_cpoem_rts``;
* ``kf``            SINS/odometer filter with zero-velocity and zero-rate updates at stands;
* ``kf_rts``        the same with the online RTS smoother run at each face end over the pass just finished (the
                    path between the face ends' survey fixes, each pass on its own: what face alignment wants,
                    twin.pipeline.alignment_loop);
* ``kf_cpoem``      plus CPOEM fixes whose points come from the forward filter (the first cut's from the face
                    survey, when the log has one: Config.cpoem_face_survey);
* ``kf_cpoem_rts``  plus the online RTS smoother run at each face end over the pass just finished; the smoothed
                    points feed the next cycle's fixes, the output is the smoothed pass;
* ``rts_offline``   one RTS pass over the whole run of ``kf_cpoem_rts``'s forward filter.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numba as nb
import numpy as np

from estimators.io.log import Log
from estimators.io.logformat import FLAG_SKIPPED, FLAG_SMOOTHED
from estimators.kalman import error_state as es
from estimators.kalman.rts import StoredInterval, matrix_blocks, one_sigma as _sd, rts_stored
from estimators.nav import earth
from estimators.nav.rotations import quat_to_mat
from estimators.shearer import odometer_filter as kf
from estimators.shearer.config import Config
from estimators.shearer.cpoem import Points, at_spacing
from estimators.shearer.health import (
    filter_lost,
    fix_fallbacks,
    innovations_inconsistent,
    restore,
    run_checked,
    snapshot,
)
from estimators.shearer.position_fixes import Fixes, face_survey_points, fixes_for, segment_points
from estimators.shearer.prepare import Mech, Prepared
from estimators.shearer.solution import Solution, join_rows, make_solution


def initial_covariance(cfg: Config, log: Log, q_nb0: np.ndarray) -> np.ndarray:
    """P0 of the error states (001 Appendix A (A2) form): the configured sigmas, heading from the survey; with
    cfg.level_from_accelerometers the level error of the start attitude q_nb0 tied to the accelerometer errors.

    Levelled at rest, the attitude leaves no velocity drift in the filter's own model (odometer_filter.system_matrix):
    f_n x phi + C_b^n e = 0 horizontally, e = b + N(f_b) a the accelerometer error at f_b = C_n^b (0, 0, g), so
    phi_E = -(C_b^n e)_N / g and phi_N = (C_b^n e)_E / g. A diagonal P0 takes the level as known to sd_level0
    besides the bias, and the first stand's zero-velocity updates, which see only phi and e together, then
    "learn" the across-face bias from that prior (seed001: roll sd 0.175 -> 0.151 deg at the first stand, with
    the true roll error staying -b_x / g)."""
    sd = np.zeros(es.N_STATES)
    sd[es.DV] = cfg.sd_velocity0
    sd[es.PHI] = [cfg.sd_level0, cfg.sd_level0, log.survey_sd[0, 2]]
    sd[es.DP] = [log.survey_sd[0, 0], log.survey_sd[0, 0], log.survey_sd[0, 1]]
    sd[es.GYRO_BIAS] = cfg.imu.gyro_bias
    sd[es.ACCEL_BIAS] = cfg.imu.accel_bias
    sd[es.ACCEL_NONORTH] = cfg.imu.accel_nonorth
    sd[es.ODO_MOUNT] = cfg.sd_odo_mount0
    sd[es.ODO_SCALE] = cfg.sd_odo_scale0
    p0 = np.diag((cfg.p0_scale * sd) ** 2)
    if not cfg.level_from_accelerometers:
        return p0
    c_nb = quat_to_mat(q_nb0)
    g = float(earth.normal_gravity(log.survey_llh[0, 0], log.survey_llh[0, 2]))
    tilt_per_error = np.vstack([-c_nb[1], c_nb[0]]) / g  # (phi_E, phi_N) per unit e in b
    t = np.eye(es.N_STATES)
    level = slice(es.PHI.start, es.PHI.start + 2)
    t[level, es.ACCEL_BIAS] = tilt_per_error
    t[level, es.ACCEL_NONORTH] = tilt_per_error @ kf.nonorth_matrix(c_nb.T @ np.array([0.0, 0.0, g]))
    return t @ p0 @ t.T


def process_noise_psd(cfg: Config) -> np.ndarray:
    """Diagonal process-noise densities of the error states (001 Appendix A (A3) form)."""
    q = np.zeros(es.N_STATES)
    q[es.DV] = cfg.imu.accel_vrw ** 2 + cfg.vibration_vrw ** 2
    q[es.PHI] = cfg.imu.gyro_arw ** 2
    q[es.GYRO_BIAS] = cfg.imu.gyro_bias_psd
    q[es.ACCEL_BIAS] = cfg.imu.accel_bias_psd
    return q * cfg.q_scale ** 2


def kf_params(cfg: Config) -> np.ndarray:
    """The parameter vector of the estimators.shearer.odometer_filter kernels."""
    params = np.zeros(kf.N_PARAMS)
    quantization = np.sqrt(cfg.metres_per_pulse ** 2 / 6) * cfg.filter_rate_hz  # of a speed over one epoch
    params[[kf.P_R_LATERAL, kf.P_R_ALONG, kf.P_R_VERTICAL, kf.P_R_ZUPT, kf.P_R_ZARU, kf.P_TAU_FWD, kf.P_TAU_FORCE]] = [
        cfg.r_lateral, np.hypot(quantization, cfg.r_odometer), cfg.r_vertical, cfg.r_zupt, cfg.r_zaru,
        cfg.speed_tau_s, cfg.force_tau_s]
    params[kf.P_LEVER:kf.P_LEVER + 3] = cfg.lever_arm_m
    return params


@nb.njit(cache=True)
def _apply_rows(nav, cal, d):
    """Feed error-state corrections d (K, N_STATES) back into navigation and calibration rows, in place."""
    for k in range(nav.shape[0]):
        kf.apply_correction(nav[k], cal[k], d[k])


class _Forward:
    """Storage of one forward run: per-epoch navigation, calibration, state sigmas and flags."""

    def __init__(self, n: int):
        self.nav = np.zeros((n + 1, es.N_NAV))
        self.cal = np.zeros((n + 1, es.N_CAL))
        self.sd = np.zeros((n + 1, es.N_STATES))
        self.flags = np.zeros(n + 1, np.int32)


class _Segment(NamedTuple):
    """One pass (epochs a..b, row 0 the previous pass's last) of the filter kernel: posterior error states, their
    one-sigma and position covariances (3, 3), the smoother's matrices on disk (None when the pass is not smoothed),
    navigation and calibration rows, flags, each fix's row in the pass, NIS gate and NIS."""

    x_post: np.ndarray
    sd: np.ndarray
    p_dp: np.ndarray
    stored: StoredInterval | None
    nav: np.ndarray
    cal: np.ndarray
    flags: np.ndarray
    fix_row: np.ndarray
    gate: np.ndarray
    nis: np.ndarray


def _run_segment(prep: Prepared, mech: Mech, a: int, b: int, fixes: Fixes, q_psd: np.ndarray, params: np.ndarray,
                 nav: np.ndarray, cal: np.ndarray, p: np.ndarray, nominal: np.ndarray, stored: StoredInterval | None,
                 blocks: tuple[np.ndarray, ...]) -> _Segment:
    """The filter kernel (odometer_filter.run_filter) over epochs (a, b] (their increments `mech`) with `fixes`,
    from (nav, cal, p, nominal), which it leaves at epoch b, a block of rts.BLOCK epochs a call, its covariances in
    `blocks` (rts.matrix_blocks); `stored`: where the smoother's matrices go (restarted; None: not kept)."""
    m, n, block = b - a + 1, es.N_STATES, blocks[0].shape[0] - 1
    seg = _Segment(np.zeros((m, n)), np.zeros((m, n)), np.zeros((m, 3, 3)), stored, np.zeros((m, es.N_NAV)),
                   np.zeros((m, es.N_CAL)), np.zeros(m, np.int32), fixes.epoch - a, fixes.gate,
                   np.full(fixes.epoch.size, np.nan))
    seg.nav[0], seg.cal[0], seg.sd[0], seg.p_dp[0] = nav, cal, _sd(p), p[es.DP, es.DP]
    smoothed = stored is not None
    p_post, p_pred, phi = blocks[0], blocks[1][:None if smoothed else 1], blocks[2][:None if smoothed else 1]
    if smoothed:
        stored.restart()
        stored.append(p[None], p[None], np.eye(n)[None])
    vel_innov = np.full((m, 3), np.nan)
    span = prep.span(a, b)
    for j0 in range(0, m - 1, block):
        j1 = min(j0 + block, m - 1)
        kf.run_filter(j0, j1, j0 + 1, prep.steps, mech.t, mech.phi_b, mech.dv_b, prep.odo[span], prep.mode[span],
                      seg.fix_row, fixes.llh, fixes.r, fixes.gate, q_psd, params, nav, cal, p, nominal, seg.nav,
                      seg.cal, seg.x_post, p_post, p_pred, phi, seg.flags, seg.nis, vel_innov)
        r = j1 - j0
        seg.sd[j0 + 1:j1 + 1], seg.p_dp[j0 + 1:j1 + 1] = _sd(p_post[:r]), p_post[:r, es.DP, es.DP]
        if smoothed:
            seg.stored.append(p_post[:r], p_pred[:r], phi[:r])
    return seg


def _checked_segment(prep: Prepared, cfg: Config, a: int, b: int, fixes: Fixes, q_psd: np.ndarray,
                     params: np.ndarray, state: tuple[np.ndarray, ...], notes: list[str],
                     stored: StoredInterval | None, blocks: tuple[np.ndarray, ...]) -> tuple[_Segment, Fixes]:
    """_run_segment from state = (nav, cal, p, nominal) under the health monitor (health.run_checked): a pass that
    loses track runs again from its start with fewer fixes; the epochs of the fixes it left out are flagged
    FLAG_SKIPPED. Returns the segment kept and its fixes."""
    saved = snapshot(state)
    mech, t = prep.mech(a, b), prep.t_kf[prep.span(a, b)]
    seg, kept = run_checked(lambda keep: _run_segment(prep, mech, a, b, fixes.take(keep), q_psd, params, *state,
                                                      stored, blocks),
                            lambda s: filter_lost(t, s.nav, s.sd, cfg)
                            | innovations_inconsistent(s.nis, s.gate, s.fix_row, b - a + 1),
                            lambda: restore(state, saved),
                            np.ones(fixes.epoch.size, bool), fix_fallbacks(fixes), t, notes)
    seg.flags[fixes.epoch[~kept] - a] |= FLAG_SKIPPED
    return seg, fixes.take(kept)


class KfPass(NamedTuple):
    """One pass of KfPasses (epochs a..b, row 0 epoch a): the forward filter's navigation rows, one-sigma of the
    error states and flags, and with smoothing the smoothed navigation rows and one-sigma (None without)."""

    nav: np.ndarray
    cal: np.ndarray
    sd: np.ndarray
    flags: np.ndarray
    nav_s: np.ndarray | None
    sd_s: np.ndarray | None


class KfPasses:
    """The SINS/odometer filter of 001 a pass at a time, its state carried from pass to pass: `run(prep, log, a, b)`
    filters epochs (a, b] (a the end of the last pass run) with CPOEM fixes from the last pass's points (`cpoem`) and
    with `smooth` runs the online RTS over the pass at its end (001 Fig. 4), whose points the next pass's fixes
    come from. `keep`, if given, keeps each pass's forward segment (with the smoother's per-epoch matrices, on disk)
    for rts_offline once the online RTS has read them. run_kf runs it over a whole log; an online run pass by pass as the passes end
    (estimators.shearer.online)."""

    def __init__(self, log: Log, cfg: Config, prep: Prepared, cpoem: bool, smooth: bool,
                 keep: PassStore | None = None):
        self.cfg, self.cpoem, self.smooth, self.keep = cfg, cpoem, smooth, keep
        self.nav, self.cal = prep.nav0.copy(), prep.cal0.copy()
        self.p = initial_covariance(cfg, log, prep.nav0[es.QUAT])
        self.q_psd, self.params = process_noise_psd(cfg), kf_params(cfg)
        self.nominal = np.zeros(es.N_NOMINAL)
        self.points: Points | None = None  # the last pass's CPOEM points (the first cut's: the face survey's)
        if cpoem:
            self.points = at_spacing(face_survey_points(log, prep)) if cfg.cpoem_face_survey else Points.empty()
        self.notes = list(prep.notes)
        self.n_fixes = self.n_gated = 0
        self._blocks = matrix_blocks(es.N_STATES)
        self._scratch = StoredInterval(es.N_STATES) if smooth and keep is None else None
        """The smoother's matrices of each pass in turn, when no pass is kept."""

    def run(self, prep: Prepared, log: Log, a: int, b: int) -> KfPass:
        cfg = self.cfg
        fixes = fixes_for(prep, cfg, log, a, b, self.points, self.notes) if self.cpoem else Fixes.empty()
        stored = StoredInterval(es.N_STATES, self.keep.folder) if self.keep is not None else self._scratch
        seg, fixes = _checked_segment(prep, cfg, a, b, fixes, self.q_psd, self.params,
                                      (self.nav, self.cal, self.p, self.nominal), self.notes, stored, self._blocks)
        self.n_fixes += fixes.epoch.size
        self.n_gated += int(np.sum(~(seg.nis <= fixes.gate)))
        out = KfPass(seg.nav, seg.cal, seg.sd, seg.flags, None, None)
        nav, p_dp = seg.nav, seg.p_dp
        if self.smooth:
            # Row 0's update is zero: the segment starts from the previous posterior.
            x_s, sd_s, p_dp, _ = rts_stored(seg.stored, seg.x_post, self._blocks, keep=es.DP)
            nav, cal_s = seg.nav.copy(), seg.cal.copy()
            _apply_rows(nav, cal_s, x_s - seg.x_post)
            out = out._replace(nav_s=nav, sd_s=sd_s)
        if self.keep is not None:
            self.keep.keep(a, seg, prep.t_kf[prep.span(a + 1, b)])
        if self.cpoem:
            self.points = segment_points(prep, cfg, a, b, nav, p_dp)
        return out

    def first_row(self, prep: Prepared) -> Solution:
        """Epoch 0's row as run_kf gives it, before any pass has run: the start state and covariance, no calibration
        (smoothed methods add FLAG_SMOOTHED)."""
        return make_solution(prep.t_kf[prep.span(0, 0)], self.cfg, self.nav[None], _sd(self.p)[None],
                             np.zeros(1, np.int32), np.zeros((1, es.N_CAL)), [])

    def finish(self, prep: Prepared) -> list[str]:
        """The run's notes, with the fixes gated and the odometer's gaps."""
        cfg, notes = self.cfg, self.notes
        if self.n_gated:
            notes.append(f"{self.n_gated} of {self.n_fixes} position fixes rejected by the innovation gate")
        if prep.odo_gaps:
            gaps = prep.odo_gaps
            notes.append(f"odometer: no data over {gaps} filter steps ({gaps / cfg.filter_rate_hz:.1f} s, first at "
                         f"t = {prep.t_first_gap:.1f} s): velocity updates skipped")
        return notes


def run_kf(log: Log, cfg: Config, prep: Prepared, cpoem: bool, smooth: bool, store: PassStore | None = None
           ) -> tuple[Solution, Solution | None]:
    """One forward run (KfPasses over the log's passes); with `smooth`, the online RTS at each pass end (its output
    and CPOEM points); with `store`, each pass kept for rts_offline."""
    fwd = _Forward(prep.n_kf)
    passes = KfPasses(log, cfg, prep, cpoem, smooth, store)
    fwd.nav[0], fwd.sd[0] = passes.nav, _sd(passes.p)
    if store is not None:
        store.start(passes, prep)
    smooth_nav = fwd.nav.copy() if smooth else None
    smooth_sd = fwd.sd.copy() if smooth else None
    for a, b in prep.segments:
        one = passes.run(prep, log, a, b)
        fwd.nav[a + 1:b + 1], fwd.cal[a + 1:b + 1] = one.nav[1:], one.cal[1:]
        fwd.sd[a + 1:b + 1], fwd.flags[a + 1:b + 1] = one.sd[1:], one.flags[1:]
        if smooth:
            smooth_nav[a + 1:b + 1], smooth_sd[a + 1:b + 1] = one.nav_s[1:], one.sd_s[1:]
        one = None  # the pass's arrays go before the next pass makes its own
    notes = passes.finish(prep)
    forward = make_solution(prep.t_kf, cfg, fwd.nav, fwd.sd, fwd.flags, fwd.cal, notes)
    smoothed = None
    if smooth:
        smoothed = make_solution(prep.t_kf, cfg, smooth_nav, smooth_sd, fwd.flags | FLAG_SMOOTHED, fwd.cal, notes)
    return forward, smoothed


class PassStore:
    """A forward run kept on disk for rts_offline (KfPasses' `keep`): each pass's smoother matrices (its
    StoredInterval) and its forward rows, a file each in `folder`. `smoothed` runs the offline smoother over them; a
    block of a pass is in memory at a time, so its memory does not grow with the run or the pass."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.saved: list[tuple[int, int]] = []  # the passes kept: epochs a..b
        self.matrices: dict[int, StoredInterval] = {}  # each kept pass's, by its first epoch a
        self.first: dict[str, np.ndarray] | None = None  # epoch 0's forward row

    def start(self, passes: KfPasses, prep: Prepared) -> None:
        """Epoch 0's forward row: the start state and its sigmas, no calibration, no flag."""
        self.first = {"t": prep.t_kf[prep.span(0, 0)].copy(), "nav": passes.nav[None].copy(),
                      "cal": np.zeros((1, es.N_CAL)), "sd": _sd(passes.p)[None], "flags": np.zeros(1, np.int32)}

    def keep(self, a: int, seg: _Segment, t: np.ndarray) -> None:
        """Pass a's segment, epochs a + 1.. at times t."""
        self._save(a, "forward", {"x_post": seg.x_post, "t": t, "nav": seg.nav[1:], "cal": seg.cal[1:],
                                  "sd": seg.sd[1:], "flags": seg.flags[1:]})
        seg.stored.close()  # its files stay; a long run keeps many
        self.matrices[a] = seg.stored
        self.saved.append((a, a + seg.x_post.shape[0] - 1))

    def _save(self, a: int, kind: str, arrays: dict[str, np.ndarray]) -> None:
        """A pass's arrays, a .npy file each (no archive to checksum: these are gigabytes on a long run)."""
        (self.folder / f"{kind}_{a}").mkdir()
        for key, value in arrays.items():
            np.save(self._file(a, key, kind), value)

    def _file(self, a: int, key: str, kind: str = "forward") -> Path:
        return self.folder / f"{kind}_{a}" / f"{key}.npy"

    def _load(self, a: int, keys: tuple[str, ...], kind: str = "forward") -> dict[str, np.ndarray]:
        return {key: np.load(self._file(a, key, kind)) for key in keys}

    def _rows(self, a: int, kind: str = "forward") -> dict[str, np.ndarray]:
        return self._load(a, ROW_KEYS, kind)

    def smoothed(self, cfg: Config) -> Iterator[Solution]:
        """rts_offline's rows (001 eqs. 29-31: one backward pass over the whole forward run, pass by pass from the
        end), a pass at a time in time order, epoch 0's row with the first.

        Row 0 of a stored pass is the previous pass's last epoch: its update is that pass's last row, and the smoothed
        value at a pass's last epoch is the one the later pass's smoother computed; the run's last epoch keeps its
        forward value. Each pass's smoothed rows go to a file of their own on the way back."""
        if not self.saved:  # no pass: the start
            first = self.first
            yield make_solution(first["t"], cfg, first["nav"], first["sd"], first["flags"] | FLAG_SMOOTHED,
                                first["cal"], [])
            return
        last_update = {}
        for a, b in self.saved:
            last_update[b] = np.load(self._file(a, "x_post"), mmap_mode="r")[-1].copy()
        known, blocks = None, matrix_blocks(es.N_STATES)
        for i in range(len(self.saved) - 1, -1, -1):
            a, b = self.saved[i]
            own = self._rows(a)
            start = self.first if i == 0 else {k: v[-1:] for k, v in self._rows(self.saved[i - 1][0]).items()}
            rows = {k: np.concatenate([start[k], own[k][:-1]]) for k in ROW_KEYS}  # epochs a..b-1
            known = _smooth_stored(self.matrices.pop(a), self._load(a, ("x_post",))["x_post"],
                                   last_update.get(a, np.zeros(es.N_STATES)), known, rows, blocks)
            self._save(a, "smoothed", rows)
        for i, (a, b) in enumerate(self.saved):
            rows = self._rows(a, "smoothed")
            end = self._rows(self.saved[i + 1][0], "smoothed") if i + 1 < len(self.saved) else self._rows(a)
            rows = {k: np.concatenate([v if i == 0 else v[1:], end[k][:1] if i + 1 < len(self.saved) else end[k][-1:]])
                    for k, v in rows.items()}
            yield make_solution(rows["t"], cfg, rows["nav"], rows["sd"],
                                rows["flags"] | FLAG_SMOOTHED, rows["cal"], [])


ROW_KEYS = ("t", "nav", "cal", "sd", "flags")
"""The forward rows PassStore keeps of each pass."""


def rts_offline(cfg: Config, store: PassStore, notes: list[str]) -> Solution:
    """The offline smoother (PassStore.smoothed) over a whole forward run kept in `store` (`notes`: the forward
    run's)."""
    sol = join_rows(list(store.smoothed(cfg)))
    sol.notes = list(notes)
    return sol


def _smooth_stored(stored: StoredInterval, x_post: np.ndarray, x_first: np.ndarray,
                   known: tuple[np.ndarray, np.ndarray] | None, rows: dict[str, np.ndarray],
                   blocks: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The offline smoother's backward pass over one stored pass (its matrices `stored` and updates `x_post`; its
    row 0's update x_first; `known` the smoothed state and covariance at its last epoch, from the later pass),
    applied to the forward `rows` of its epochs but the last (nav, cal, sd) in place (`blocks`: rts.matrix_blocks);
    returns the smoothed state and covariance at its first epoch."""
    x_post[0] = x_first
    x_s, sd_s, _, p_s0 = rts_stored(stored, x_post, blocks, known)
    _apply_rows(rows["nav"], rows["cal"], x_s[:-1] - x_post[:-1])
    rows["sd"][:] = sd_s[:-1]
    return x_s[0].copy(), p_s0
