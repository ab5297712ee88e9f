"""The federated filter kernel (estimators.shearer.federated_filter) run over a prepared log, pass by pass: the
state it carries from one pass to the next, its output at every epoch, and the Solution with the fusion columns.

003's magnetometer filters (estimators.shearer.adaptive_federated_mag) give it the magnetometer readings per
epoch; 004's rail kinematics model (estimators.shearer.rail_kinematics) gives it each pass's rail fixes and the
detectors' parameters, and takes the pass's estimate for the next pass's points.
"""

from __future__ import annotations

import numpy as np

from estimators.faults.detectors import fsprt_state
from estimators.io.log import Log
from estimators.io.logformat import FLAG_MAG, FLAG_SKIPPED
from estimators.kalman import error_state as es
from estimators.shearer import federated_filter as fk
from estimators.shearer import rail_fix_update as rf
from estimators.shearer.config import Config
from estimators.shearer.health import (
    filter_lost,
    fix_fallbacks,
    restore,
    run_checked,
    snapshot,
)
from estimators.shearer.position_fixes import Fixes
from estimators.shearer.positioning import (
    initial_covariance,
    kf_params,
    process_noise_psd,
)
from estimators.shearer.prepare import Prepared
from estimators.shearer.solution import Solution, make_solution

PassFixes = tuple[Fixes, np.ndarray]
"""A pass's rail-model fixes with each one's var_floor (F,) (rf.rail_fix_update)."""


def _epoch_output(n: int, r_yaw: float) -> fk.EpochOutput:
    """Output rows for n epochs as the kernel finds them (rows it does not write keep these)."""
    return fk.EpochOutput(np.zeros((n, es.N_NAV)), np.zeros((n, es.N_CAL)), np.zeros((n, es.N_STATES)),
                          np.zeros(n, np.int32), np.zeros(n, np.int32), np.full((n, fk.N_SUB), np.nan),
                          np.full(n, r_yaw), np.full(n, np.nan), np.full((n, fk.N_SUB, fk.N_DELTA), np.nan))


class FederatedRun:
    """One run of the federated (or centralized) filter over the segments of a log, a pass at a time (`run_pass`,
    whose output rows are the pass's own: an online run keeps nothing of the passes before).

    mag: (calibrated mean reading per epoch (K, 3), NaN where none; the M_* vector), None without magnetometer;
    det_params: the D_* vector of the rail model's detectors (rf), None without rail fixes. With `whole`, `out`
    gathers the kernel's output at every epoch of the log (fk.EpochOutput) and `fixes` per pass the rail fixes'
    epochs, points, detector statistics and whether each was applied, for `solution`."""

    def __init__(self, log: Log, cfg: Config, prep: Prepared, federated: bool,
                 mag: tuple[np.ndarray, np.ndarray] | None = None, det_params: np.ndarray | None = None,
                 whole: bool = True):
        self.prep, self.cfg = prep, cfg
        self.mag_b, params_m = mag if mag is not None else (None, np.zeros(fk.N_MAG_PARAMS))
        self.tuning = fk.Tuning(process_noise_psd(cfg), kf_params(cfg), params_m,
                                det_params if det_params is not None else np.zeros(rf.N_DET_PARAMS))
        self.p0 = initial_covariance(cfg, log, prep.nav0[es.QUAT])
        self.last = _epoch_output(1, params_m[fk.M_R_YAW])  # the last pass's last row (its row 0 for the next)
        self.last.nav[0], self.last.cal[0], self.last.sd[0] = prep.nav0, prep.cal0, np.sqrt(np.diag(self.p0))
        self.out = _epoch_output(prep.n_kf + 1, params_m[fk.M_R_YAW]) if whole else None
        if self.out is not None:
            self.out.nav[0], self.out.cal[0] = prep.nav0, prep.cal0
        self.fixes: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []  # epoch, llh, stats, applied
        p_sub, beta = fk.initial_covariances(self.p0, federated)
        detectors = rf.DetectorState(fsprt_state(rf.DET_DOF), np.zeros(1, np.int8), np.zeros(rf.N_COUNTS, np.int64),
                                     np.zeros((max(cfg.detector.window, 1), 2)))
        self.state = fk.FilterState(prep.nav0.copy(), prep.cal0.copy(), p_sub, beta, np.zeros(es.N_NOMINAL),
                                    np.zeros((cfg.mag.window, 1, 1)), np.zeros(1, np.int64), detectors)
        self.mode = fk.FEDERATED if federated else fk.CENTRALIZED
        self.health_notes: list[str] = []  # what the health monitor did (run_pass)
        self.pass_fixes: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        """The last pass's rail fixes: epochs, points, detector statistics, whether each was applied."""
        self.n_disturbed = self.n_invalid = 0  # epochs with the magnetometer disturbed, a sub-filter unusable
        self.t_disturbed = np.nan  # the first disturbed epoch's time

    def run_pass(self, a: int, b: int, rail: PassFixes | None = None) -> tuple[np.ndarray, fk.EpochOutput]:
        """The filter over epochs (a, b] with the pass's rail fixes (none: None), under the health monitor
        (estimators.shearer.health.run_checked: a pass that loses track runs again from its start with fewer
        fixes, then without the magnetometer); returns the fixes' detector statistics (F, 3) (NaN for a fix not
        tested or left out) and the kernel's output over epochs a..b (row 0 the last pass's last)."""
        prep, m, span = self.prep, b - a + 1, self.prep.span(a, b)
        fixes, var_floor = rail if rail is not None else (Fixes.empty(), np.zeros(0))
        self.state.det.counts[rf.COUNT_TESTED] = 0  # rail fixes tested in this pass (rail_kinematics.ARM_FIXES)
        start = snapshot(self.state)
        mag_b = self.mag_b[a:b + 1] if self.mag_b is not None else np.full((m, 3), np.nan)
        mag = np.isfinite(mag_b[1:]).any()
        everything = np.ones(fixes.epoch.size, bool)
        fallbacks = [(label, (keep, True)) for label, keep in fix_fallbacks(fixes)]
        if mag:
            fallbacks.append(("without any position fix or the magnetometer", (~everything, False)))
        out = _epoch_output(m, self.tuning.mag_params[fk.M_R_YAW])
        for field, last in zip(out, self.last):
            field[0] = last[0]
        mech = prep.mech(a, b)
        sensors = fk.Sensors(prep.steps, 0, mech.t, mech.phi_b, mech.dv_b, prep.odo[span], prep.mode[span],
                             mag_b)

        def run(arg):
            keep, use_mag = arg
            taken = fixes.take(keep)
            results = rf.RailResults(np.full((taken.epoch.size, 3), np.nan), np.zeros(taken.epoch.size, np.int8))
            kernel_fixes = rf.RailFixes(taken.epoch - a, taken.llh, taken.r, taken.advance, var_floor[keep],
                                        ~np.isfinite(taken.gate))
            fk.run_afkf(self.mode, 0, m - 1, sensors if use_mag else sensors._replace(mag_b=np.full((m, 3), np.nan)),
                        kernel_fixes, results, self.tuning, self.state, out)
            return results

        def lost(_results):
            return filter_lost(prep.t_kf[span], out.nav, out.sd, self.cfg)

        results, (keep, _) = run_checked(run, lost, lambda: restore(self.state, start), (everything, True),
                                         fallbacks, prep.t_kf[span], self.health_notes)
        out.flags[fixes.epoch[~keep] - a] |= FLAG_SKIPPED
        stats = np.full((fixes.epoch.size, 3), np.nan)
        applied = np.zeros(fixes.epoch.size, np.int8)
        stats[keep], applied[keep] = results.stats, results.applied
        self.last = fk.EpochOutput(*(field[-1:].copy() for field in out))
        self.pass_fixes = (fixes.epoch, fixes.llh, stats, applied)
        disturbed = out.mag_flags[1:] & fk.MAG_DISTURBED > 0
        if disturbed.any() and not self.n_disturbed:
            self.t_disturbed = prep.t_kf[span][1 + np.argmax(disturbed)]
        self.n_disturbed += int(disturbed.sum())
        self.n_invalid += int(np.sum(out.mag_flags[1:] & fk.SUB_INVALID > 0))
        if self.out is not None:
            for whole, rows in zip(self.out, out):
                whole[a + 1:b + 1] = rows[1:]
            self.fixes.append(self.pass_fixes)
        return stats, out

    def first_row(self) -> fk.EpochOutput:
        """Epoch 0's output row as `solution` gives it: the start state with the initial one-sigma."""
        row = _epoch_output(1, self.tuning.mag_params[fk.M_R_YAW])
        row.nav[0], row.cal[0], row.sd[0] = self.prep.nav0, self.prep.cal0, np.sqrt(np.diag(self.p0))
        return row

    def rows(self, t: np.ndarray, out: fk.EpochOutput, notes: list[str]) -> Solution:
        """The Solution, with its fusion columns, of output rows `out` at epochs t (a pass's, or the run's)."""
        flags = out.flags | np.where(out.mag_flags & fk.MAG_USED, FLAG_MAG, 0).astype(np.int32)
        sol = make_solution(t, self.cfg, out.nav, out.sd, flags, out.cal, notes)
        sol.fusion = fusion_columns(t, out.beta, out.r_yaw, out.yaw_innov, out.mag_flags, out.sub_delta)
        return sol

    def solution(self, notes: list[str]) -> Solution:
        """The run's Solution (notes: the method's so far; the fusion's are added) with its fusion columns."""
        self.out.sd[0] = np.sqrt(np.diag(self.p0))
        return self.rows(self.prep.t_kf, self.out, notes + self.notes())

    def notes(self) -> list[str]:
        """What the health monitor did and what the fusion found over the passes run."""
        notes = list(self.health_notes)
        disturbed = self.n_disturbed
        if disturbed:
            notes.append(f"mag: {disturbed} epochs ({disturbed / self.cfg.filter_rate_hz:.1f} s, first at t = "
                         f"{self.t_disturbed:.1f} s) disturbed (field strength or dip off the model's), yaw updates "
                         f"left out")
        if self.n_invalid:
            notes.append(f"fusion: a sub-filter's covariance was unusable at {self.n_invalid} epochs (weight 0, "
                         f"restarted)")
        return notes


def fusion_columns(t, beta, r_yaw, innov, mag_flags, delta) -> dict[str, np.ndarray]:
    """ESTIMATE_FUSION columns (estimators.io.logformat). delta (K, N_SUB, N_DELTA): x_i - x_g of position and
    attitude error (fk.DELTA_*); a sub-filter's position is the global one minus its position-error difference,
    its yaw the global one plus the difference of the attitude error about up."""
    out = {"t": t, "beta_odometer": beta[:, fk.SUB_ODOMETER], "beta_aiding": beta[:, fk.SUB_AIDING], "r_yaw": r_yaw,
           "yaw_innovation": innov, "mag_flags": mag_flags}
    for k, sub in ((fk.SUB_ODOMETER, "odometer"), (fk.SUB_AIDING, "aiding")):
        for i, a in enumerate("enu"):
            out[f"{sub}_d_pos_{a}"] = -delta[:, k, fk.DELTA_POS.start + i]
        out[f"{sub}_d_yaw"] = delta[:, k, fk.DELTA_ATT.start + 2]
    return out
