"""Benchmark: the twin alone on a scenario (default seed004.toml): wall time, real-time factor, peak memory.

Target (issue 2): 6.4 simulated hours of seed004 in <= 60 s (>= 400x real time), <= 4 GB peak, on the
project's 2-core machine. Run: python benchmarks/bench_twin.py [SCENARIO]
"""

from __future__ import annotations

import json
import resource
import sys
import tempfile
import time
from pathlib import Path

import twin

TARGET_RTF = 400.0
TARGET_PEAK_GB = 4.0


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    scenario = Path(sys.argv[1]) if len(sys.argv) > 1 else root / "scenarios" / "seed004.toml"
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        out = twin.run(scenario, Path(tmp) / "run", force=True, sensors=False).dir
        wall = time.perf_counter() - start
        summary = json.loads((out / "metrics.json").read_text())["twin"]
        size_mb = sum(f.stat().st_size for f in out.iterdir()) / 1e6
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB on Linux
    rtf = summary["simulated_s"] / wall
    print(f"scenario            {scenario.name}")
    print(f"simulated           {summary['simulated_s'] / 3600:.2f} h, {summary['shearer_samples']:,} truth samples, "
          f"{summary['pan_updates']:,} pan updates")
    print(f"wall time           {wall:.1f} s (simulate + truth Parquet + run.rrd; no sensor streams)")
    print(f"real-time factor    {rtf:.0f}x   (target >= {TARGET_RTF:.0f}x)")
    print(f"peak memory         {peak_gb:.2f} GB   (target <= {TARGET_PEAK_GB:.0f} GB)")
    print(f"run directory size  {size_mb:.0f} MB")
    worst_pan = max(c["pan_advance_error_max_mm"] for c in summary["cycles"])
    worst_sup = max(c["support_advance_error_max_mm"] for c in summary["cycles"])
    print(f"advance per cycle   pans within {worst_pan:.1f} mm, supports within {worst_sup:.1f} mm of the web")


if __name__ == "__main__":
    main()
