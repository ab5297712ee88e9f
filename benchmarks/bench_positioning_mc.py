"""Monte Carlo of the 001 shearer positioning on seed001: SEP per cycle (mean and spread) and the filter's
consistency, the average normalized estimation error squared (ANEES) of position and attitude against the
two-sided 95 % chi-square band (Bar-Shalom section 5.4.2).

Physics once: seed001 is simulated once; each trial redraws every sensor error (IMU, odometer, push rams,
survey) from the same truth. NEES uses the estimators' one-sigma columns (diagonal covariance).
Run: python benchmarks/bench_positioning_mc.py [TRIALS] [METHOD ...] [--axes] [--off SOURCE ...]

--axes prints, per method and axis (east, north, up), the attitude error's rms against the claimed one-sigma (rms
over trials and epochs) and the per-axis ANEES (1 dof), and the final odometer scale and mounting x and z estimates
(with the filter's own one-sigma of mounting z: on a straight face it is known only as well as the heading).
--off SOURCE switches one of the twin's error sources off (ablation; the filter's configuration is kept):
vibration, nonorth (gyro and accelerometer), gm (in-run bias instability), turnon (turn-on biases), imu_mount
(the IMU mounting misalignment, also in the filter's calibration), odo_mount, odo_scale, noise (white noise).
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

from estimators.io import metrics
from estimators.io.log import log_from_columns
from estimators.kalman.error_state import CAL_MOUNT, CAL_SCALE
from estimators.shearer.config import PositioningError
from estimators.shearer.methods import estimate
from estimators.shearer.solution import SD_ATT, SD_POS, estimate_columns
from twin.cli import default_scenario
from twin.config import imu_grades
from twin.config.scenario import load_scenario
from twin.pipeline.estimate import positioning_config, true_states
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

GRADE_OFF = {"nonorth": ("gyro_nonorth", "accel_nonorth"), "gm": ("gyro_bias_instability", "accel_bias_instability"),
             "turnon": ("gyro_bias", "accel_bias"), "noise": ("gyro_arw", "accel_vrw"),
             "accel_turnon": ("accel_bias",), "gyro_turnon": ("gyro_bias",)}
SOURCES = ("vibration", "imu_mount", "odo_mount", "odo_scale", *GRADE_OFF)


def _switch_off(scn, off: tuple[str, ...]):
    """The scenario with the twin's error sources `off` switched off (ablation); a new grade where needed."""
    unknown = [o for o in off if o not in SOURCES]
    if unknown:
        raise ValueError(f"unknown error source {unknown[0]!r} (sources: {', '.join(SOURCES)})")
    sensors = scn.sensors
    if "vibration" in off:
        sensors = sensors.model_copy(update={"vibration": sensors.vibration.model_copy(update={"enabled": False})})
    if "imu_mount" in off:
        sensors = sensors.model_copy(update={"imu": sensors.imu.model_copy(update={"misalignment_deg": [0.0] * 3})})
    odo = {}
    if "odo_mount" in off:
        odo["mounting_deg"] = [0.0] * 3
    if "odo_scale" in off:
        odo["scale_error"] = 0.0
    if odo:
        sensors = sensors.model_copy(update={"odometer": sensors.odometer.model_copy(update=odo)})
    zero = [f for o in off for f in GRADE_OFF.get(o, ())]
    if zero:
        name = f"{sensors.imu.grade}-ablation"
        imu_grades.GRADES[name] = dataclasses.replace(imu_grades.grade(sensors.imu.grade), **dict.fromkeys(zero, 0.0))
        sensors = sensors.model_copy(update={"imu": sensors.imu.model_copy(update={"grade": name})})
    return scn.model_copy(update={"sensors": sensors})


def main(trials: int = 20, methods: tuple[str, ...] = ("kf_cpoem", "kf_cpoem_rts"), off: tuple[str, ...] = (),
         axes: bool = False, **overrides) -> dict:
    """`overrides`: Config fields to change (tuning studies); `off`: the twin's error sources to switch off
    (the filter's configuration stays that of seed001, but for the IMU mounting, which it is given exactly).
    Prints the table; returns per method the SEP per trial and cycle [m] (`sep`, trials x cycles) and the median
    ANEES of position and attitude (`anees_pos`, `anees_att`) with the band (`band`); with `axes` also the
    attitude rms error and claimed sd per axis (`att_rms`, `att_sd` [rad], east/north/up)."""
    figs: dict = {"sep": {}, "anees_pos": {}, "anees_att": {}, "band": None, "att_rms": {}, "att_sd": {}}
    scn0 = load_scenario(default_scenario().parent / "seed001.toml")
    scn = _switch_off(scn0, off)
    result = simulate(scn)
    truth, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    ideal = imu_truth(scn, truth)
    cfg_scn = scn0 if "imu_mount" not in off else scn0.model_copy(update={"sensors": scn.sensors.model_copy(
        update={"imu": scn0.sensors.imu.model_copy(update={"misalignment_deg": [0.0] * 3})})})
    cfg = dataclasses.replace(positioning_config(cfg_scn), **overrides)
    att_err = {m: [] for m in methods}
    att_sd = {m: [] for m in methods}
    final = {m: [] for m in methods}
    seps = {m: [] for m in methods}
    nees_pos = {m: [] for m in methods}
    nees_att = {m: [] for m in methods}
    t0 = time.perf_counter()
    for trial in range(trials):
        s = sensor_streams(scn, result.tables, ideal, trial)
        sols = estimate(log_from_columns(s["imu"], s["odometer"], s["survey"], s["pushram"]), cfg, methods)
        for m, sol in sols.items():
            cols = estimate_columns(sol)
            t, err = metrics.position_errors(cols, truth)
            _, att = metrics.attitude_errors(cols, truth)
            seps[m].append([c["sep"] for c in metrics.cycle_metrics(t, err, cycles)])
            nees_pos[m].append(metrics.nees(err, sol.sd[:, SD_POS]))
            nees_att[m].append(metrics.nees(att, sol.sd[:, SD_ATT]))
            att_err[m].append(att)
            att_sd[m].append(sol.sd[:, SD_ATT])
            if sol.cal is not None:
                mount_x, mount_z = CAL_MOUNT.start, CAL_MOUNT.start + 2
                final[m].append([sol.cal[-1, CAL_SCALE], sol.cal[-1, mount_x], sol.cal[-1, mount_z],
                                 sol.sd_cal[-1, mount_z]])
    wall = time.perf_counter() - t0
    lo, hi = metrics.nees_band(3, trials)
    figs["band"] = (lo, hi)
    print(f"seed001, {trials} trials (sensor errors redrawn from one simulation), {wall:.1f} s")
    print(f"95 % band of the ANEES over {trials} trials, 3 dof: [{lo:.2f}, {hi:.2f}]")
    print(f"{'method':14s} {'SEP A1':>14s} {'A2':>14s} {'A3':>14s} {'A4':>14s}   ANEES pos (in band)  att (in band)")
    for m in methods:
        sep = np.array(seps[m])[:, :4]
        a_pos = np.mean(nees_pos[m], axis=0)[1:]
        a_att = np.mean(nees_att[m], axis=0)[1:]
        figs["sep"][m], figs["anees_pos"][m], figs["anees_att"][m] = sep, float(np.median(a_pos)), float(np.median(a_att))
        cells = " ".join(f"{mu:7.3f}+-{sd:5.3f}" for mu, sd in zip(sep.mean(0), sep.std(0)))
        print(f"{m:14s} {cells}   {np.median(a_pos):6.2f} ({np.mean((a_pos >= lo) & (a_pos <= hi)):4.0%})"
              f"        {np.median(a_att):6.2f} ({np.mean((a_att >= lo) & (a_att <= hi)):4.0%})")
    print("ANEES columns: median over epochs of the trial-averaged NEES, and the share of epochs inside the band")
    if off:
        print(f"error sources switched off in the twin: {', '.join(off)}")
    if axes:
        lo1, hi1 = metrics.nees_band(1, trials)
        st = true_states(scn)
        print(f"attitude per axis [deg]: rms error / rms claimed sd (epoch 0 | run), ANEES 1 dof [{lo1:.2f}, {hi1:.2f}]")
        for m in methods:
            e, sd = np.array(att_err[m]), np.array(att_sd[m])
            rms, rsd = np.sqrt(np.mean(e[:, 1:] ** 2, axis=(0, 1))), np.sqrt(np.mean(sd[:, 1:] ** 2, axis=(0, 1)))
            r0, s0 = np.sqrt(np.mean(e[:, 0] ** 2, axis=0)), np.sqrt(np.mean(sd[:, 0] ** 2, axis=0))
            a1 = np.median(np.mean((e / sd)[:, 1:] ** 2, axis=0), axis=0)
            figs["att_rms"][m], figs["att_sd"][m] = rms, rsd
            print(f"{m:14s} " + "  ".join(f"{a} {np.degrees(r0[i]):.3f}/{np.degrees(s0[i]):.3f} | "
                                          f"{np.degrees(rms[i]):.3f}/{np.degrees(rsd[i]):.3f} ({a1[i]:5.2f})"
                                          for i, a in enumerate("ENU")))
            if final[m]:
                fs = np.array(final[m])
                print(f"{'':14s} final odometer scale {fs[:, 0].mean():+.5f} +- {fs[:, 0].std():.5f} "
                      f"(truth {st['odo_scale']:+.5f}), mounting x {np.degrees(fs[:, 1]).mean():+.3f} +- "
                      f"{np.degrees(fs[:, 1]).std():.3f} deg (truth {np.degrees(st['odo_mount_x']):+.3f}), mounting z "
                      f"{np.degrees(fs[:, 2]).mean():+.3f} +- {np.degrees(fs[:, 2]).std():.3f} deg "
                      f"(truth {np.degrees(st['odo_mount_z']):+.3f}; the filter's own sd "
                      f"{np.degrees(np.sqrt(np.mean(fs[:, 3] ** 2))):.3f} deg)")
    return figs


if __name__ == "__main__":
    args = sys.argv[1:]
    n = int(args.pop(0)) if args and args[0].isdigit() else 20
    axes = "--axes" in args
    args = [a for a in args if a != "--axes"]
    off = tuple(args[args.index("--off") + 1:]) if "--off" in args else ()
    args = args[:args.index("--off")] if "--off" in args else args
    try:
        main(n, tuple(args) or ("kf_cpoem", "kf_cpoem_rts"), off=off, axes=axes)
    except (ValueError, PositioningError) as exc:
        sys.exit(f"bench_positioning_mc: error: {exc}")
