"""Shearer positioning benchmark on the experiment of 001 (scenarios/seed001.toml): our SEP per cutting cycle
beside 001 Table 3, the Table 2 sweep (Par 1-12: the same motion with degraded IMUs), the CPOEM spacings of
001 section 4, and the throughput of the filter plus the online RTS smoother.

Physics once: seed001 is simulated once; each row redraws the sensor errors for its IMU grade.
Run: python benchmarks/bench_positioning.py [--no-sweep]
     python benchmarks/bench_positioning.py --throughput RUN_DIR   (e.g. a `longwall run scenarios/seed004.toml`)
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

from estimators.io import metrics
from estimators.io.log import Log, load_log, log_from_columns
from estimators.kalman.error_state import CAL_MOUNT, CAL_SCALE
from estimators.shearer.methods import estimate
from estimators.shearer.solution import Solution, estimate_columns
from twin.cli import default_scenario
from twin.config.scenario import load_scenario, parse_scenario
from twin.pipeline.estimate import positioning_config, true_states
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

TABLE3 = {"traditional without compensation": (1.75, 1.99, 2.28, 2.31),
          "traditional with compensation": (0.21, 0.29, 0.33, 0.17), "proposed (KF + CPOEM + RTS)": (0.50, 0.32, 0.13, 0.17)}
OURS = {"dr": "traditional without compensation", "dr_compensated": "traditional with compensation",
        "kf": "SINS/odometer KF", "kf_cpoem": "KF + CPOEM", "kf_cpoem_rts": "proposed (KF + CPOEM + RTS)",
        "rts_offline": "offline RTS over the run"}


def log_of(streams: dict) -> Log:
    return log_from_columns(streams["imu"], streams["odometer"], streams["survey"], streams["pushram"])


def sep_row(sol: Solution, truth: dict, cycles: dict) -> list[float]:
    cols = estimate_columns(sol)
    t, err = metrics.position_errors(cols, truth)
    return [c["sep"] for c in metrics.cycle_metrics(t, err, cycles)]


def figures(sweep: bool = True) -> dict:
    """Print the benchmark; return its figures: SEP per cycle [m] per method (`sep`), with the face ends of the
    first cut only (`sep_first_cut`), per CPOEM spacing (`sep_delta`), per Par k of the sweep (`sweep`), throughput."""
    figs: dict = {"sep": {}, "sep_delta": {}, "sweep": {}}
    scn = load_scenario(default_scenario().parent / "seed001.toml")
    t0 = time.perf_counter()
    result = simulate(scn)
    print(f"seed001 simulated in {time.perf_counter() - t0:.1f} s ({result.tables['truth_shearer']['t'][-1]:.0f} s "
          f"of cutting)")
    truth, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    ideal = imu_truth(scn, truth)
    log = log_of(sensor_streams(scn, result.tables, ideal, 0))
    cfg = positioning_config(scn)
    estimate(log, cfg, ("kf_cpoem_rts",))  # compile
    t0 = time.perf_counter()
    sols = estimate(log, cfg, tuple(OURS))  # the methods of 001 (the mag and rail filters need other streams)
    wall = time.perf_counter() - t0
    print(f"\nSEP per cutting cycle [m], {scn.sensors.imu.grade}, CPOEM spacing {cfg.cpoem_spacing_m} m, survey of "
          f"the face ends: {scn.sensors.survey.face_ends}")
    print(f"{'method':36s} {'A1':>6s} {'A2':>6s} {'A3':>6s} {'A4':>6s}   | 001 Table 3: A1 A2 A3 A4")
    for name, sol in sols.items():
        row = sep_row(sol, truth, cycles)
        figs["sep"][name] = row[:4]
        paper = TABLE3.get(OURS[name])
        ref = "  ".join(f"{v:.2f}" for v in paper) if paper else "-"
        print(f"{OURS[name] + ' (' + name + ')':36s} " + " ".join(f"{v:6.3f}" for v in row[:4]) + f"   | {ref}")
    data = scn.model_dump()
    data["sensors"]["survey"]["face_ends"] = "first_cut"
    first = parse_scenario(data, "seed001-first-cut")
    sol = estimate(log_of(sensor_streams(first, result.tables, ideal, 0)), cfg, ("kf_cpoem_rts",))["kf_cpoem_rts"]
    figs["sep_first_cut"] = sep_row(sol, truth, cycles)[:4]
    print(f"{'same, face ends of the 1st cut only':36s} " + " ".join(f"{v:6.3f}" for v in figs["sep_first_cut"])
          + "   | (001's survey: both ends of the first cut)")
    e, st = sols["kf_cpoem_rts"], true_states(scn)
    mount = e.cal[-1, CAL_MOUNT]
    print(f"odometer scale error: estimated {e.cal[-1, CAL_SCALE]:+.4f}, true {st['odo_scale']:+.4f}; "
          f"mounting x, z [deg]: estimated {np.degrees(mount[0]):+.3f}, {np.degrees(mount[2]):+.3f}, true "
          f"{np.degrees(st['odo_mount_x']):+.3f}, {np.degrees(st['odo_mount_z']):+.3f}")
    print("\nCPOEM point spacing Delta (001 section 4: 2, 6, 10 m), KF + CPOEM + RTS, SEP per cycle [m]")
    for delta in (2.0, 6.0, 10.0):
        sol = estimate(log, dataclasses.replace(cfg, cpoem_spacing_m=delta), ("kf_cpoem_rts",))["kf_cpoem_rts"]
        figs["sep_delta"][delta] = sep_row(sol, truth, cycles)[:4]
        print(f"Delta {delta:4.0f} m " + " ".join(f"{v:6.3f}" for v in figs["sep_delta"][delta]))
    t0 = time.perf_counter()
    estimate(log, cfg, ("kf_cpoem_rts",))
    one = time.perf_counter() - t0
    figs["throughput"] = log.imu.size / one
    print(f"\nthroughput: KF + CPOEM + online RTS {log.imu.size / one:,.0f} IMU samples/s "
          f"({log.imu.size:,} samples in {one:.2f} s; all six methods {wall:.2f} s); target >= 100,000")
    if not sweep:
        return figs
    print("\n001 Table 2 sweep (Par 1-12), KF + CPOEM + RTS, SEP per cycle [m]")
    for k in range(1, 13):
        data = scn.model_dump()
        data["sensors"]["imu"]["grade"] = f"par{k}"
        s_k = parse_scenario(data, f"seed001-par{k}")
        sol = estimate(log_of(sensor_streams(s_k, result.tables, ideal, 0)), positioning_config(s_k),
                       ("kf_cpoem_rts",))["kf_cpoem_rts"]
        figs["sweep"][k] = sep_row(sol, truth, cycles)[:4]
        print(f"Par {k:2d} " + " ".join(f"{v:6.3f}" for v in figs["sweep"][k]))
    return figs


def main(sweep: bool = True) -> None:
    figures(sweep)


def throughput(run_dir: str) -> None:
    """IMU samples per second through the filter and the online RTS smoother on an existing run directory."""
    from pathlib import Path

    scn = load_scenario(Path(run_dir) / "scenario.toml")
    log = load_log(Path(run_dir))
    cfg = positioning_config(scn)
    t0 = time.perf_counter()
    estimate(log, cfg, ("kf_cpoem_rts",))
    wall = time.perf_counter() - t0
    print(f"{scn.name}: KF + CPOEM + online RTS {log.imu.size / wall:,.0f} IMU samples/s ({log.imu.size:,} "
          f"samples, {log.imu.times_at(np.array([log.imu.size - 1]))[0] / 3600:.2f} h, in {wall:.1f} s); target >= 100,000")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--throughput"]:
        throughput(sys.argv[2])
    else:
        main("--no-sweep" not in sys.argv[1:])
