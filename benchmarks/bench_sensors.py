"""Benchmark: all sensor streams of a scenario (default seed004.toml) from its truth, per trial.

Target (issue 3): every sensor stream of seed004 in <= 10 s (>= 500,000 IMU samples/s) on this 2-core
machine; for comparison, gnss-ins-sim's generator manages about 20,000 samples/s here.
Run: python benchmarks/bench_sensors.py [SCENARIO]
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from twin.config.scenario import load_scenario
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams


def main() -> None:
    root = Path(__file__).resolve().parent.parent
    scn = load_scenario(Path(sys.argv[1]) if len(sys.argv) > 1 else root / "scenarios" / "seed004.toml")
    truth = simulate(scn).tables
    n = truth["truth_shearer"]["t"].size
    start = time.perf_counter()
    ideal = imu_truth(scn, truth["truth_shearer"])
    t_ideal = time.perf_counter() - start
    times = []
    for trial in range(2):
        start = time.perf_counter()
        streams = sensor_streams(scn, truth, ideal, trial)
        times.append(time.perf_counter() - start)
    total = t_ideal + times[0]
    rows = {name: len(cols["t"]) if "t" in cols else len(next(iter(cols.values()))) for name, cols in streams.items()}
    print(f"scenario                {scn.name}: {n:,} truth samples")
    print(f"ideal IMU increments    {t_ideal:.2f} s (once per run: lever arm, mounting, vibration)")
    print(f"sensor errors, trial    {times[0]:.2f} s, {times[1]:.2f} s (every stream: {rows})")
    print(f"all streams, first trial {total:.2f} s = {n / total:,.0f} IMU samples/s   (target <= 10 s, >= 500,000/s)")
    print(f"each further trial      {times[1]:.2f} s = {n / times[1]:,.0f} samples/s")


if __name__ == "__main__":
    main()
