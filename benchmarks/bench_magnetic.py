"""Magnetic-heading building blocks of issue 6 on scenarios/seed003.toml and seed003_interference.toml.

With the true pitch and roll (the best a SINS can give the tilt compensation) and the WMM reference, per
scenario and per phase (straight cut, sumping and cut-out, stands):

* the magnetic yaw error (tilt-compensated yaw, 002 eqs. 3-6, minus the true yaw) [deg]: mean, RMS, max;
* the yaw noise the model predicts (002 eqs. 26-27: sigma_m / H) beside the spread measured at stands;
* the disturbance test (field norm and dip against the WMM): share of readings flagged inside and outside the
  interference window, and the yaw error of the readings it lets through;
* the innovation-based R (003 section 4.2, window WINDOW_S) of the yaw closing error at the end of the
  interference window and at the end of the run, against the yaw error variance the readings really have.

Run: python benchmarks/bench_magnetic.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from estimators.kalman.adaptive_noise import InnovationNoiseEstimator
from estimators.nav.geomagnetic import (
    field_check,
    geomagnetic_reference,
    tilt_compensated_yaw,
    wrap_angle,
    yaw_noise_variance,
)
from estimators.nav.rotations import quat_to_euler
from twin.config.scenario import load_scenario
from twin.face.haulage import CUTTING, STOPPED
from twin.pipeline.simulate import simulate
from twin.sensors.magnetometer import shearer_attitude_at
from twin.sensors.streams import imu_truth, sensor_streams

SCENARIOS = Path(__file__).resolve().parent.parent / "scenarios"
WINDOW_S = 5.0


def phase_at(shearer: dict, t: np.ndarray) -> np.ndarray:
    i = np.clip(np.searchsorted(shearer["t"], t, side="right") - 1, 0, shearer["t"].size - 1)
    return np.asarray(shearer["phase"])[i]


def stats(err_deg: np.ndarray) -> str:
    if err_deg.size == 0:
        return "   (none)"
    return (f"mean {err_deg.mean():+7.3f}  rms {np.sqrt(np.mean(err_deg ** 2)):7.3f}  "
            f"max {np.abs(err_deg).max():7.3f}  n {err_deg.size}")


def run(name: str) -> None:
    t0 = time.perf_counter()
    scn = load_scenario(SCENARIOS / f"{name}.toml")
    res = simulate(scn)
    shearer = res.tables["truth_shearer"]
    mag = sensor_streams(scn, res.tables, imu_truth(scn, shearer))["mag"]
    cfg = scn.sensors.mag
    ref = geomagnetic_reference(np.radians(scn.site.lat_deg), np.radians(scn.site.lon_deg), scn.site.height_m,
                                cfg.date)
    t = mag["t"]
    b = np.column_stack([mag["b_x"], mag["b_y"], mag["b_z"]])
    pitch, roll, yaw = quat_to_euler(shearer_attitude_at(shearer, t))
    err = np.degrees(wrap_angle(tilt_compensated_yaw(b, pitch, roll, ref.declination) - yaw))
    phase = phase_at(shearer, t)
    windows = [(f.t_start_s, f.t_end_s) for f in scn.faults if f.kind == "mag_interference" and f.target is None]
    disturbed = np.zeros(t.size, bool)
    for a, e in windows:
        disturbed |= (t >= a) & (t < e)
    check = field_check(b, pitch, roll, ref)
    print(f"\n{name}: {t[-1]:.0f} s, {t.size} readings, WMM D {np.degrees(ref.declination):.2f} deg, "
          f"I {np.degrees(ref.inclination):.2f} deg, F {ref.intensity * 1e6:.2f} uT, H {ref.horizontal * 1e6:.2f} uT; "
          f"interference {windows or 'none'}; straight-cut heading "
          f"{np.mod(-np.degrees(np.median(yaw[phase == CUTTING])), 360):.2f} deg cw")
    print("  magnetic yaw error [deg] (true tilt):")
    print(f"    straight cut, clean     {stats(err[(phase == CUTTING) & ~disturbed])}")
    print(f"    straight cut, disturbed {stats(err[(phase == CUTTING) & disturbed])}")
    print(f"    sump and cut-out        {stats(err[(phase != CUTTING) & (phase != STOPPED)])}")
    print(f"    stands                  {stats(err[phase == STOPPED])}")
    stand = err[phase == STOPPED]
    print(f"  yaw noise: model sigma_m / H = {np.degrees(np.sqrt(yaw_noise_variance(ref, cfg.noise_t))):.3f} deg, "
          f"measured sd at stands = {stand.std():.3f} deg")
    print(f"  disturbance test: flagged {100 * (~check.ok[~disturbed]).mean():.2f} % outside the window, "
          f"{100 * (~check.ok[disturbed]).mean() if disturbed.any() else float('nan'):.2f} % inside; "
          f"|norm error| max {100 * np.abs(check.norm_error[~disturbed]).max():.2f} % / "
          f"|dip error| max {np.degrees(np.abs(check.dip_error[~disturbed])).max():.2f} deg outside; "
          f"yaw error of accepted readings max {np.abs(err[check.ok]).max():.3f} deg")
    window = round(WINDOW_S * cfg.rate_hz)
    est = InnovationNoiseEstimator(window, r_nominal=yaw_noise_variance(ref, cfg.noise_t),
                                   r_min=yaw_noise_variance(ref, cfg.noise_t) / 4, min_samples=window // 4)
    r_hist = np.array([est.update(np.radians(e), 0.0)[0, 0] for e in err])  # truth attitude: H P H^T = 0
    for label, k in [(f"end of window {a:.0f}-{e:.0f} s", np.searchsorted(t, e) - 1) for a, e in windows] + [
            ("end of run", t.size - 1)]:
        span = slice(max(0, k - window + 1), k + 1)
        print(f"  innovation R at {label}: sqrt(R) = {np.degrees(np.sqrt(r_hist[k])):.3f} deg, RMS of the "
              f"window's yaw errors {np.sqrt(np.mean(err[span] ** 2)):.3f} deg")
    print(f"  ({time.perf_counter() - t0:.1f} s)")


if __name__ == "__main__":
    for scenario in ("seed003", "seed003_interference"):
        run(scenario)
