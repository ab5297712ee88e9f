"""Shearer positioning of 001: SINS/odometer Kalman filter, CPOEM position fixes, RTS smoothing at each face end,
and the dead-reckoning baseline, run on a sensor log.

Methods (each an estimates/NAME stream):

* ``dr``            the "traditional method" of 001 section 4: free SINS attitude and odometer distance;
* ``dr_compensated``  the same with the sensor biases, odometer scale and mounting estimated by ``kf_cpoem_rts``;
* ``kf``            SINS/odometer filter (001 eqs. 12-20) with zero-velocity and zero-rate updates at stands;
* ``kf_cpoem``      plus CPOEM fixes (001 eqs. 6, 21-22) whose points come from the forward filter;
* ``kf_cpoem_rts``  plus the online RTS smoother (001 eqs. 28-31, Fig. 4) run at each face end over the pass just
                    finished; the smoothed points feed the next cycle's fixes, the output is the smoothed pass;
* ``rts_offline``   one RTS pass over the whole run of ``kf_cpoem_rts``'s forward filter;
* ``ckf_mag``       003's centralized SINS/odometer/magnetometer filter, needs the mag stream;
* ``afkf``          003's adaptive federated filter with the magnetometer disturbance test;
* ``fkf_rail``      004's federated SINS/odometer + SINS/rail-kinematics-model filter with fault detection and
                    isolation of the rail model (these three: estimators.shearer.federated).

Passes and face ends are found from the odometer alone: a straight cut is a run of travel in one direction
longer than half the face (the distance between the two surveyed face-end points); the pass ends when the
shearer stands after it. The first cycle has no CPOEM points; its face ends are surveyed (the survey stream).
The start pose comes from the survey (position, heading) and from levelling the accelerometers while the
shearer stands before the first cut.
"""

from __future__ import annotations

import itertools
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numba as nb
import numpy as np

from estimators.faults.detectors import DetectorConfig
from estimators.io.logformat import FLAG_SMOOTHED, NONORTH_AXES
from estimators.kalman.rts import rts_backward
from estimators.nav import earth
from estimators.nav.rotations import (
    euler_to_mat,
    euler_to_quat,
    quat_rotate,
    quat_to_euler,
    quat_to_mat,
    rotvec_to_quat,
)
from estimators.shearer import odometer_filter as kf
from estimators.shearer.cpoem import Points, RamLog, crossings, predict_fixes, record
from estimators.shearer.face_line import fit_face_line
from estimators.sins.fine_alignment import fine_align
from estimators.sins.strapdown import compensated_increments, mechanize

METHODS = ("dr", "dr_compensated", "kf", "kf_cpoem", "kf_cpoem_rts", "rts_offline", "ckf_mag", "afkf", "fkf_rail")
DEG = np.pi / 180


class PositioningError(ValueError):
    """A log the positioning cannot use; the message names the stream and what to fix."""


@dataclass(frozen=True)
class ImuNoise:
    """The IMU's error budget as the filter models it (SI): white noise, turn-on bias sigma, bias random walk."""

    gyro_arw: float  # rad/sqrt(s)
    accel_vrw: float  # m/s/sqrt(s)
    gyro_bias: float  # rad/s, one-sigma turn-on bias
    accel_bias: float  # m/s^2
    gyro_bias_psd: float = 0.0  # rad^2/s^3, random-walk density of the in-run bias
    accel_bias_psd: float = 0.0  # m^2/s^5
    accel_nonorth: float = 1e-6  # rad, one-sigma of each element of the accelerometers' symmetric A (tiny: none)


@dataclass(frozen=True)
class MagSettings:
    """The shearer magnetometer as the SINS/magnetometer filters (estimators.afkf) use it. Units SI."""

    date: str = "2026-06-01"
    """Date for the geomagnetic model (declination, dip and strength at the start position)."""
    noise_t: float = 1e-7
    """White noise per axis [T]."""
    extra_sigma: float = 0.5 * DEG
    """Yaw error [rad] the white noise does not cover: calibration residual, motor field, declination error. The
    nominal yaw variance is noise_t^2 / (H^2 n) + extra_sigma^2 for n readings per filter epoch (002 eq. 27)."""
    window: int = 50
    """Innovations in the noise-estimation window (003 section 4.2) [filter epochs]."""
    min_samples: int = 20
    """Innovations needed before the window's estimate replaces the nominal variance."""
    field_check: bool = True
    """Leave out readings whose strength or dip disagrees with the geomagnetic model (the disturbance test)."""
    norm_tol: float = 0.03
    """Largest relative deviation of the field strength from the model's."""
    dip_tol: float = 2.0 * DEG
    """Largest deviation of the dip from the model's [rad]."""
    gate: float = float("inf")
    """Normalized innovation squared above which a yaw update is left out."""
    saturation_t: float = 8e-5
    """Range of the magnetometer [T]: a component at or beyond it is saturated (MTi-30: +-0.8 G)."""
    hard_iron_t: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Hard-iron offset h [T] of an earlier calibration (estimators.nav.geomagnetic.fit_ellipsoid), removed first."""
    soft_iron_correction: tuple[tuple[float, ...], ...] = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    """S^-1 of that calibration: B_b = S^-1 (b_b - h)."""
    sharing: str = "trace"
    """Information-sharing rule (estimators.kalman.fusion): "trace" (003 section 4.3) or "inverse_trace"."""


@dataclass(frozen=True)
class Config:
    """Everything the filter needs besides the log. Units SI."""

    imu: ImuNoise
    lever_arm_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """IMU position relative to the body reference point (the point reported), body frame."""
    imu_mounting_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Calibrated mounting of the IMU axes s in the body frame, C_s^b = Rz Rx Ry of (about x, about y, about z):
    pitch and roll from the static calibration of 000 section 6.1-6.2; about z what the installation survey says.
    The increments are turned into b before the mechanization."""
    metres_per_pulse: float = 0.002
    support_u_m: tuple[float, ...] = ()
    """Face coordinate (odometer travel from the start pose) of each support, for the CPOEM advance."""
    n_samples: int = 4
    filter_rate_hz: float = 10.0
    cpoem_spacing_m: float = 2.0
    r_lateral: float = 0.02  # motion-constraint noise across the face [m/s] (suspension, drum vibration)
    r_vertical: float = 0.02
    r_odometer: float = 0.002  # odometer velocity noise besides quantization [m/s]
    r_zupt: float = 0.002  # [m/s]
    r_zaru: float = 5e-4  # zero-rate noise: idle vibration of the machine [rad/s]
    advance_sd: float = 0.005  # advance from the ram strokes [m]
    ram_noise_sd: float = 1e-4  # one-sigma noise of a push-ram reading [m]
    path_sd: float = 0.03  # the pans' running line between cycles beyond the measured advance [m]
    path_along_sd: float = 0.05
    """The same along the face [m]: the odometer counts path length, and the cut-out runs diagonally through the
    snake (a web over a snake of 8 pans adds about 5 cm), so a face coordinate shifts at every face end."""
    fix_gate: float = 40.0  # normalized innovation squared above which a CPOEM fix is rejected (3 dof); surveyed
    # face ends are trusted, never gated
    sd_velocity0: float = 0.01
    sd_level0: float = 0.3 * DEG
    level_from_accelerometers: bool = True
    """P0 of the level: the start attitude is levelled with the accelerometers, so its tilt error is the one the
    accelerometers' bias and non-orthogonality put there (initial_covariance), plus sd_level0 independent of them.
    False: sd_level0 alone, independent (001 Appendix A's diagonal P0)."""
    sd_odo_mount0: float = 1.0 * DEG
    sd_odo_scale0: float = 0.01
    p0_scale: float = 1.0
    q_scale: float = 1.0
    level_window_s: float = 60.0
    speed_tau_s: float = 20.0
    """Time constant [s] of the odometer speed the velocity measurement is linearized at: long, because the
    quantization error of an encoder at constant speed is a sawtooth, correlated over many epochs."""
    force_tau_s: float = 5.0
    """Time constant [s] of each of the two low-pass stages of the specific force the error dynamics are linearized
    at (estimators.shearer.odometer_filter.transition). The drum tone (0.5-1 Hz) shakes the IMU horizontally; its velocity is in
    the innovations, and an F that carries its acceleration correlates the heading gain with that velocity, which
    rectifies into a heading drift (9 deg/h on seed001 with an error-free IMU through one 2 s stage). Two 5 s
    stages pass 0.3 % of a 0.6 Hz tone with 10 s of delay."""
    vibration_vrw: float = 1e-3
    """Velocity random walk [m/s/sqrt(s)] added for the cutting machine's vibration. The twin's cutting vibration
    (drum 1 mm at 0.6 Hz, pick band 0.3 g at 30 Hz) moves the IMU's velocity increments, after sculling
    compensation, by a bounded oscillation of about 5 mm/s; read as a random walk that is 1.2-1.6e-3 over 10 s
    and 0.5-0.6e-3 over 100 s (seed001, error-free IMU, vibration on against off, across the face and vertically),
    the spans over which the level and the accelerometer bias are told apart. With 5e-4 the attitude ANEES on
    seed001 was 4.39, above its 95 % band (4.16); with 1e-3 it is 4.06, the positions unchanged."""
    mag: MagSettings = MagSettings()
    chute_length_m: float = 0.0
    """Point spacing of the rail kinematics model (004: one point per chute); 0 takes cpoem_spacing_m."""
    end_zone_m: float = 0.0
    """Stretch at each face end where the snake sump and the end push move the pans between two passes (the
    shearer's length plus the push lag, the snake and two pans): the rail kinematics model gives no fixes there
    (its strokes are not yet read reliably there: see the issue 7 note)."""
    rail_advance_sd: float = 0.0
    """Advance from the ram strokes [m] as the rail kinematics model uses it; 0 takes advance_sd."""
    detector: DetectorConfig = field(default_factory=lambda: DetectorConfig(fading=0.6, t_on=12.0, t_off=5.0,
                                                                            window=30, sd_floor=0.005))
    """Fault detectors on the rail kinematics model's fixes (004 section IV). The fixes come one per chute (one
    every 10-20 s at cutting speed), not at 10 Hz: a fading factor of 0.6 per fix keeps about a minute of memory.
    They test the innovation across the face against the model's variance scaled by what the last 30 accepted
    fixes' innovations show (estimators.shearer.federated_filter._fix_update: h P h' + R is several times too large for fixes
    from the filter's own previous pass), floored at 5 mm; with that scale's noise, t_on 12 and t_off 5
    (fault_detection.DetectorConfig)."""
    isolate_by: str | None = "fsprt"
    """The detector whose fault flag isolates the rail kinematics model (residual, dual_state, fsprt; None)."""

    @classmethod
    def appendix_a(cls, **kw) -> Config:
        """001 Table 1 / Appendix A: P0 of (A2) (Table 1 values x 3) and Q of (A3) (MTi-G-700 noise x 5)."""
        imu = ImuNoise(gyro_arw=0.6 * DEG / 60, accel_vrw=0.08e-3 * 9.80665, gyro_bias=720 * DEG / 3600,
                       accel_bias=3e-3 * 9.80665)
        return cls(imu=imu, sd_velocity0=0.01, sd_level0=0.3 * DEG, level_from_accelerometers=False,
                   sd_odo_mount0=3 * DEG, sd_odo_scale0=0.05,
                   p0_scale=3.0, q_scale=5.0, **kw)


@dataclass(frozen=True)
class Log:
    """The streams the positioning reads (columns as in estimators.io.logformat)."""

    imu_t: np.ndarray
    dtheta: np.ndarray
    dv: np.ndarray
    odo_t: np.ndarray
    odo_distance: np.ndarray
    odo_direction: np.ndarray
    survey_t: np.ndarray
    survey_llh: np.ndarray  # (S, 3)
    survey_yaw: np.ndarray
    survey_sd: np.ndarray  # (S, 3): horizontal, vertical [m], yaw [rad]
    ram_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ram_support: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    ram_extension: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ram_valid: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    mag_t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mag_b: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (M, 3) [T]
    face_u: np.ndarray = field(default_factory=lambda: np.zeros(0))  # FACE_SURVEY: distance from the start pose
    face_llh: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    face_sd: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # horizontal, vertical [m]


@dataclass
class Solution:
    """One method's output at the filter epochs: body-point navigation, one-sigma, flags, sensor states."""

    t: np.ndarray
    llh: np.ndarray  # (K, 3)
    v_n: np.ndarray  # (K, 3)
    q_nb: np.ndarray  # (K, 4)
    sd: np.ndarray  # (K, 9): position ENU, velocity ENU, attitude ENU (NaN without covariance)
    flags: np.ndarray
    cal: np.ndarray | None = None  # (K, 10) estimators.shearer.odometer_filter calibration vector
    sd_cal: np.ndarray | None = None  # (K, N_CAL), in the calibration vector's order
    notes: list[str] = field(default_factory=list)
    fusion: dict[str, np.ndarray] | None = None  # ESTIMATE_FUSION columns of a federated filter
    detectors: dict[str, np.ndarray] | None = None  # ESTIMATE_DETECTORS columns of the rail-model filter


# ------------------------------------------------------------------------------------------------------------
# Preparing the log


def _odometer_at(log: Log, t_kf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Odometer distance at the epochs and the mode of each interval (t[j-1], t[j]]: 1 moving, 0 standing, -1 no
    data. An interval has no data outside the log or where it overlaps a dropout: two consecutive samples more
    than 2.5 nominal periods apart."""
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
    mode = np.where(covered, np.where(moved, 1, 0), -1)
    return dist, np.concatenate([[0], mode]).astype(np.int8)


STRAIGHT_CUT_FRACTION = 0.8
"""A run of travel in one direction longer than this fraction of the face is a straight cut (a sump or a cut-out
into the snake covers the snake and the shearer, up to about half of a short face)."""


def straight_cuts(u: np.ndarray, mode: np.ndarray, face_travel: float) -> list[tuple[int, int]]:
    """(first, last) epochs of each run of travel in one direction longer than STRAIGHT_CUT_FRACTION of the
    face."""
    du = np.diff(u, prepend=u[0])
    moving = np.flatnonzero((mode == 1) & (du != 0))
    if moving.size == 0:
        return []
    sign = np.sign(du[moving])
    breaks = np.flatnonzero(sign[1:] != sign[:-1]) + 1
    runs = []
    for grp in np.split(moving, breaks):
        if abs(u[grp[-1]] - u[grp[0] - 1]) > STRAIGHT_CUT_FRACTION * face_travel:
            runs.append((int(grp[0]), int(grp[-1])))
    return runs


def _initial_state(log: Log, t_mech: np.ndarray, dv_b: np.ndarray, mode: np.ndarray, steps: int,
                   cfg: Config) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Navigation vector at t[0] (IMU point) and the start calibration, from the stand before the first cut:
    survey position and heading, level from the accelerometers (coarse), then the fine alignment of 000
    (estimators.sins.fine_alignment, EKF) over the stand, whose mean attitude over its last seconds and bias estimates
    start the filter. A stand the fine alignment finds moving is levelled only (noted)."""
    notes = []
    first_move = np.flatnonzero(mode == 1)
    stand_end = (first_move[0] - 1) * steps if first_move.size else dv_b.shape[0]
    dt = t_mech[1] - t_mech[0]
    n = int(min(stand_end, cfg.level_window_s / dt))
    if n < max(5, int(1.0 / dt)):
        raise PositioningError(f"odometer: the shearer moves {n * dt:.2f} s after the start; levelling needs at "
                               f"least 1 s of standing before the first cut")
    f_b = dv_b[:n].sum(axis=0) / (n * dt)
    pitch = np.arcsin(np.clip(f_b[1] / np.linalg.norm(f_b), -1, 1))
    roll = np.arctan2(-f_b[0], f_b[2])
    if not np.isfinite(log.survey_yaw[0]):
        raise PositioningError("survey: the first row needs the start heading (yaw); a MEMS gyro cannot find it")
    q_nb = euler_to_quat(pitch, roll, log.survey_yaw[0])
    lat, lon, h = log.survey_llh[0]
    cal = np.zeros(kf.N_CAL)
    imu_dt = float(np.median(np.diff(log.imu_t)))
    n_imu = round(n * dt / imu_dt)
    dtheta_s, dv_s = body_increments(log, cfg)
    res = fine_align(dtheta_s[:n_imu], dv_s[:n_imu], imu_dt, lat, q_nb, (cfg.imu.gyro_arw, cfg.imu.accel_vrw),
                     np.array([cfg.sd_level0, cfg.sd_level0, log.survey_sd[0, 2]]), "ekf", h=h,
                     gyro_bias_sigma=cfg.imu.gyro_bias, accel_bias_sigma=cfg.imu.accel_bias,
                     velocity_sigma=cfg.r_zupt, rate_sigma=cfg.r_zaru, on_motion="flag")
    if res.motion_t is None:
        q_nb = res.attitude(min(10.0, 0.5 * n * dt))
        cal[kf.CAL_ACCEL.start:kf.CAL_ACCEL.start + 2] = res.bias[-1, :2]
        cal[kf.CAL_GYRO] = res.bias[-1, 2:5]
        p0, r0, _ = quat_to_euler(q_nb)
        notes.append(f"fine alignment over {n * dt:.1f} s of standing: pitch {np.degrees(p0):.3f} deg, roll "
                     f"{np.degrees(r0):.3f} deg, gyro bias {np.round(np.degrees(cal[kf.CAL_GYRO]) * 3600, 1)} deg/h")
    else:
        notes.append(f"the stand looks moving from {res.motion_t:.1f} s: levelled only, pitch "
                     f"{np.degrees(pitch):.3f} deg, roll {np.degrees(roll):.3f} deg")
    off = quat_rotate(q_nb, np.asarray(cfg.lever_arm_m, float))
    r_m, r_n = earth.radii(lat)
    nav = np.zeros(kf.N_NAV)
    nav[:3] = lat + off[1] / (r_m + h), lon + off[0] / ((r_n + h) * np.cos(lat)), h + off[2]
    nav[kf.QUAT] = q_nb
    return nav, cal, notes


def initial_covariance(cfg: Config, log: Log, q_nb0: np.ndarray) -> np.ndarray:
    """P0 of the error states (001 Appendix A (A2) form): the configured sigmas, heading from the survey; with
    cfg.level_from_accelerometers the level error of the start attitude q_nb0 tied to the accelerometer errors.

    Levelled at rest, the attitude leaves no velocity drift in the filter's own model (shearer_kf.system_matrix):
    f_n x phi + C_b^n e = 0 horizontally, e = b + N(f_b) a the accelerometer error at f_b = C_n^b (0, 0, g), so
    phi_E = -(C_b^n e)_N / g and phi_N = (C_b^n e)_E / g. A diagonal P0 takes the level as known to sd_level0
    besides the bias, and the first stand's zero-velocity updates, which see only phi and e together, then
    "learn" the across-face bias from that prior (seed001: roll sd 0.175 -> 0.151 deg at the first stand, with
    the true roll error staying -b_x / g)."""
    sd = np.zeros(kf.N_STATES)
    sd[kf.DV] = cfg.sd_velocity0
    sd[kf.PHI] = [cfg.sd_level0, cfg.sd_level0, log.survey_sd[0, 2]]
    sd[kf.DP] = [log.survey_sd[0, 0], log.survey_sd[0, 0], log.survey_sd[0, 1]]
    sd[kf.GYRO_BIAS] = cfg.imu.gyro_bias
    sd[kf.ACCEL_BIAS] = cfg.imu.accel_bias
    sd[kf.ACCEL_NONORTH] = cfg.imu.accel_nonorth
    sd[kf.ODO_MOUNT] = cfg.sd_odo_mount0
    sd[kf.ODO_SCALE] = cfg.sd_odo_scale0
    p0 = np.diag((cfg.p0_scale * sd) ** 2)
    if not cfg.level_from_accelerometers:
        return p0
    c_bn = quat_to_mat(q_nb0)
    g = float(earth.normal_gravity(log.survey_llh[0, 0], log.survey_llh[0, 2]))
    tilt_per_error = np.vstack([-c_bn[1], c_bn[0]]) / g  # (phi_E, phi_N) per unit e in b
    t = np.eye(kf.N_STATES)
    level = slice(kf.PHI.start, kf.PHI.start + 2)
    t[level, kf.ACCEL_BIAS] = tilt_per_error
    t[level, kf.ACCEL_NONORTH] = tilt_per_error @ kf.nonorth_matrix(c_bn.T @ np.array([0.0, 0.0, g]))
    return t @ p0 @ t.T


def process_noise_psd(cfg: Config) -> np.ndarray:
    """Diagonal process-noise densities of the error states (001 Appendix A (A3) form)."""
    q = np.zeros(kf.N_STATES)
    q[kf.DV] = cfg.imu.accel_vrw ** 2 + cfg.vibration_vrw ** 2
    q[kf.PHI] = cfg.imu.gyro_arw ** 2
    q[kf.GYRO_BIAS] = cfg.imu.gyro_bias_psd
    q[kf.ACCEL_BIAS] = cfg.imu.accel_bias_psd
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


# ------------------------------------------------------------------------------------------------------------
# Outputs


@nb.njit(cache=True)
def _apply_rows(nav, cal, d):
    for k in range(nav.shape[0]):
        kf.apply_correction(nav[k], cal[k], d[k])


def _body_llh(nav: np.ndarray, lever: np.ndarray) -> np.ndarray:
    """Body reference point of IMU-point navigation rows."""
    off = quat_rotate(nav[:, kf.QUAT], lever)
    r_m, r_n = earth.radii(nav[:, 0])
    h = nav[:, 2]
    return np.column_stack([nav[:, 0] - off[:, 1] / (r_m + h), nav[:, 1] - off[:, 0] / ((r_n + h) *
                                                                                      np.cos(nav[:, 0])),
                            h - off[:, 2]])


def _sd(p: np.ndarray) -> np.ndarray:
    """One-sigma of every state from covariances (..., n, n)."""
    return np.sqrt(np.maximum(np.diagonal(p, axis1=-2, axis2=-1), 0.0))


# ------------------------------------------------------------------------------------------------------------
# The filter over a whole log


@dataclass
class Prepared:
    """The log resampled for the filters: mechanization increments, filter epochs, odometer, cuts, segments."""

    t_mech: np.ndarray
    phi_b: np.ndarray
    dv_b: np.ndarray
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


def body_increments(log: Log, cfg: Config) -> tuple[np.ndarray, np.ndarray]:
    """The IMU increments turned from the sensor axes into b with the calibrated mounting."""
    mat_bs = euler_to_mat(*cfg.imu_mounting_rad)
    return log.dtheta @ mat_bs.T, log.dv @ mat_bs.T


def prepare(log: Log, cfg: Config) -> Prepared:
    if log.survey_t.size == 0:
        raise PositioningError("survey: no rows; the start position and heading must be surveyed")
    imu_rate = 1.0 / np.median(np.diff(log.imu_t))
    steps_f = imu_rate / cfg.n_samples / cfg.filter_rate_hz
    if abs(steps_f - round(steps_f)) > 1e-6 or round(steps_f) < 1:
        raise PositioningError(f"imu: {imu_rate:.6g} Hz is not {cfg.n_samples} x {cfg.filter_rate_hz:g} Hz x an "
                               f"integer; choose filter_rate_hz to divide the mechanization rate")
    steps = round(steps_f)
    t = np.concatenate([[log.imu_t[0] - 1.0 / imu_rate], log.imu_t])
    zero = np.zeros((1, 3))
    dtheta_b, dv_b = body_increments(log, cfg)
    try:
        t_mech, phi_b, dv_b = compensated_increments(t, np.concatenate([zero, dtheta_b]),
                                                     np.concatenate([zero, dv_b]), cfg.n_samples)
    except ValueError as err:
        raise PositioningError(f"imu: {err}") from None
    n_kf = (t_mech.size - 1) // steps
    t_mech = t_mech[: n_kf * steps + 1]
    t_kf = t_mech[::steps]
    odo, mode = _odometer_at(log, t_kf)
    nav0, cal0, notes = _initial_state(log, t_mech, dv_b, mode, steps, cfg)
    u = odo - odo[0]
    if log.survey_t.size >= 2:
        d = earth.lla_to_enu(*log.survey_llh[1], *log.survey_llh[0])
        face_travel = float(np.hypot(d[0], d[1]))
    else:
        face_travel = float(np.ptp(u))
        notes.append("survey has no far face end: face length taken from the odometer")
    cuts = straight_cuts(u, mode, face_travel)
    settle = round(cfg.filter_rate_hz)  # one second of the stand after the cut belongs to the pass
    ends = sorted({min(last + 1 + settle, n_kf) for _, last in cuts})
    bounds = [0] + [e for e in ends if 0 < e < n_kf] + [n_kf]
    segments = list(itertools.pairwise(bounds))
    survey_epochs = np.minimum(np.searchsorted(t_kf, log.survey_t[1:]), n_kf)
    rams = None
    if log.ram_t.size and len(cfg.support_u_m) >= 2:
        rams = RamLog.from_rows(log.ram_t, log.ram_support, log.ram_extension, log.ram_valid, cfg.support_u_m,
                               cfg.ram_noise_sd)
    return Prepared(t_mech, phi_b, dv_b, steps, t_kf, odo, mode, cuts, segments, survey_epochs, rams, nav0,
                     cal0, notes)


class _Forward:
    """Storage of one forward run: per-epoch navigation, calibration and state sigmas (full covariances only per
    segment, on disk for the offline smoother)."""

    def __init__(self, n: int, keep_dir: Path | None):
        self.nav = np.zeros((n + 1, kf.N_NAV))
        self.cal = np.zeros((n + 1, kf.N_CAL))
        self.sd = np.zeros((n + 1, kf.N_STATES))
        self.flags = np.zeros(n + 1, np.int32)
        self.innov = np.full((n + 1, 3), np.nan)  # velocity innovation, m frame
        self.keep_dir = keep_dir
        self.saved: list[tuple[int, int]] = []

    def save_segment(self, a: int, x_post, p_post, p_pred, phi) -> None:
        if self.keep_dir is not None:
            np.savez(self.keep_dir / f"{a}.npz", x_post=x_post, p_post=p_post, p_pred=p_pred, phi=phi)
            self.saved.append((a, a + x_post.shape[0] - 1))


@dataclass
class Fixes:
    """Position fixes of a segment, in epoch order: epoch, lat/lon/h, ENU covariance, NIS gate, and the advance
    direction in n (unit; zero for a surveyed face end), along which a push-ram stroke moved a predicted point."""

    epoch: np.ndarray
    llh: np.ndarray
    r: np.ndarray
    gate: np.ndarray
    advance: np.ndarray

    @classmethod
    def empty(cls) -> Fixes:
        return cls(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0), np.zeros((0, 3)))

    def take(self, keep: np.ndarray) -> Fixes:
        """The fixes selected by `keep` (a mask or indices)."""
        return Fixes(self.epoch[keep], self.llh[keep], self.r[keep], self.gate[keep], self.advance[keep])


def fixes_for(prep: Prepared, cfg: Config, log: Log, a: int, b: int, points: Points | None,
              notes: list[str], face_ends: bool = True) -> Fixes:
    """Position fixes of epochs (a, b]: surveyed face ends (trusted: never gated; with `face_ends`), then CPOEM
    points crossed on a straight cut (gated at cfg.fix_gate)."""
    sel = np.flatnonzero((prep.survey_epochs > a) & (prep.survey_epochs <= b) & face_ends)
    j = list(prep.survey_epochs[sel])
    llh = [log.survey_llh[1 + k] for k in sel]
    r = [np.diag([log.survey_sd[1 + k, 0] ** 2] * 2 + [log.survey_sd[1 + k, 1] ** 2]) for k in sel]
    gate = [np.inf] * len(j)
    advance = [np.zeros(3)] * len(j)
    if points is not None and points.u.size and prep.rams is not None:
        u = prep.odo - prep.odo[0]
        for first, last in prep.cuts:
            if first > b or last <= a:
                continue
            lo, hi = max(first - 1, a), min(last, b)
            epochs, marks = crossings(u, cfg.cpoem_spacing_m, lo, hi)
            fj, fllh, fr, skipped, fadv = predict_fixes(points, u, prep.t_kf, epochs, marks, prep.rams,
                                                        cfg.advance_sd, cfg.path_sd, cfg.path_along_sd)
            j += list(fj)
            llh += list(fllh)
            r += list(fr)
            gate += [cfg.fix_gate] * fj.size
            advance += list(fadv)
            if skipped.size:
                notes.append(f"CPOEM: no push-ram stroke at u = {', '.join(f'{v:.1f}' for v in skipped)} m "
                             f"(t {prep.t_kf[lo]:.0f}-{prep.t_kf[hi]:.0f} s): points skipped")
    if not j:
        return Fixes.empty()
    order = np.argsort(j, kind="stable")
    return Fixes(np.array(j, np.int64), np.array(llh), np.array(r), np.array(gate), np.array(advance)).take(order)


def face_survey_points(log: Log, prep: Prepared) -> tuple[Points, np.ndarray]:
    """The installed face line (FACE_SURVEY) as CPOEM points of the first cut, smoothed by a local quadratic fit
    along the face (estimators.shearer.face_line: the survey's independent point errors averaged over +-14.5 m with
    tricube weights), with the fit's covariance; and the line's direction d enu / d u (K, 3) at each point. Its
    face coordinate is a true distance, the filter's the odometer's: the two part by the odometer's scale error,
    which the rail-model filter puts in the fix's measurement model (estimators.shearer.federated_filter._fix_update)."""
    if log.face_u.size == 0 or not prep.cuts:
        return Points.empty(), np.zeros((0, 3))
    first, last = prep.cuts[0]
    sign = 1.0 if prep.odo[last] >= prep.odo[first - 1] else -1.0  # the odometer counts the first cut this way
    order = np.argsort(log.face_u, kind="stable")
    u = sign * log.face_u[order]
    line = fit_face_line(log.face_llh[order], log.face_u[order])
    c_bn = np.broadcast_to(quat_to_mat(prep.nav0[kf.QUAT]), (u.size, 3, 3))
    sd_h, sd_v = log.face_sd[order, 0], log.face_sd[order, 1]
    cov = np.zeros((u.size, 3, 3))
    cov[:, [0, 1, 2], [0, 1, 2]] = line.gain[:, None] * np.column_stack([sd_h ** 2, sd_h ** 2, sd_v ** 2])
    points = Points(u, np.full(u.size, prep.t_kf[0]), line.llh(), cov, c_bn.copy())
    return points, sign * line.direction


def segment_points(prep: Prepared, cfg: Config, a: int, b: int, nav: np.ndarray, cov_enu: np.ndarray) -> Points:
    """CPOEM points of the straight cut inside epochs [a, b] from navigation rows nav and position covariances
    cov_enu (3, 3) (epochs a..b)."""
    u = prep.odo - prep.odo[0]
    lever = np.asarray(cfg.lever_arm_m, float)
    for first, last in prep.cuts:
        if first > a and last <= b:
            llh = np.zeros((prep.t_kf.size, 3))
            cov = np.zeros((prep.t_kf.size, 3, 3))
            c_bn = np.zeros((prep.t_kf.size, 3, 3))
            llh[a:b + 1] = _body_llh(nav, lever)
            cov[a:b + 1] = cov_enu
            c_bn[a:b + 1] = quat_to_mat(nav[:, kf.QUAT])
            return record(u, prep.t_kf, llh, cov, c_bn, cfg.cpoem_spacing_m, first - 1, last)
    return Points.empty()


def run_kf(log: Log, cfg: Config, prep: Prepared, cpoem: bool, smooth: bool,
           keep_dir: Path | None = None) -> tuple[Solution, Solution | None, _Forward]:
    """One forward run; with `smooth`, the online RTS at each pass end (its output and CPOEM points)."""
    n = prep.t_kf.size - 1
    fwd = _Forward(n, keep_dir)
    nav = prep.nav0.copy()
    cal = prep.cal0.copy()
    p = initial_covariance(cfg, log, prep.nav0[kf.QUAT])
    fwd.nav[0], fwd.sd[0] = nav, _sd(p)
    q_psd = process_noise_psd(cfg)
    params = kf_params(cfg)
    nominal = np.zeros(kf.N_NOMINAL)
    smooth_nav = fwd.nav.copy() if smooth else None
    smooth_sd = fwd.sd.copy() if smooth else None
    points: Points | None = Points.empty() if cpoem else None
    notes = list(prep.notes)
    n_fixes = n_gated = 0
    for a, b in prep.segments:
        fixes = fixes_for(prep, cfg, log, a, b, points, notes) if cpoem else Fixes.empty()
        m = b - a + 1
        x_post = np.zeros((m, kf.N_STATES))
        p_post = np.zeros((m, kf.N_STATES, kf.N_STATES))
        p_pred = np.zeros_like(p_post)
        phi = np.zeros_like(p_post)
        p_post[0], p_pred[0], phi[0] = p, p, np.eye(kf.N_STATES)
        nis_out = np.full(fixes.epoch.size, np.nan)
        seg_nav = np.zeros((m, kf.N_NAV))
        seg_cal = np.zeros((m, kf.N_CAL))
        seg_nav[0], seg_cal[0] = nav, cal
        seg_flags = np.zeros(m, np.int32)
        seg_innov = np.full((m, 3), np.nan)
        kf.run_filter(0, m - 1, prep.steps, prep.t_mech[a * prep.steps:], prep.phi_b[a * prep.steps:],
                      prep.dv_b[a * prep.steps:], prep.odo[a:b + 1], prep.mode[a:b + 1], fixes.epoch - a, fixes.llh,
                      fixes.r, fixes.gate, q_psd, params, nav, cal, p, nominal, seg_nav, seg_cal, x_post, p_post, p_pred,
                      phi, seg_flags, nis_out, seg_innov)
        n_fixes += fixes.epoch.size
        n_gated += int(np.sum(~(nis_out <= fixes.gate)))
        fwd.nav[a + 1:b + 1], fwd.cal[a + 1:b + 1] = seg_nav[1:], seg_cal[1:]
        fwd.sd[a + 1:b + 1], fwd.flags[a + 1:b + 1] = _sd(p_post[1:]), seg_flags[1:]
        fwd.innov[a + 1:b + 1] = seg_innov[1:]
        fwd.save_segment(a, x_post, p_post, p_pred, phi)
        if smooth:
            x_s, p_s = np.empty_like(x_post), np.empty_like(p_post)
            x_post[0] = 0.0  # the segment starts from the previous posterior
            rts_backward(x_post, p_post, np.zeros_like(x_post), p_pred, phi, x_s, p_s)
            s_nav, s_cal = seg_nav.copy(), seg_cal.copy()
            _apply_rows(s_nav, s_cal, x_s - x_post)
            smooth_nav[a + 1:b + 1], smooth_sd[a + 1:b + 1] = s_nav[1:], _sd(p_s[1:])
            if cpoem:
                points = segment_points(prep, cfg, a, b, s_nav, p_s[:, kf.DP, kf.DP])
        elif cpoem:
            points = segment_points(prep, cfg, a, b, seg_nav, p_post[:, kf.DP, kf.DP])
    if n_gated:
        notes.append(f"{n_gated} of {n_fixes} position fixes rejected by the innovation gate")
    missing = np.flatnonzero(prep.mode[1:] < 0) + 1
    if missing.size:
        notes.append(f"odometer: no data over {missing.size} filter steps ({missing.size / cfg.filter_rate_hz:.1f} s, "
                     f"first at t = {prep.t_kf[missing[0]]:.1f} s): velocity updates skipped")
    forward = make_solution(prep, cfg, fwd.nav, fwd.sd, fwd.flags, fwd.cal, notes)
    smoothed = None
    if smooth:
        smoothed = make_solution(prep, cfg, smooth_nav, smooth_sd, fwd.flags | FLAG_SMOOTHED, fwd.cal, notes)
    return forward, smoothed, fwd


def make_solution(prep: Prepared, cfg: Config, nav: np.ndarray, sd_all: np.ndarray, flags: np.ndarray,
                  cal: np.ndarray, notes: list[str]) -> Solution:
    """A Solution from navigation rows and the one-sigma of the error states at the filter epochs."""
    sd = np.column_stack([sd_all[:, kf.DP], sd_all[:, kf.DV], sd_all[:, kf.PHI]])
    sd_cal = np.column_stack([sd_all[:, kf.GYRO_BIAS], sd_all[:, kf.ACCEL_BIAS], sd_all[:, kf.ODO_MOUNT],
                              sd_all[:, kf.ODO_SCALE], sd_all[:, kf.ACCEL_NONORTH]])
    return Solution(prep.t_kf, _body_llh(nav, np.asarray(cfg.lever_arm_m, float)), nav[:, kf.VEL].copy(),
                    nav[:, kf.QUAT].copy(), sd, flags.copy(), cal.copy(), sd_cal, list(notes))


def rts_offline(prep: Prepared, cfg: Config, fwd: _Forward) -> Solution:
    """One backward pass (001 eqs. 29-31) over the whole forward run, segment by segment from the end.

    Row 0 of a stored segment is the previous segment's last epoch: its update is that segment's last row, and
    the smoothed value at a segment's last epoch is the one the later segment's pass computed."""
    nav, cal, sd = fwd.nav.copy(), fwd.cal.copy(), fwd.sd.copy()
    segs = [(a, b, fwd.keep_dir / f"{a}.npz") for a, b in fwd.saved]
    last_update = {b: np.load(path)["x_post"][-1] for a, b, path in segs}
    x_known = p_known = None
    for a, b, path in reversed(segs):
        data = np.load(path)
        x_post, p_pred, phi = data["x_post"].copy(), data["p_pred"], data["phi"]
        x_post[0] = last_update.get(a, np.zeros(kf.N_STATES))
        p_post = data["p_post"].copy()
        x_run = x_post.copy()
        if x_known is not None:
            x_run[-1], p_post[-1] = x_known, p_known
        x_s, p_s = np.empty_like(x_post), np.empty_like(p_post)
        rts_backward(x_run, p_post, np.zeros_like(x_post), p_pred, phi, x_s, p_s)
        _apply_rows(nav[a:b], cal[a:b], x_s[:-1] - x_post[:-1])
        sd[a:b] = _sd(p_s[:-1])
        x_known, p_known = x_s[0], p_s[0]
    return make_solution(prep, cfg, nav, sd, fwd.flags | FLAG_SMOOTHED, cal, [])


def dead_reckoning(log: Log, cfg: Config, prep: Prepared, cal: np.ndarray | None = None) -> Solution:
    """001's traditional method: the free SINS attitude carries the odometer distance along body y (with `cal`,
    the biases, odometer mounting and scale of a filter are applied first)."""
    gyro = cal[kf.CAL_GYRO] if cal is not None else np.zeros(3)
    accel = cal[kf.CAL_ACCEL] if cal is not None else np.zeros(3)
    dt = 1.0 / (1.0 / np.median(np.diff(log.imu_t)))
    t = np.concatenate([[log.imu_t[0] - dt], log.imu_t])
    zero = np.zeros((1, 3))
    lat0, lon0, h0 = prep.nav0[:3]
    dtheta_b, dv_b = body_increments(log, cfg)
    sins = mechanize(t, np.concatenate([zero, dtheta_b - gyro * dt]), np.concatenate([zero, dv_b - accel * dt]),
                     lat0, lon0, h0, np.zeros(3), prep.nav0[kf.QUAT], cfg.n_samples)
    q = sins.q_nb[:: prep.steps][: prep.t_kf.size]
    mount = cal[kf.CAL_MOUNT] if cal is not None else np.zeros(3)
    scale = cal[kf.CAL_SCALE] if cal is not None else 0.0
    y_m_b = quat_to_mat(rotvec_to_quat(mount))[:, 1]  # odometer axis in b (C_m^b as a rotation vector)
    dd = np.diff(prep.odo) / (1 + scale)
    step_n = quat_rotate(q[:-1], np.broadcast_to(y_m_b, (dd.size, 3))) * dd[:, None]
    enu = np.concatenate([np.zeros((1, 3)), np.cumsum(step_n, axis=0)])
    body0 = log.survey_llh[0]
    llh = np.column_stack(earth.enu_to_lla(enu, *body0))
    v = np.concatenate([np.zeros((1, 3)), step_n / np.diff(prep.t_kf)[:, None]])
    nan = np.full((prep.t_kf.size, 9), np.nan)
    return Solution(prep.t_kf, llh, v, q, nan, np.zeros(prep.t_kf.size, np.int32))


def estimate(log: Log, cfg: Config, methods: tuple[str, ...] = METHODS) -> dict[str, Solution]:
    """Run the requested methods on a log; returns method -> Solution."""
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise PositioningError(f"unknown method '{unknown[0]}' (methods: {', '.join(METHODS)})")
    prep = prepare(log, cfg)
    out: dict[str, Solution] = {}
    if "kf" in methods:
        out["kf"], _, _ = run_kf(log, cfg, prep, cpoem=False, smooth=False)
    if "kf_cpoem" in methods:
        out["kf_cpoem"], _, _ = run_kf(log, cfg, prep, cpoem=True, smooth=False)
    needs_rts = {"kf_cpoem_rts", "rts_offline", "dr_compensated"} & set(methods)
    if needs_rts:
        with tempfile.TemporaryDirectory(prefix="longwall-rts-") as tmp:
            keep = Path(tmp) if "rts_offline" in methods else None
            _, smoothed, fwd = run_kf(log, cfg, prep, cpoem=True, smooth=True, keep_dir=keep)
            if "kf_cpoem_rts" in methods:
                out["kf_cpoem_rts"] = smoothed
            if "rts_offline" in methods:
                out["rts_offline"] = rts_offline(prep, cfg, fwd)
        if "dr_compensated" in methods:
            out["dr_compensated"] = dead_reckoning(log, cfg, prep, smoothed.cal[-1])
    if "dr" in methods:
        out["dr"] = dead_reckoning(log, cfg, prep)
    if {"ckf_mag", "afkf", "fkf_rail"} & set(methods):
        from estimators.shearer import federated as fp  # it builds on this module

        if "ckf_mag" in methods:
            out["ckf_mag"] = fp.run_mag(log, cfg, prep, federated=False)
        if "afkf" in methods:
            out["afkf"] = fp.run_mag(log, cfg, prep, federated=True)
        if "fkf_rail" in methods:
            out["fkf_rail"] = fp.run_rail(log, cfg, prep, cfg.isolate_by)
    return {m: out[m] for m in methods}




def log_from_columns(imu, odometer, survey, pushram=None, mag=None, face_survey=None) -> Log:
    """A Log from stream columns (pyarrow tables or mappings of arrays, logformat column names)."""
    def col(table, name):
        c = table[name] if isinstance(table, dict) else table.column(name)
        return np.asarray(c if isinstance(c, np.ndarray) else c.to_numpy())

    optional = {}
    if pushram is not None:
        optional.update(ram_t=col(pushram, "t"), ram_support=col(pushram, "support"),
                        ram_extension=col(pushram, "extension"), ram_valid=col(pushram, "valid"))
    if mag is not None:
        optional.update(mag_t=col(mag, "t"), mag_b=np.column_stack([col(mag, f"b_{a}") for a in "xyz"]))
    if face_survey is not None:
        optional.update(face_u=col(face_survey, "u"),
                        face_llh=np.column_stack([col(face_survey, k) for k in ("lat", "lon", "h")]),
                        face_sd=np.column_stack([col(face_survey, k) for k in ("sd_horizontal", "sd_vertical")]))
    return Log(imu_t=col(imu, "t"), dtheta=np.column_stack([col(imu, f"dtheta_{a}") for a in "xyz"]),
               dv=np.column_stack([col(imu, f"dv_{a}") for a in "xyz"]), odo_t=col(odometer, "t"),
               odo_distance=col(odometer, "distance"), odo_direction=col(odometer, "direction"),
               survey_t=col(survey, "t"), survey_llh=np.column_stack([col(survey, k) for k in ("lat", "lon", "h")]),
               survey_yaw=col(survey, "yaw"),
               survey_sd=np.column_stack([col(survey, k) for k in ("sd_horizontal", "sd_vertical", "sd_yaw")]),
               **optional)


def load_log(run_dir: Path) -> Log:
    """The streams of a run directory the positioning reads (push rams, magnetometer and face survey optional),
    checked on load."""
    from estimators.io.logformat import (
        FACE_SURVEY,
        IMU,
        MAG,
        ODOMETER,
        PUSHRAM,
        SURVEY,
        read_stream,
    )

    def optional(stream):
        return read_stream(run_dir, stream) if (Path(run_dir) / stream.filename).is_file() else None

    return log_from_columns(read_stream(run_dir, IMU), read_stream(run_dir, ODOMETER), read_stream(run_dir, SURVEY),
                            optional(PUSHRAM), optional(MAG), optional(FACE_SURVEY))


def estimate_columns(sol: Solution) -> dict[str, np.ndarray]:
    """A Solution as ESTIMATE columns (estimators.io.logformat)."""
    out = {"t": sol.t, "lat": sol.llh[:, 0], "lon": sol.llh[:, 1], "h": sol.llh[:, 2], "flags": sol.flags}
    for i, a in enumerate("enu"):
        out[f"v_n_{a}"] = sol.v_n[:, i]
        out[f"sd_pos_{a}"], out[f"sd_vel_{a}"], out[f"sd_att_{a}"] = sol.sd[:, i], sol.sd[:, 3 + i], sol.sd[:, 6 + i]
    for i, a in enumerate("wxyz"):
        out[f"q_nb_{a}"] = sol.q_nb[:, i]
    return out


def state_columns(sol: Solution) -> dict[str, np.ndarray]:
    """A filter Solution's calibration as ESTIMATE_STATES columns."""
    out = {"t": sol.t, "odo_scale": sol.cal[:, kf.CAL_SCALE], "sd_odo_scale": sol.sd_cal[:, kf.CAL_SCALE]}
    for name, cal, axes in (("gyro_bias", kf.CAL_GYRO, "xyz"), ("accel_bias", kf.CAL_ACCEL, "xyz"),
                            ("odo_mount", kf.CAL_MOUNT, "xyz"), ("accel_nonorth", kf.CAL_NONORTH, NONORTH_AXES)):
        for i, a in enumerate(axes):
            out[f"{name}_{a}"] = sol.cal[:, cal.start + i]
            out[f"sd_{name}_{a}"] = sol.sd_cal[:, cal.start + i]
    return out
