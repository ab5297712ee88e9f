"""Monte Carlo of the 001 shearer positioning on seed001: SEP per cycle (mean and spread) and the filter's
consistency, the average normalized estimation error squared (ANEES) of position and attitude against the
two-sided 95 % chi-square band (Bar-Shalom section 5.4.2).

Physics once: seed001 is simulated once; each trial redraws every sensor error (IMU, odometer, push rams,
survey) from the same truth. NEES uses the estimators' one-sigma columns (diagonal covariance).
Run: python benchmarks/bench_positioning_mc.py [TRIALS] [METHOD ...]
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

from estimators import metrics
from estimators import shearer_positioning as sp
from twin.cli import default_scenario
from twin.estimate import positioning_config
from twin.scenario import load_scenario
from twin.sensors import imu_truth, sensor_streams
from twin.simulate import simulate


def main(trials: int = 20, methods: tuple[str, ...] = ("kf_cpoem", "kf_cpoem_rts"), **overrides) -> dict:
    """`overrides`: Config fields to change (tuning studies). Prints the table; returns per method the SEP per
    trial and cycle [m] (`sep`, trials x cycles) and the median ANEES of position and attitude (`anees_pos`,
    `anees_att`) with the band (`band`)."""
    figs: dict = {"sep": {}, "anees_pos": {}, "anees_att": {}, "band": None}
    scn = load_scenario(default_scenario().parent / "seed001.toml")
    result = simulate(scn)
    truth, cycles = result.tables["truth_shearer"], result.tables["truth_cycles"]
    ideal = imu_truth(scn, truth)
    cfg = dataclasses.replace(positioning_config(scn), **overrides)
    seps = {m: [] for m in methods}
    nees_pos = {m: [] for m in methods}
    nees_att = {m: [] for m in methods}
    t0 = time.perf_counter()
    for trial in range(trials):
        s = sensor_streams(scn, result.tables, ideal, trial)
        sols = sp.estimate(sp.log_from_columns(s["imu"], s["odometer"], s["survey"], s["pushram"]), cfg, methods)
        for m, sol in sols.items():
            cols = sp.estimate_columns(sol)
            t, err = metrics.position_errors(cols, truth)
            _, att = metrics.attitude_errors(cols, truth)
            seps[m].append([c["sep"] for c in metrics.cycle_metrics(t, err, cycles)])
            nees_pos[m].append(metrics.nees(err, sol.sd[:, 0:3]))
            nees_att[m].append(metrics.nees(att, sol.sd[:, 6:9]))
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
    return figs


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    main(n, tuple(sys.argv[2:]) or ("kf_cpoem", "kf_cpoem_rts"))
