"""Benchmark: closed-loop face alignment (issue 26). The twin alone (no sensors, no files) on
scenarios/face_alignment.toml, a 200-pan face with the drift sources of bench_drift cut for 100 cycles, once per mode:
open loop (no offsets), the face alignment system fed the true shearer path of each shear (the upper bound of what
an estimator can give), and fed the path 001's filter estimates online from the run's own readings (kf_cpoem_rts; the
twin draws them as it goes). Prints the pan line's straightness (RMS and max deviation from its best-fit line) every
`--every` cycles per mode, the offsets applied, and over cycles 10 to the end the mean and the fitted trend, beside
the issue's targets; for an estimator, its paths' SEP and their error across the face about its best-fit line. The
modes run in parallel processes, one a core.

Run: python benchmarks/bench_face_alignment.py [--cycles N] [--every K] [--modes none,truth,kf_cpoem_rts]
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from estimators.face.straightness import face_drift
from twin.config.scenario import load_face_scenario, parse_scenario
from twin.pipeline.simulate import simulate_stream

SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "face_alignment.toml"
TARGETS = {"none": "grows", "truth": "<= 30 mm RMS, no trend", "kf_cpoem_rts": "<= 50 mm RMS, no trend"}
SETTLED_CYCLE = 10
"""The issue's statistics are over cycles 10 to the end: the loop's first shears remove the installed line's error."""


def trend(values: np.ndarray) -> float:
    """Least-squares slope of `values` per cycle."""
    return float(np.polyfit(np.arange(values.size, dtype=float), values, 1)[0]) if values.size > 1 else np.nan


def run_mode(mode: str, cycles: int) -> dict:
    """The face's straightness after every cycle (RMS, max [m]), its creep, and the offsets applied (RMS per cycle)."""
    data = load_face_scenario(SCENARIO).model_dump()
    data["cycles"] = cycles
    data["alignment"]["mode"] = mode
    scn = parse_scenario(data, SCENARIO.name)
    start = time.perf_counter()
    result = simulate_stream(scn, lambda rows: None)
    wall = time.perf_counter() - start
    drift = face_drift(result.tables["truth_pans"], result.tables["truth_cycles"]["t_end"], scn.face.pan_count,
                       np.radians(scn.face.azimuth_deg))
    return {"rms": drift.straightness_rms, "max": drift.straightness_max, "creep": drift.creep,
            "offsets": np.sqrt((result.offsets ** 2).mean(axis=1)), "wall": wall, "hours": result.duration_s / 3600,
            "held": [s.note for s in result.alignment if s.held], "errors": result.path_errors}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=None, help="cycles to cut (the scenario's 100)")
    parser.add_argument("--every", type=int, default=10, help="print every K cycles")
    parser.add_argument("--modes", default="none,truth,kf_cpoem_rts",
                        help="comma-separated: none, truth, kf_cpoem_rts, kf_cpoem, kf")
    args = parser.parse_args()
    cycles = args.cycles or load_face_scenario(SCENARIO).cycles
    modes = args.modes.split(",")
    with ProcessPoolExecutor(max_workers=len(modes)) as pool:
        runs = dict(zip(modes, pool.map(run_mode, modes, [cycles] * len(modes))))
    first = runs[modes[0]]
    print(f"scenario {SCENARIO.name}: {cycles} cycles, {first['hours']:.1f} h simulated per mode; "
          + ", ".join(f"{m} {r['wall']:.0f} s" for m, r in runs.items()))
    print(f"{'cycle':>5}" + "".join(f"{m + ' rms':>12}{'max':>7}{'offsets':>9}" for m in modes) + "   [mm]")
    for k in [*range(0, cycles, args.every), cycles - 1]:
        print(f"{k + 1:>5}" + "".join(f"{r['rms'][k] * 1e3:>12.1f}{r['max'][k] * 1e3:>7.1f}{r['offsets'][k] * 1e3:>9.1f}"
                                     for r in runs.values()))
    print(f"\ncycles {SETTLED_CYCLE}-{cycles}:")
    for mode, r in runs.items():
        tail = r["rms"][min(SETTLED_CYCLE, cycles) - 1:] * 1e3
        print(f"  {mode:<6} straightness RMS mean {tail.mean():6.1f} mm, largest {tail.max():6.1f} mm, trend "
              f"{trend(tail):+.3f} mm/cycle; creep {r['creep'][-1] * 1e3:+.0f} mm; target {TARGETS.get(mode, '-')}")
        if r["errors"]:
            sep = np.array([e["sep_m"] for e in r["errors"]]) * 1e3
            across = np.array([e["x_rms_m"] for e in r["errors"]]) * 1e3
            print(f"         its paths over {sep.size} shears: SEP median {np.median(sep):.0f} mm (largest "
                  f"{sep.max():.0f}), across the face about the best-fit line RMS median {np.median(across):.1f} mm "
                  f"(largest {across.max():.1f})")
        for note in r["held"]:
            print(f"         {note}")


if __name__ == "__main__":
    main()
