"""What the shearer positioning is told besides the log (SI units): the IMU's error budget, the magnetometer's
settings for 003's filters, and the filter, CPOEM (001) and rail-model (004) settings; and the error a log the
positioning cannot use raises."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.faults.detectors import DetectorConfig

STREAMED = ("kf_cpoem_rts", "rts_offline", "dr_compensated", "fkf_rail", "kf_rts", "kf_cpoem", "kf", "dr")
"""The methods `estimate` runs online over the log's pieces when it is given them (estimators.shearer.online: 001's
filters and dead reckoning and 004's federated rail-model filter a pass at a time, rts_offline backward over the
passes kept on disk; the batch method's rows bit for bit). 003's magnetometer filters (ckf_mag, afkf) run on the
whole log."""

DEAD_RECKONING = ("dr", "dr_compensated")
"""001's dead reckoning methods (estimators.shearer.dead_reckoning): no filter, so no covariance (their one-sigmas
are NaN, and the health monitor gives them only the checks that need none)."""

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
    """The shearer magnetometer as the SINS/magnetometer filters (estimators.shearer.adaptive_federated_mag) use it.
    Units SI."""

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
    cpoem_face_survey: bool = True
    """The first cut's CPOEM points from the installed face line's survey when the log has one (the face survey
    stream, estimators.shearer.position_fixes.face_survey_points, as 004's rail model takes its first cut's),
    at the survey's own step (estimators.shearer.cpoem.at_spacing); False: none, as in 001, whose first pass is the
    filter's alone. Without them the first pass's height follows the filter's tilt along the face, which it
    cannot part from the accelerometer's bias along it (seed004: +115 mm at the far end, 0.3 mrad, 30 ug over g),
    and the chain of passes keeps that profile for good: the face ends' 5 cm surveys do not pull it back against a
    pass of tight chained fixes (seed004, kf_cpoem_rts: height error +60 to +100 mm over the far half of the face in
    every cycle, SEP 0.072 m; with them 0.040 m)."""
    r_lateral: float = 0.02  # motion-constraint noise across the face [m/s] (suspension, drum vibration)
    r_vertical: float = 0.02
    r_odometer: float = 0.002  # odometer velocity noise besides quantization [m/s]
    r_zupt: float = 0.002  # [m/s]
    r_zaru: float = 5e-4  # zero-rate noise: idle vibration of the machine [rad/s]
    stand_settle_s: float = 1.0
    """A stand begins this long after the odometer last counted or showed a haulage direction, and ends this long
    before it does again. A machine coasting to a stop moves by less than a pulse for several epochs (a 2 mm pulse
    in 0.1 s is 20 mm/s) while its direction signal is already off, and creeps before the signal comes on at a
    start (the twin's reports a direction above 5 mm/s); a zero-velocity update there takes the motion for a
    velocity error, which the odometer scale's correlation with the along-face velocity turns into a position
    jump (25 cm on an error-free north-south run of the twin). The epochs in between get no update."""
    advance_sd: float = 0.005  # advance from the ram strokes [m]
    ram_noise_sd: float = 1e-4  # one-sigma noise of a push-ram reading [m]
    path_sd: float = 0.03  # the pans' running line between cycles beyond the measured advance [m]
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
    at (estimators.shearer.odometer_filter.transition). The drum tone (0.5-1 Hz) shakes the IMU horizontally; its
    velocity is in the innovations, and an F that carries its acceleration correlates the heading gain with that
    velocity, which rectifies into a heading drift (9 deg/h on seed001 with an error-free IMU through one 2 s
    stage). Two 5 s stages pass 0.3 % of a 0.6 Hz tone with 10 s of delay."""
    vibration_vrw: float = 1e-3
    """Velocity random walk [m/s/sqrt(s)] added for the cutting machine's vibration. The twin's cutting vibration
    (drum 1 mm at 0.6 Hz, pick band 0.3 g at 30 Hz) moves the IMU's velocity increments, after sculling
    compensation, by a bounded oscillation of about 5 mm/s; read as a random walk that is 1.2-1.6e-3 over 10 s
    and 0.5-0.6e-3 over 100 s (seed001, error-free IMU, vibration on against off, across the face and vertically),
    the spans over which the level and the accelerometer bias are told apart. With 5e-4 the attitude ANEES on
    seed001 was 4.39, above its 95 % band (4.16); with 1e-3 it is 4.06, the positions unchanged."""
    mag: MagSettings = MagSettings()
    health_max_speed_m_s: float = 1.0
    """The health monitor (estimators.shearer.health): a speed no shearer hauls at (they cut at 0.05-0.5 m/s)."""
    health_jump_sigma: float = 10.0
    """The health monitor: a position correction beyond this many sigma of the prior is a lost track ..."""
    health_jump_floor_m: float = 0.05
    """... if it is also larger than this (a survey or CPOEM fix of a well-known state moves it by millimetres)."""
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
    They test the innovation across the face against the model's variance scaled by what the last 30 accepted fixes'
    innovations show (estimators.shearer.rail_fix_update.rail_fix_update: h P h' + R is several times too large for
    fixes from the filter's own previous pass), floored at 5 mm; with that scale's noise, t_on 12 and t_off 5
    (estimators.faults.detectors.DetectorConfig)."""
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

