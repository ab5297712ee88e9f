"""The shearer filters' start state (estimators.shearer.prepare): the position and heading from the survey, the level
from the accelerometers while the shearer stands before the first cut, refined by the fine alignment of 000."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from estimators.io.log import Log
from estimators.kalman import error_state as es
from estimators.nav import earth
from estimators.nav.rotations import euler_to_quat, quat_rotate, quat_to_euler
from estimators.shearer.config import Config, PositioningError
from estimators.shearer.odometer_filter import MODE_MOVING
from estimators.sins.fine_alignment import fine_align

if TYPE_CHECKING:
    from estimators.shearer.prepare import Prepared


def initial_state(log: Log, prep: Prepared, cfg: Config) -> tuple[np.ndarray, np.ndarray, list[str]]:
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
