"""Benchmark: a face that drifts (issue 25 item 5). The twin alone (no sensors, no estimators, no files) on
scenarios/drift_200.toml, a 200-pan face cut open loop for 50 cycles; prints the pan line's straightness (RMS and max
deviation from its best-fit line) and creep (mean along-face shift of the pans, and of the tailgate drive frame) at
the end of every cycle, and the fitted trend of each. Run: python benchmarks/bench_drift.py [SCENARIO]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from estimators.face.straightness import face_drift
from twin.config.scenario import load_face_scenario
from twin.pipeline.simulate import simulate_stream


def trend(values: np.ndarray) -> tuple[float, float]:
    """Least-squares slope per cycle of `values` over cycles 1..n, and its standard error."""
    k = np.arange(1, values.size + 1, dtype=float)
    coef, res, *_ = np.polyfit(k, values, 1, full=True)
    sigma = np.sqrt(res[0] / (k.size - 2) / ((k - k.mean()) ** 2).sum()) if res.size else 0.0
    return float(coef[0]), float(sigma)


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    path = Path(sys.argv[1]) if len(sys.argv) > 1 else root / "scenarios" / "drift_200.toml"
    scn = load_face_scenario(path)
    start = time.perf_counter()
    result = simulate_stream(scn, lambda rows: None)  # the shearer's truth dropped: memory stays flat
    wall = time.perf_counter() - start
    pans, cycles = result.tables["truth_pans"], result.tables["truth_cycles"]
    times = np.concatenate([[0.0], cycles["t_end"]])
    drift = face_drift(pans, times, scn.face.pan_count, np.radians(scn.face.azimuth_deg))
    print(f"scenario  {path.name}: {scn.face.pan_count} pans, {scn.cycles} cycles, {result.duration_s / 3600:.1f} h "
          f"simulated in {wall:.0f} s ({result.duration_s / wall:.0f}x real time), {result.events} events")
    print(f"{'cycle':>5} {'straightness rms':>17} {'max':>8} {'creep':>8} {'tailgate':>9}   [mm]")
    for k in range(times.size):
        print(f"{'start' if k == 0 else k:>5} {drift.straightness_rms[k] * 1e3:>17.1f} "
              f"{drift.straightness_max[k] * 1e3:>8.1f} {drift.creep[k] * 1e3:>8.1f} {drift.creep_tailgate[k] * 1e3:>9.1f}")
    for name, values in (("straightness rms", drift.straightness_rms), ("straightness max", drift.straightness_max),
                         ("creep", drift.creep), ("tailgate creep", drift.creep_tailgate)):
        slope, sigma = trend(values[1:] * 1e3)
        print(f"trend  {name:<17} {slope:+7.2f} +- {sigma:.2f} mm/cycle   ({values[0] * 1e3:+.1f} at the start, "
              f"{values[-1] * 1e3:+.1f} after cycle {scn.cycles})")


if __name__ == "__main__":
    main()
