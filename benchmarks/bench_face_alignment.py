"""Benchmark: closed-loop face alignment (issue 26). The twin alone (no sensors, no files) on
scenarios/face_alignment.toml, a 200-pan face with the drift sources of bench_drift cut for 100 cycles, once per mode:
open loop (no offsets), the face alignment system fed the true shearer path of each shear (the upper bound of what
an estimator can give), and fed the path an estimator makes online from the run's own readings, which the twin draws
as it goes (001's filter smoothed per pass without fixes, kf_rts, and with CPOEM, kf_cpoem_rts; 004's fkf_rail). `--seeds N` makes it a Monte Carlo: each mode run on N seeds (the
face's floor and every sensor's errors redrawn). Prints the pan line's straightness (RMS and max deviation from its
best-fit line) every `--every` cycles per mode, the offsets applied, and over cycles 10 to the end the mean and the
fitted trend, beside the issue's targets; for an estimator, its paths' SEP and their error across the face about
its best-fit line. The runs go to `--workers` processes.

Run: python benchmarks/bench_face_alignment.py [--cycles N] [--every K] [--modes none,truth,kf_rts,kf_cpoem_rts,fkf_rail]
     [--seeds N] [--workers W]
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from estimators.face.straightness import face_drift
from twin.config.scenario import load_face_scenario, parse_scenario
from twin.pipeline.simulate import simulate_stream

SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "face_alignment.toml"
TARGETS = {"none": "grows", "truth": "<= 30 mm RMS, no trend", "kf_rts": "<= 50 mm RMS, no trend",
           "kf_cpoem_rts": "<= 50 mm RMS, no trend",
           "fkf_rail": "<= 50 mm RMS, no trend"}
SETTLED_CYCLE = 10
"""The issue's statistics are over cycles 10 to the end: the loop's first shears remove the installed line's error."""


def trend(values: np.ndarray) -> float:
    """Least-squares slope of `values` per cycle."""
    return float(np.polyfit(np.arange(values.size, dtype=float), values, 1)[0]) if values.size > 1 else np.nan


def run_mode(mode: str, cycles: int, seed: int | None = None) -> dict:
    """The face's straightness after every cycle (RMS, max [m]), its creep, and the offsets applied (RMS per cycle);
    `seed` replaces the scenario's (the face's floor and every sensor's errors)."""
    data = load_face_scenario(SCENARIO).model_dump()
    data["cycles"] = cycles
    data["alignment"]["mode"] = mode
    if seed is not None:
        data["seed"] = seed
    scn = parse_scenario(data, SCENARIO.name)
    start = time.perf_counter()
    result = simulate_stream(scn, lambda rows: None)
    wall = time.perf_counter() - start
    drift = face_drift(result.tables["truth_pans"], result.tables["truth_cycles"]["t_end"], scn.face.pan_count,
                       np.radians(scn.face.azimuth_deg))
    return {"rms": drift.straightness_rms, "max": drift.straightness_max, "creep": drift.creep,
            "offsets": np.sqrt((result.offsets ** 2).mean(axis=1)), "wall": wall, "hours": result.duration_s / 3600,
            "held": [s.note for s in result.alignment if s.held], "errors": result.path_errors}


def _spread(values: list[float], fmt: str) -> str:
    """mean (+- sd over the seeds when there are several)."""
    v = np.asarray(values, float)
    return f"{v.mean():{fmt}}" + (f" +- {v.std(ddof=1):{fmt}}" if v.size > 1 else "")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=None, help="cycles to cut (the scenario's 100)")
    parser.add_argument("--every", type=int, default=10, help="print every K cycles")
    parser.add_argument("--modes", default="none,truth,kf_rts,kf_cpoem_rts,fkf_rail",
                        help="comma-separated: none, truth, kf_rts, kf_cpoem_rts, kf_cpoem, kf, fkf_rail")
    parser.add_argument("--seeds", type=int, default=1,
                        help="Monte Carlo: runs per mode, seeds scenario seed + 0..N-1 (default 1: the scenario's)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="processes (default: the cores)")
    args = parser.parse_args()
    base = load_face_scenario(SCENARIO)
    cycles = args.cycles or base.cycles
    modes = args.modes.split(",")
    tasks = [(mode, base.seed + k) for mode in modes for k in range(args.seeds)]
    with ProcessPoolExecutor(max_workers=min(args.workers, len(tasks))) as pool:
        done = list(pool.map(run_mode, *zip(*[(m, cycles, seed) for m, seed in tasks])))
    runs = {mode: [r for (m, _), r in zip(tasks, done) if m == mode] for mode in modes}
    first = runs[modes[0]][0]
    print(f"scenario {SCENARIO.name}: {cycles} cycles, {first['hours']:.1f} h simulated per run, {args.seeds} seed(s) "
          f"per mode; wall per run: " + ", ".join(f"{m} {_spread([r['wall'] for r in rs], '.0f')} s"
                                                  for m, rs in runs.items()))
    width = {m: len(m) + 6 for m in modes}
    print(f"{'cycle':>5}" + "".join(f"{m + ' rms':>{width[m]}}{'max':>7}{'offsets':>9}" for m in modes)
          + f"   [mm{', mean over the seeds' if args.seeds > 1 else ''}]")
    for k in [*range(0, cycles, args.every), cycles - 1]:
        print(f"{k + 1:>5}" + "".join(
            f"{np.mean([r['rms'][k] for r in rs]) * 1e3:>{width[m]}.1f}{np.mean([r['max'][k] for r in rs]) * 1e3:>7.1f}"
            f"{np.mean([r['offsets'][k] for r in rs]) * 1e3:>9.1f}" for m, rs in runs.items()))
    settled = min(SETTLED_CYCLE, cycles) - 1
    print(f"\ncycles {SETTLED_CYCLE}-{cycles}{' (mean +- sd over the seeds)' if args.seeds > 1 else ''}:")
    for mode, rs in runs.items():
        tails = [r["rms"][settled:] * 1e3 for r in rs]
        print(f"  {mode:<12} straightness RMS mean {_spread([t.mean() for t in tails], '.1f')} mm, largest "
              f"{_spread([t.max() for t in tails], '.1f')} mm, trend {_spread([trend(t) for t in tails], '+.3f')} "
              f"mm/cycle; creep {_spread([r['creep'][-1] * 1e3 for r in rs], '+.0f')} mm; target "
              f"{TARGETS.get(mode, '-')}")
        errors = [e for r in rs for e in r["errors"]]
        if errors:
            sep = np.array([e["sep_m"] for e in errors]) * 1e3
            across = np.array([e["x_rms_m"] for e in errors]) * 1e3
            print(f"               its paths over {sep.size} shears: SEP median {np.median(sep):.0f} mm (largest "
                  f"{sep.max():.0f}), across the face about the best-fit line RMS median {np.median(across):.1f} mm "
                  f"(largest {across.max():.1f})")
        for note in sorted({n for r in rs for n in r["held"]}):
            print(f"               {note}")


if __name__ == "__main__":
    main()
