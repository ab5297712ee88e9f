"""The sensor log prepared for the shearer filters (001, 003, 004): the IMU increments in the body frame and
coning/sculling-compensated at the mechanization rate, the filter epochs, the odometer at them, the straight
cuts and the segments (passes), and the start state.

Passes and face ends are found from the odometer alone: a straight cut is a run of travel in one direction
longer than STRAIGHT_CUT_FRACTION of the face (the distance between the two surveyed face-end points); the pass
ends when the shearer stands after it. The first cycle has no CPOEM points; its face ends are surveyed (the survey
stream). The start pose comes from the survey (position, heading) and from levelling the accelerometers while the
shearer stands before the first cut.

The IMU increments are not held whole: `Prepared.mech(a, b)` compensates a pass's rows (epochs a..b) when a filter
runs it, read from the log's ImuRows, so the estimators' memory holds a pass of increments, not the run's.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from estimators.io.log import ImuRows, Log
from estimators.kalman import error_state as es
from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_mat,
    euler_to_quat,
    quat_rotate,
    quat_to_euler,
)
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.cpoem import RamLog
from estimators.shearer.odometer_filter import (
    MODE_MOVING,
    MODE_NO_DATA,
    MODE_SETTLING,
    MODE_STANDING,
)
from estimators.sins.fine_alignment import fine_align
from estimators.sins.strapdown import compensated_increments


def _odometer_at(log: Log, t_kf: np.ndarray, settle_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Odometer distance at the epochs and the odometer channel of each interval (t[j-1], t[j]]
    (estimators.shearer.odometer_filter MODE_*): moving where the odometer counted or showed a haulage direction;
    standing where it shows neither from settle_s before the interval to settle_s after it (the machine may still
    coast at a stop, or creep before its direction signal comes on at a start), settling in between; no data
    outside the log or where the interval overlaps a dropout (two consecutive samples more than 2.5 nominal
    periods apart). The look-ahead makes a stand known settle_s late, which an online run waits for."""
    t = log.odo_t
    dist = np.interp(t_kf, t, log.odo_distance)
    lo, hi = t_kf[:-1], t_kf[1:]
    covered = (lo >= t[0]) & (hi <= t[-1])
    if t.size > 1:
        step = np.diff(t)
        gap = np.flatnonzero(step > 2.5 * np.median(step))
        if gap.size:
            gap_start, gap_end = t[gap], t[gap + 1]  # disjoint and sorted
            k = np.searchsorted(gap_end, lo, side="right")  # the first dropout ending after the interval starts
            covered &= ~((k < gap.size) & (gap_start[np.minimum(k, gap.size - 1)] < hi))
    moving = np.concatenate([[0], np.cumsum(log.odo_direction != 0)])[np.searchsorted(t, t_kf, side="right")]
    moved = (np.diff(moving) > 0) | (np.abs(np.diff(dist)) > 0)
    active = (log.odo_direction != 0) | (np.diff(log.odo_distance, prepend=log.odo_distance[:1]) != 0)
    t_active = t[active]
    last = np.searchsorted(t_active, lo, side="right") - 1  # the last sample showing motion up to the start
    after = np.searchsorted(t_active, hi, side="left")  # the first one from the end on
    if t_active.size == 0:  # the machine never moves in this log
        settled = np.ones(lo.size, bool)
    else:
        settled = (((last < 0) | (lo - t_active[np.maximum(last, 0)] >= settle_s))
                   & ((after >= t_active.size) | (t_active[np.minimum(after, t_active.size - 1)] - hi >= settle_s)))
    still = np.where(settled, MODE_STANDING, MODE_SETTLING)
    mode = np.where(covered, np.where(moved, MODE_MOVING, still), MODE_NO_DATA)
    return dist, np.concatenate([[MODE_STANDING], mode]).astype(np.int8)


STRAIGHT_CUT_FRACTION = 0.8
"""A run of travel in one direction longer than this fraction of the face is a straight cut (a sump or a cut-out
into the snake covers the snake and the shearer, up to about half of a short face)."""


def straight_cuts(u: np.ndarray, mode: np.ndarray, face_travel: float) -> list[tuple[int, int]]:
    """(first, last) epochs of each run of travel in one direction longer than STRAIGHT_CUT_FRACTION of the
    face."""
    du = np.diff(u, prepend=u[0])
    moving = np.flatnonzero((mode == MODE_MOVING) & (du != 0))
    if moving.size == 0:
        return []
    sign = np.sign(du[moving])
    breaks = np.flatnonzero(sign[1:] != sign[:-1]) + 1
    runs = []
    for grp in np.split(moving, breaks):
        if abs(u[grp[-1]] - u[grp[0] - 1]) > STRAIGHT_CUT_FRACTION * face_travel:
            runs.append((int(grp[0]), int(grp[-1])))
    return runs


def _initial_state(log: Log, prep: Prepared, cfg: Config) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Navigation vector at t[0] (IMU point) and the start calibration, from the stand before the first cut:
    survey position and heading, level from the accelerometers (coarse), then the fine alignment of 000
    (estimators.sins.fine_alignment, EKF) over the stand, whose mean attitude over its last seconds and bias estimates
    start the filter. A stand the fine alignment finds moving is levelled only (noted)."""
    notes = []
    steps = prep.steps
    first_move = np.flatnonzero(prep.mode == MODE_MOVING)
    stand_end = (first_move[0] - 1) * steps if first_move.size else prep.n_kf * steps
    dt = prep.mech_dt
    n = int(min(stand_end, cfg.level_window_s / dt))
    if n < max(5, int(1.0 / dt)):
        raise PositioningError(f"odometer: the shearer moves {n * dt:.2f} s after the start; levelling needs at "
                               f"least 1 s of standing before the first cut")
    stand = prep.mech(0, -(-n // steps))
    f_b = stand.dv_b[:n].sum(axis=0) / (n * dt)
    pitch = np.arcsin(np.clip(f_b[1] / np.linalg.norm(f_b), -1, 1))
    roll = np.arctan2(-f_b[0], f_b[2])
    if not np.isfinite(log.survey_yaw[0]):
        raise PositioningError("survey: the first row needs the start heading (yaw); a MEMS gyro cannot find it")
    q_nb = euler_to_quat(pitch, roll, log.survey_yaw[0])
    lat, lon, h = log.survey_llh[0]
    cal = np.zeros(es.N_CAL)
    imu_dt = prep.imu_dt
    n_imu = round(n * dt / imu_dt)
    _, dtheta_s, dv_s = prep.increments(0, n_imu)
    res = fine_align(dtheta_s[1:], dv_s[1:], imu_dt, lat, q_nb, (cfg.imu.gyro_arw, cfg.imu.accel_vrw),
                     np.array([cfg.sd_level0, cfg.sd_level0, log.survey_sd[0, 2]]), "ekf", h=h,
                     gyro_bias_sigma=cfg.imu.gyro_bias, accel_bias_sigma=cfg.imu.accel_bias,
                     velocity_sigma=cfg.r_zupt, rate_sigma=cfg.r_zaru, on_motion="flag")
    if res.motion_t is None:
        q_nb = res.attitude(min(10.0, 0.5 * n * dt))
        cal[es.CAL_ACCEL.start:es.CAL_ACCEL.start + 2] = res.accel_bias[-1]
        cal[es.CAL_GYRO] = res.gyro_bias[-1]
        p0, r0, _ = quat_to_euler(q_nb)
        notes.append(f"fine alignment over {n * dt:.1f} s of standing: pitch {np.degrees(p0):.3f} deg, roll "
                     f"{np.degrees(r0):.3f} deg, gyro bias {np.round(np.degrees(cal[es.CAL_GYRO]) * 3600, 1)} deg/h")
    else:
        notes.append(f"the stand looks moving from {res.motion_t:.1f} s: levelled only, pitch "
                     f"{np.degrees(pitch):.3f} deg, roll {np.degrees(roll):.3f} deg")
    off = quat_rotate(q_nb, np.asarray(cfg.lever_arm_m, float))
    r_m, r_n = earth.radii(lat)
    nav = np.zeros(es.N_NAV)
    nav[es.LAT], nav[es.LON], nav[es.HGT] = (lat + off[1] / (r_m + h), lon + off[0] / ((r_n + h) * np.cos(lat)),
                                             h + off[2])
    nav[es.QUAT] = q_nb
    return nav, cal, notes


@dataclass(frozen=True)
class Mech:
    """The mechanization increments of epochs a..b (Prepared.mech): update times t (U + 1,), row 0 at epoch a, and
    the coning/sculling-compensated rotation vectors phi_b and velocity increments dv_b (U, 3) over
    (t[u], t[u + 1]], U = (b - a) * steps."""

    t: np.ndarray
    phi_b: np.ndarray
    dv_b: np.ndarray


@dataclass
class Prepared:
    """The log resampled for the filters: filter epochs, odometer, cuts, segments, start state, and the IMU
    increments of any epochs on demand (`mech`, `increments`)."""

    imu: ImuRows
    mat_bs: np.ndarray
    imu_dt: float
    n_samples: int
    steps: int
    t_kf: np.ndarray
    odo: np.ndarray
    mode: np.ndarray
    cuts: list[tuple[int, int]]
    segments: list[tuple[int, int]]
    survey_epochs: np.ndarray
    rams: RamLog | None
    nav0: np.ndarray
    cal0: np.ndarray
    notes: list[str]

    @property
    def n_kf(self) -> int:
        """The last filter epoch (epochs 0..n_kf)."""
        return self.t_kf.size - 1

    @property
    def mech_dt(self) -> float:
        """The first mechanization interval [s]."""
        t = self.increments(0, self.n_samples)[0]
        return float(t[-1] - t[0])

    def increments(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU increments (row k over (t[k-1], t[k]]) of samples i0+1..i1 turned into b, with row 0 at sample i0
        (its increments unused): sample 0 is the start, a period before the log's first row, with zero increments."""
        t, dtheta, dv = self.imu.read(max(i0 - 1, 0), i1)
        if i0 == 0:
            t = np.concatenate([[t[0] - 1.0 / (1.0 / self.imu_dt)], t])
            dtheta, dv = np.concatenate([np.zeros((1, 3)), dtheta]), np.concatenate([np.zeros((1, 3)), dv])
        return t, dtheta @ self.mat_bs.T, dv @ self.mat_bs.T

    def epoch_increments(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """`increments` of epochs a..b (row 0 at epoch a), and the log's row number of row 0 (-1: the start)."""
        per_epoch = self.steps * self.n_samples
        return *self.increments(a * per_epoch, b * per_epoch), a * per_epoch - 1

    def mech(self, a: int, b: int) -> Mech:
        """The mechanization increments of epochs a..b (Mech); PositioningError naming the log's first row that
        compensation refuses."""
        *increments, first_row = self.epoch_increments(a, b)
        try:
            return Mech(*compensated_increments(*increments, self.n_samples, first_row))
        except ValueError as err:
            raise PositioningError(f"imu: {err}") from None


def body_mounting(cfg: Config) -> np.ndarray:
    """C_s^b of the calibrated mounting: the IMU increments turned from the sensor axes into b."""
    return euler_to_mat(*cfg.imu_mounting_rad)


def prepare(log: Log, cfg: Config) -> Prepared:
    """The log resampled for the filters (Prepared); PositioningError names the stream a log cannot be used for."""
    if log.survey_t.size == 0:
        raise PositioningError("survey: no rows; the start position and heading must be surveyed")
    imu_dt = log.imu.period()
    imu_rate = 1.0 / imu_dt
    steps_f = imu_rate / cfg.n_samples / cfg.filter_rate_hz
    if abs(steps_f - round(steps_f)) > 1e-6 or round(steps_f) < 1:
        raise PositioningError(f"imu: {imu_rate:.6g} Hz is not {cfg.n_samples} x {cfg.filter_rate_hz:g} Hz x an "
                               f"integer; choose filter_rate_hz to divide the mechanization rate")
    steps = round(steps_f)
    per_epoch = steps * cfg.n_samples
    n_kf = log.imu.size // cfg.n_samples // steps
    if n_kf < 1:
        raise PositioningError(f"imu: {log.imu.size} rows, fewer than one filter epoch ({per_epoch} rows)")
    t_kf = np.concatenate([[np.nan], log.imu.times_at(np.arange(1, n_kf + 1) * per_epoch - 1)])
    prep = Prepared(log.imu, body_mounting(cfg), imu_dt, cfg.n_samples, steps, t_kf, np.zeros(0), np.zeros(0, np.int8),
                    [], [], np.zeros(0, int), None, np.zeros(es.N_NAV), np.zeros(es.N_CAL), [])
    t_kf[0] = prep.increments(0, 1)[0][0]
    prep.odo, prep.mode = _odometer_at(log, t_kf, cfg.stand_settle_s)
    prep.nav0, prep.cal0, prep.notes = _initial_state(log, prep, cfg)
    u = prep.odo - prep.odo[0]
    if log.survey_t.size >= 2:
        d = earth.lla_to_enu(*log.survey_llh[1], *log.survey_llh[0])
        face_travel = float(np.hypot(d[0], d[1]))
    else:
        face_travel = float(np.ptp(u))
        prep.notes.append("survey has no far face end: face length taken from the odometer")
    prep.cuts = straight_cuts(u, prep.mode, face_travel)
    settle = round(cfg.filter_rate_hz)  # one second of the stand after the cut belongs to the pass
    ends = sorted({min(last + 1 + settle, n_kf) for _, last in prep.cuts})
    bounds = [0] + [e for e in ends if 0 < e < n_kf] + [n_kf]
    prep.segments = list(itertools.pairwise(bounds))
    prep.survey_epochs = np.minimum(np.searchsorted(t_kf, log.survey_t[1:]), n_kf)
    if log.ram_t.size and len(cfg.support_u_m) >= 2:
        prep.rams = RamLog.from_rows(log.ram_t, log.ram_support, log.ram_extension, log.ram_valid, cfg.support_u_m,
                                     cfg.ram_noise_sd)
    return prep
