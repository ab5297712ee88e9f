"""004 on the twin: INS/odometer against the federated INS/odometer + INS/rail-kinematics-model filter per cycle
beside 004 Table 2, the rail-model fault of 004 section V.A (seed004_fault) with the three detectors side by side
(detection delay, clearing delay, misses, false alarms per hour, error during the fault), fault-free Monte Carlo
false alarms of the fading SPRT; with --long instead the 20-cycle variant (seed004_20cycles, 25.7 h).

Physics once: seed004 is simulated once; seed004_fault differs only in the fault, which acts on the push-ram
sensors, so its trials draw their sensors from the same truth. Each trial redraws every sensor error.
Run: python benchmarks/bench_rail.py [TRIALS] | --long
"""

from __future__ import annotations

import sys
import time

import numpy as np

from estimators.io import metrics
from estimators.io.log import Log, log_from_columns
from estimators.io.logformat import FLAG_ISOLATED
from estimators.shearer.positioning import run_kf
from estimators.shearer.prepare import Prepared, prepare
from estimators.shearer.rail_kinematics import (
    ARM_FIXES,
    DETECTORS,
    detector_chi2,
    fsprt_alarms,
    run_rail,
)
from estimators.shearer.solution import Solution, estimate_columns
from twin.cli import default_scenario
from twin.config.scenario import load_scenario
from twin.pipeline.estimate import positioning_config
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

TABLE2 = {  # 004 Table 2, RMSE per cycle [m]: INS/ODO east, north; assisted by model east, north
    "kf": ([0.886, 0.964, 0.939, 0.981, 1.041], [0.853, 1.002, 0.851, 0.923, 0.970]),
    "fkf_rail": ([0.420, 0.446, 0.592, 0.663, 0.816], [0.180, 0.239, 0.208, 0.226, 0.214]),
}
CLEAR_MARGIN_S = 60.0
"""Isolation that ends within this time after the fault counts as the fault's, not as a false alarm."""


def _log(scn, tables, ideal, trial: int) -> Log:
    s = sensor_streams(scn, tables, ideal, trial)
    return log_from_columns(s["imu"], s["odometer"], s["survey"], s["pushram"], face_survey=s["face_survey"])


def _cycle_rmse(sol: Solution, tables) -> np.ndarray:
    """(cycles, 2) RMSE east, north."""
    _, err = metrics.position_errors(estimate_columns(sol), tables["truth_shearer"])
    rows = metrics.cycle_metrics(sol.t, err, tables["truth_cycles"])[:-1]
    return np.array([[r["rmse_e"], r["rmse_n"]] for r in rows])


def _windows(t: np.ndarray, flag: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) of the runs of True in flag at times t."""
    edges = np.diff(np.concatenate([[0], flag.astype(np.int8), [0]]))
    return [(float(t[a]), float(t[b - 1])) for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]


def armed_fsprt(detectors: dict[str, np.ndarray], prep: Prepared) -> np.ndarray:
    """The FSPRT statistic at the fixes where it can raise an alarm: from each pass's (ARM_FIXES + 1)-th tested
    fix on (estimators.shearer.rail_fix_update counts the tested fixes per pass, prep.segments)."""
    tested = np.isfinite(detectors["fsprt"])
    t_tested = detectors["t"][tested]
    starts = prep.t_kf[[a for a, _ in prep.segments]]
    pass_of = np.searchsorted(starts, t_tested, side="left")  # a pass holds the fixes after its first epoch
    first = np.searchsorted(pass_of, pass_of, side="left")  # index of the pass's first tested fix
    rank = np.arange(t_tested.size) - first + 1
    return detectors["fsprt"][tested][rank > ARM_FIXES]


def detector_figures(sol: Solution, name: str, threshold: float, t0: float, t1: float, hours: float,
                     t_on: float) -> dict[str, float]:
    """Delay to the first alarm after t0, delay of the clearing after t1, fault fixes not flagged, false alarms
    per hour (alarms outside [t0, t1 + CLEAR_MARGIN_S]). An FSPRT alarm is its statistic crossing T1 (004 eq.
    24); the isolation flag it raises is dated back to the fault's onset (the filter rolls back), so it may start
    before t0 and is not itself the alarm."""
    d = sol.detectors
    if name == "fsprt":
        alarms = fsprt_alarms(d, t_on)
        inside = [(a, b) for a, b in _windows(sol.t, (sol.flags & FLAG_ISOLATED) > 0)
                  if a <= t1 + CLEAR_MARGIN_S and b >= t0]
    else:
        alarms = d["t"][d[name] > threshold]
        inside = []
    first = alarms[(alarms >= t0) & (alarms <= t1 + CLEAR_MARGIN_S)]
    cleared = max((b for _, b in inside), default=np.nan)
    in_fault = (d["t"] >= t0) & (d["t"] <= t1)
    if name == "fsprt":
        missed = int(np.sum(in_fault & (d["isolated"] == 0) & (d["t"] >= (first[0] if first.size else t1))))
    else:
        missed = int(np.sum(in_fault & ~(d[name] > threshold)))
    false = int(np.sum((alarms < t0) | (alarms > t1 + CLEAR_MARGIN_S)))
    return {"delay": (first[0] - t0) if first.size else np.nan, "clear": cleared - t1 if name == "fsprt" else np.nan,
            "missed": missed, "fixes": int(in_fault.sum()), "false_per_h": false / hours}


def main(trials: int = 20) -> None:
    figures(trials)


def figures(trials: int = 20) -> dict:
    """Print the benchmark; return its figures: trial 0's RMSE per cycle (`rmse`: method -> (cycles, 2) east,
    north [m]), the faulted run's detectors (`detectors`: name -> detector_figures plus `error_in_fault` [m]; the
    fault-free filter's `clean_error_in_fault`, no isolation's `none_error_in_fault`), and the fault-free Monte
    Carlo trials 1..trials: FSPRT alarms per trial (`alarms`), the largest statistic on an armed fix per trial
    (`peak_fsprt`) and RMSE per cycle (`mc_rmse`, (trials, cycles, 2))."""
    figs: dict = {"detectors": {}}
    t_start = time.perf_counter()
    scn = load_scenario(default_scenario().parent / "seed004.toml")
    scn_fault = load_scenario(default_scenario().parent / "seed004_fault.toml")
    result = simulate(scn)
    tables = result.tables
    ideal = imu_truth(scn, tables["truth_shearer"])
    cfg = positioning_config(scn)
    t_sim = time.perf_counter() - t_start
    hours = float(tables["truth_shearer"]["t"][-1]) / 3600

    log = _log(scn, tables, ideal, 0)
    prep = prepare(log, cfg)
    t0 = time.perf_counter()
    kf_sol = run_kf(log, cfg, prep, cpoem=False, smooth=False)[0]
    t_kf = time.perf_counter() - t0
    t0 = time.perf_counter()
    rail = run_rail(log, cfg, prep)
    t_rail = time.perf_counter() - t0
    rmse = {"kf": _cycle_rmse(kf_sol, tables), "fkf_rail": _cycle_rmse(rail, tables)}
    figs["rmse"] = rmse
    print(f"seed004 (simulated in {t_sim:.0f} s), trial 0: RMSE per cycle [m], ours beside 004 Table 2")
    print(f"{'cycle':>5s}  {'INS/ODO E':>18s} {'INS/ODO N':>18s}   {'with model E':>18s} {'with model N':>18s}")
    for k in range(rmse["kf"].shape[0]):
        cells = [f"{rmse[m][k, i]:8.3f} ({TABLE2[m][i][k]:5.3f})" if k < 5 else f"{rmse[m][k, i]:8.3f}"
                 for m in ("kf", "fkf_rail") for i in (0, 1)]
        print(f"{k + 1:5d}  {cells[0]:>18s} {cells[1]:>18s}   {cells[2]:>18s} {cells[3]:>18s}")
    n_imu = log.imu.size
    print(f"throughput: INS/odometer {n_imu / t_kf:,.0f}, federated rail filter {n_imu / t_rail:,.0f} IMU samples/s")

    fault = scn_fault.faults[0]
    f_log = _log(scn_fault, tables, ideal, 0)
    f_prep = prepare(f_log, cfg)
    thr = dict(zip(("residual", "dual_state"), detector_chi2(cfg.detector)))
    print(f"\nseed004_fault, trial 0: rail deviation {fault.value:g} deg per two chutes, {fault.t_start_s:g}-"
          f"{fault.t_end_s:g} s; detectors (thresholds: residual chi-square {thr['residual']:.1f}, dual-state "
          f"{thr['dual_state']:.1f}, FSPRT {cfg.detector.t_on:g} / "
          f"{cfg.detector.t_off:g}, fading {cfg.detector.fading:g})")
    clean_err = _window_error(rail, tables, fault)
    figs["clean_error_in_fault"] = clean_err
    print(f"{'isolating detector':20s} {'delay [s]':>9s} {'clear [s]':>9s} {'missed':>8s} {'false/h':>8s} "
          f"{'max horiz. error in fault [m]':>30s}  (fault-free {clean_err:.3f}; target <= +0.05)")
    for name in DETECTORS:
        sol = run_rail(f_log, cfg, f_prep, isolate_by=name)
        fig = detector_figures(sol, name, thr.get(name, np.nan), fault.t_start_s, fault.t_end_s, hours, cfg.detector.t_on)
        fig["error_in_fault"] = _window_error(sol, tables, fault)
        figs["detectors"][name] = fig
        print(f"{name:20s} {fig['delay']:9.1f} {fig['clear']:9.1f} {fig['missed']:4d}/{fig['fixes']:<3d} "
              f"{fig['false_per_h']:8.2f} {fig['error_in_fault']:30.3f}")
    none = run_rail(f_log, cfg, f_prep, isolate_by=None)
    figs["none_error_in_fault"] = _window_error(none, tables, fault)
    print(f"{'none (no isolation)':20s} {'':9s} {'':9s} {'':8s} {'':8s} {figs['none_error_in_fault']:30.3f}")
    print("targets: FSPRT delay <= 60 s, clear <= 60 s after the fault ends")

    alarms, worst, mc_rmse, peak = [], [], [], []
    for trial in range(1, trials + 1):
        tlog = _log(scn, tables, ideal, trial)
        tprep = prepare(tlog, cfg)
        sol = run_rail(tlog, cfg, tprep)
        alarms.append(int(fsprt_alarms(sol.detectors, cfg.detector.t_on).size))
        peak.append(float(armed_fsprt(sol.detectors, tprep).max()))
        mc_rmse.append(_cycle_rmse(sol, tables))
        worst.append(mc_rmse[-1].max(axis=0))
    worst = np.array(worst)
    figs["alarms"], figs["mc_rmse"], figs["peak_fsprt"] = alarms, np.array(mc_rmse), peak
    print(f"\nfault-free Monte Carlo, {trials} trials of seed004 ({trials * hours:.0f} h): FSPRT false alarms "
          f"{sum(alarms)} (target 0; per trial {alarms}); worst cycle RMSE E {worst[:, 0].mean():.3f} +- "
          f"{worst[:, 0].std():.3f}, N {worst[:, 1].mean():.3f} +- {worst[:, 1].std():.3f} m")
    print(f"largest FSPRT statistic on an armed fault-free fix: {max(peak):.2f} (trial {int(np.argmax(peak)) + 1}; "
          f"T1 {cfg.detector.t_on:g}); per trial " + " ".join(f"{v:.1f}" for v in peak))
    mean = figs["mc_rmse"].mean(axis=0)
    print("mean RMSE per cycle E " + " ".join(f"{v:.3f}" for v in mean[:, 0]) + ", N "
          + " ".join(f"{v:.3f}" for v in mean[:, 1]) + f" m; trial-cycles at or under 0.10 m: E "
          f"{np.mean(figs['mc_rmse'][:, :, 0] <= 0.10):.0%}, N {np.mean(figs['mc_rmse'][:, :, 1] <= 0.10):.0%}")
    print(f"\ntotal {time.perf_counter() - t_start:.0f} s")
    return figs


def _window_error(sol: Solution, tables, fault) -> float:
    """Largest horizontal error while the fault acts and a minute after."""
    _, err = metrics.position_errors(estimate_columns(sol), tables["truth_shearer"])
    w = (sol.t >= fault.t_start_s) & (sol.t <= fault.t_end_s + CLEAR_MARGIN_S)
    return float(np.hypot(err[w, 0], err[w, 1]).max())


def _long_run() -> None:
    """seed004_20cycles: RMSE per cycle with and without the model, the largest error, FSPRT alarms (fault-free)."""
    t_start = time.perf_counter()
    scn = load_scenario(default_scenario().parent / "seed004_20cycles.toml")
    result = simulate(scn)
    ideal = imu_truth(scn, result.tables["truth_shearer"])
    cfg = positioning_config(scn)
    log = _log(scn, result.tables, ideal, 0)
    prep = prepare(log, cfg)
    t_sim = time.perf_counter() - t_start
    sols = {"kf": run_kf(log, cfg, prep, cpoem=False, smooth=False)[0]}
    t0 = time.perf_counter()
    sols["fkf_rail"] = run_rail(log, cfg, prep)
    t_rail = time.perf_counter() - t0
    hours = float(result.tables["truth_shearer"]["t"][-1]) / 3600
    print(f"seed004_20cycles ({hours:.1f} h, simulated in {t_sim:.0f} s): RMSE per cycle E / N [m]")
    for m, sol in sols.items():
        r = _cycle_rmse(sol, result.tables)
        _, err = metrics.position_errors(estimate_columns(sol), result.tables["truth_shearer"])
        print(f"{m:9s} E " + " ".join(f"{v:.2f}" for v in r[:, 0]))
        print(f"{'':9s} N " + " ".join(f"{v:.2f}" for v in r[:, 1]))
        print(f"{'':9s} max horizontal error {np.nanmax(np.hypot(err[:, 0], err[:, 1])):.2f} m, finite "
              f"{bool(np.isfinite(sol.llh).all())}; last 5 cycles' worst RMSE E {r[-5:, 0].max():.2f}, "
              f"N {r[-5:, 1].max():.2f} m against the first 5's E {r[:5, 0].max():.2f}, N {r[:5, 1].max():.2f}")
    alarms = fsprt_alarms(sols["fkf_rail"].detectors, cfg.detector.t_on)
    print(f"FSPRT alarms (fault-free): {alarms.size}; rail filter {log.imu.size / t_rail:,.0f} IMU samples/s; "
          f"total {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if "--long" in sys.argv:
        _long_run()
    else:
        main(int(args[0]) if args else 20)
