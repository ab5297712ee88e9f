"""Per-support push-ram checks (estimators.faults.ram_checks) on seed004: detection, delay and attribution per fault
type, and false alarms over redrawn fault-free trials.

Physics once: seed004 (200 supports, 1 m web, push-ram sensors of 0.02 m, five cycles in 6.4 h) is simulated once;
every trial draws all sensor streams again from the same truth (`sensor_streams(..., trial)`), the faulty cases
with one fault added to the schedule (ram faults and rail_deviation do not change the physics). Each fault is put
on support TARGET around its first push and advance (found in the truth), with magnitudes sized to the 0.02 m
sensor noise; rail_deviation is 004 section V's case (1 deg per two chutes from 2825 s to 3131 s), and the
deviated supports are those whose readings it changes.

A fault counts as detected when a finding of its kind on its support (for rail_deviation: a run of supports
inside the deviated ones) is confirmed inside the fault window; the delay is the confirmation time after the
window starts. push_shortfall is not run: the ram reads the full commanded stroke while the pan stops short, so
no sensor check can see it (left to the rail kinematics model filter).

Run: python benchmarks/bench_ram_checks.py [TRIALS] [--cycles N]   (TRIALS fault-free trials, default 20;
--cycles caps the run at its first N cycles, as the tests' conftest does, when the full 6.4 h is too slow)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from estimators.faults.ram_checks import check_log
from estimators.faults.ram_findings import format_finding
from estimators.faults.ram_levels import LEVEL_SAMPLES
from estimators.faults.ram_neighbours import (
    NEIGHBOUR_SIGMAS,
    NEIGHBOUR_WINDOW,
    _neighbour_filter,
)
from estimators.faults.ram_self_checks import BURST_RATIO, _flat_run
from estimators.faults.ram_strokes import _stroke_threshold
from twin.config.scenario import load_scenario, parse_scenario
from twin.face.layout import support_stations
from twin.pipeline.estimate import ram_layout
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "seed004.toml"
TARGET = 100
KIND = {"ram_stuck": "stuck", "ram_offset": "offset", "ram_drift": "drift", "ram_scale": "scale",
        "ram_dropout": "dropout", "ram_noise_burst": "noise_burst", "rail_deviation": "rail_deviation"}


def first_push(supports: dict[str, np.ndarray], target: int, web: float) -> tuple[float, float]:
    """(start of the first push, first advance) of a support, from its truth rows."""
    rows = supports["support"] == target
    t, ram = supports["t"][rows], supports["ram"][rows]
    advance = int(np.flatnonzero(np.diff(ram) < -0.5 * web)[0]) + 1
    push = int(np.flatnonzero(np.diff(ram[:advance]) > 0.01)[0]) + 1
    return float(t[push]), float(t[advance])


def cases(supports, web: float) -> list[dict]:
    push, advance = first_push(supports, TARGET, web)
    start = round(push - 100.0)

    def f(kind, t0, t1, value=0.0):
        return {"kind": kind, "t_start_s": float(t0), "t_end_s": float(t1), "value": value, "target": TARGET}

    return [
        f("ram_stuck", start, advance + 200),
        f("ram_offset", start, advance + 200, 0.15),
        f("ram_drift", start, start + 1000, 2e-4),
        f("ram_scale", start, advance + 200, 0.15),
        f("ram_dropout", start, start + 300),
        f("ram_noise_burst", start, start + 300, 0.1),
        {"kind": "rail_deviation", "t_start_s": 2825.0, "t_end_s": 3131.0, "value": 1.0},
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("trials", nargs="?", type=int, default=20)
    parser.add_argument("--cycles", type=int, default=None)
    args = parser.parse_args()
    scn = load_scenario(SCENARIO)
    if args.cycles:
        scn = parse_scenario({**scn.model_dump(), "cycles": min(args.cycles, scn.cycles)}, scn.name)
    t0 = time.perf_counter()
    result = simulate(scn)
    ideal = imu_truth(scn, result.tables["truth_shearer"])
    duration = float(result.tables["truth_shearer"]["t"][-1])
    print(f"{scn.name}: {scn.cycles} cycles, {duration / 3600:.2f} h, {support_stations(scn).size} supports, "
          f"ram noise {scn.sensors.pushram.noise_m} m; physics {time.perf_counter() - t0:.0f} s")
    layout = ram_layout(scn)
    interior = _neighbour_filter(layout.n_supports)
    tau_n = layout.bend_m * interior[3][TARGET] + NEIGHBOUR_SIGMAS * layout.sigma_m * interior[2][TARGET] \
        * 1.2533 / np.sqrt(NEIGHBOUR_WINDOW)
    tau_s = _stroke_threshold(layout, np.array([LEVEL_SAMPLES]), np.array([LEVEL_SAMPLES]))[0]
    print(f"thresholds: neighbour {tau_n:.3f} m (support {TARGET}), stroke {tau_s:.3f} m (15-reading plateaus), "
          f"flat run {_flat_run(layout)} readings, burst {BURST_RATIO * layout.sigma_m:.3f} m")

    clean = sensor_streams(scn, result.tables, ideal, 0)["pushram"]
    print(f"\n{'fault':<16}{'value':>8}{'window [s]':>17}  {'detected':<9}{'delay [s]':>10}  {'named':<14}"
          f"{'value found':>12}  other findings")
    check_seconds = []
    for fault in cases(result.tables["truth_supports"], scn.face.web_depth_m):
        faulty = parse_scenario({**scn.model_dump(), "faults": [fault]}, scn.name)
        ram = sensor_streams(faulty, result.tables, ideal, 0)["pushram"]
        start = time.perf_counter()
        found = check_log(ram, ram_layout(faulty))
        check_seconds.append(time.perf_counter() - start)
        t0, t1, kind = fault["t_start_s"], fault["t_end_s"], KIND[fault["kind"]]
        if kind == "rail_deviation":
            changed = np.unique(ram["support"][np.abs(ram["extension"] - clean["extension"]) > 1e-9])
            lo, hi = int(changed.min()), int(changed.max())
            hits = [f for f in found if f.kind == kind and lo <= f.support and f.last_support <= hi]
            where = f"{lo}-{hi} deviated"
        else:
            hits = [f for f in found if f.kind == kind and f.support == f.last_support == TARGET]
            where = f"{TARGET}"
        hits = [f for f in hits if t0 <= f.t_detect < t1 + 1.0]
        other = [f for f in found if f not in hits]
        if hits:
            f = min(hits, key=lambda f: f.t_detect)
            named = f"{f.support}" if f.support == f.last_support else f"{f.support}-{f.last_support}"
            row = f"{'yes':<9}{f.t_detect - t0:>10.0f}  {named:<14}{f.value:>12.4g}"
        else:
            row = f"{'no':<9}{'-':>10}  {'-':<14}{'-':>12}"
        print(f"{fault['kind']:<16}{fault['value']:>8g}{f'{t0:.0f}-{t1:.0f}':>17}  {row}  {len(other)}"
              f"   (target {where})")
        for f in other:
            print(f"{'':<18}{format_finding(f)}")
    print(f"{'push_shortfall':<16}{'':>8}{'':>17}  not a sensor fault: the ram reads the commanded stroke; left to "
          "the rail kinematics model filter")

    alarms, findings_seen = [], []
    for trial in range(args.trials):
        ram = sensor_streams(scn, result.tables, ideal, trial)["pushram"]
        start = time.perf_counter()
        found = check_log(ram, layout)
        check_seconds.append(time.perf_counter() - start)
        alarms.append(len(found))
        findings_seen += found
    print(f"\nfalse alarms over {args.trials} fault-free trials: {sum(alarms)} findings "
          f"({sum(a > 0 for a in alarms)} trials with any)")
    for f in findings_seen:
        print(f"  {format_finding(f)}")
    print(f"checks: {np.median(check_seconds):.1f} s per log ({duration / 3600:.1f} h x "
          f"{layout.n_supports} supports at {scn.sensors.pushram.rate_hz:g} Hz)")


if __name__ == "__main__":
    main()
