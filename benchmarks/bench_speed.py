"""Benchmark: the speed table of issue 9, measured in one run, as ratios against peer packages.

Rows (seed004 is simulated once; rows 1, 2, 3 and 4 use that one simulation):

1. twin real-time factor: simulated seconds / wall seconds of twin.pipeline.simulate.simulate (no Parquet, no Rerun;
   benchmarks/bench_twin.py times the whole `longwall run --twin-only`);            target >= 400x (issue 2)
2. sensor streams: IMU samples generated per wall second, the ideal increments plus every stream of one trial
   (twin.sensors.streams.imu_truth + sensor_streams, as benchmarks/bench_sensors.py's headline);   target >= 1,000,000/s (issue 24)
3. strapdown mechanization, 4-sample coning/sculling, on seed004's IMU increments (benchmarks/bench_strapdown.py's
   ours and pyins_time) against pyins's compute_increments_from_imu + Integrator;   target >= 5,000,000/s (issue 24)
4. filter plus smoother: KF + CPOEM + online RTS (shearer_positioning, as benchmarks/bench_positioning.py
   --throughput) over the whole of seed004 against pyins's run_feedback_filter (pyins has no smoother) on the
   first --pyins-seconds of the same log;                                          target >= 500,000/s (issue 24)
5. support attitude, 200 supports at 100 Hz (benchmarks/bench_support_attitude.py's face_readings): 002's UKF
   and ours against ahrs.filters.UKF on the same readings, per support-sample; target for ours >= 100x real time
   (issue 8), i.e. >= 2,000,000 support-samples/s;
6. peak resident memory per stage (the process's high-water mark, reset before each stage through
   /proc/self/clear_refs) and over the run; target for the twin <= 4 GB (issue 2).

Peers are the `bench` extra (pip install -e ".[bench]": python-ins, imported as pyins, and ahrs); a peer that is
not installed is named and its ratio skipped. The table is printed and written as Markdown and CSV (--out).
Run: python benchmarks/bench_speed.py [--out runs/bench/speed.md] [--quick]
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import math
import re
import resource
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # the sibling benchmarks, when imported from tests

from tables import markdown_table, text_table  # a sibling: after the path above

INSTALL_HINT = 'pip install -e ".[bench]"'
TARGET_SENSORS = 1_000_000.0  # issue 24 (issue 3: 500,000)
TARGET_STRAPDOWN = 5_000_000.0  # issue 24 (issue 4: 1,000,000)
TARGET_FILTER = 500_000.0  # issue 24 (issue 5: 100,000)
TARGET_SUPPORT_RTF = 100.0


# ------------------------------------------------------------------------------------------------------------
# The table


@dataclass
class Row:
    """One figure of the speed table. `ours` and `peer` in `unit`; a ratio is ours / peer (higher is better for
    every throughput row); `target_min` / `target_max` bound ours."""

    figure: str
    unit: str
    ours: float | None
    peer_name: str = ""
    peer: float | None = None
    peer_missing: str = ""  # why there is no peer figure (not installed, failed); empty: no peer for this row
    target: str = ""
    target_min: float | None = None
    target_max: float | None = None
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.ours is None or self.peer is None or self.peer <= 0:
            return None
        return self.ours / self.peer

    @property
    def met(self) -> bool | None:
        if self.ours is None or (self.target_min is None and self.target_max is None):
            return None
        return ((self.target_min is None or self.ours >= self.target_min)
                and (self.target_max is None or self.ours <= self.target_max))


def fmt_value(value: float | None, unit: str) -> str:
    if value is None or not math.isfinite(value):
        return "-"
    if unit == "x":
        return f"{value:,.0f}x" if value >= 100 else f"{value:,.1f}x"
    if unit == "GB":
        return f"{value:.2f} GB"
    return f"{value:,.0f} {unit}" if value >= 100 else f"{value:,.3g} {unit}"


def table_cells(rows: Sequence[Row]) -> list[list[str]]:
    """Header and one line of text cells per row: figure, ours, peer, ratio, target, note."""
    out = [["figure", "ours", "peer", "ratio (ours/peer)", "target", "note"]]
    for r in rows:
        if r.peer is not None:
            peer = f"{r.peer_name}: {fmt_value(r.peer, r.unit)}"
            ratio = f"{r.ratio:,.1f}x" if r.ratio is not None else "-"
        elif r.peer_missing:
            peer, ratio = f"skipped: {r.peer_name} {r.peer_missing}".replace("  ", " "), "skipped"
        else:
            peer, ratio = "-", "-"
        target = r.target or "-"
        if r.met is not None:
            target += " (met)" if r.met else " (NOT met)"
        out.append([r.figure, fmt_value(r.ours, r.unit), peer, ratio, target, r.note])
    return out


def format_text(rows: Sequence[Row]) -> str:
    cells = table_cells(rows)
    notes = [f"  {line[0]}: {line[5]}" for line in cells[1:] if line[5]]
    return "\n".join([text_table([line[:5] for line in cells])] + (["", "notes:"] + notes if notes else []))


def format_markdown(rows: Sequence[Row], title: str = "Speed table") -> str:
    return markdown_table(title, table_cells(rows))


CSV_FIELDS = ["figure", "unit", "ours", "peer_name", "peer", "ratio", "peer_status", "target", "target_met", "note"]


def csv_records(rows: Sequence[Row]) -> list[dict[str, str]]:
    def num(v):
        return "" if v is None or not math.isfinite(v) else f"{v:.6g}"

    recs = []
    for r in rows:
        status = "measured" if r.peer is not None else (f"skipped: {r.peer_missing}" if r.peer_missing else "none")
        recs.append({"figure": r.figure, "unit": r.unit, "ours": num(r.ours), "peer_name": r.peer_name,
                     "peer": num(r.peer), "ratio": num(r.ratio), "peer_status": status, "target": r.target,
                     "target_met": "" if r.met is None else str(r.met).lower(), "note": r.note})
    return recs


def write_table(rows: Sequence[Row], out_md: Path, title: str = "Speed table") -> tuple[Path, Path]:
    """The table as Markdown at `out_md` and as CSV beside it (same stem, .csv)."""
    out_md = Path(out_md)
    out_md.parent.mkdir(parents=True, exist_ok=True)
    out_csv = out_md.with_suffix(".csv")
    out_md.write_text(format_markdown(rows, title))
    with out_csv.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_FIELDS)
        writer.writeheader()
        writer.writerows(csv_records(rows))
    return out_md, out_csv


# ------------------------------------------------------------------------------------------------------------
# Peers and memory


def peer_version(dist: str, module: str) -> str | None:
    """The installed version of a peer, None if it does not import."""
    try:
        __import__(module)
    except ImportError:
        return None
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return "?"


class Memory:
    """Peak resident memory per stage: the kernel's high-water mark (VmHWM) reset before each stage (Linux >= 4.0,
    /proc/self/clear_refs); elsewhere the process's ru_maxrss, which only grows."""

    def __init__(self) -> None:
        self.stages: dict[str, float] = {}
        self.reset_ok = self._reset()

    @staticmethod
    def _reset() -> bool:
        try:
            Path("/proc/self/clear_refs").write_text("5")
            return True
        except OSError:
            return False

    @staticmethod
    def _peak_gb() -> float:
        try:
            m = re.search(r"VmHWM:\s+(\d+)\s+kB", Path("/proc/self/status").read_text())
            if m:
                return int(m.group(1)) / 1e6
        except OSError:
            pass
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6  # kB on Linux

    def measure(self, stage: str, fn: Callable, *args):
        self._reset()
        try:
            return fn(*args)
        finally:
            self.stages[stage] = self._peak_gb()

    def overall_gb(self) -> float:
        return max([*self.stages.values(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6])


# ------------------------------------------------------------------------------------------------------------
# Stages


def stage_twin(scn) -> tuple[object, float, float]:
    """Simulate once: (result, simulated seconds, wall seconds)."""
    from twin.pipeline.simulate import simulate

    start = time.perf_counter()
    result = simulate(scn)
    wall = time.perf_counter() - start
    return result, float(result.tables["truth_shearer"]["t"][-1]), wall


def stage_sensors(scn, tables) -> tuple[dict, int, float]:
    """Ideal IMU increments and every stream of trial 0: (streams, IMU samples, wall seconds)."""
    from twin.sensors.streams import imu_truth, sensor_streams

    start = time.perf_counter()
    ideal = imu_truth(scn, tables["truth_shearer"])
    streams = sensor_streams(scn, tables, ideal, 0)
    wall = time.perf_counter() - start
    return streams, int(np.asarray(streams["imu"]["t"]).size), wall


def imu_arrays(imu: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t (with a leading epoch before the first increment), dtheta, dv (zero first row) of an imu stream."""
    t = np.asarray(imu["t"], float)
    dtheta = np.column_stack([np.asarray(imu[f"dtheta_{a}"], float) for a in "xyz"])
    dv = np.column_stack([np.asarray(imu[f"dv_{a}"], float) for a in "xyz"])
    dt = float(np.median(np.diff(t)))
    zero = np.zeros((1, 3))
    return np.concatenate([[t[0] - dt], t]), np.concatenate([zero, dtheta]), np.concatenate([zero, dv])


def head(log, seconds: float):
    """The first `seconds` of a positioning log (every timed stream cut at imu_t[0] + seconds)."""
    from estimators.io.log import ImuArrays

    t, dtheta, dv = log.imu.read(0, log.imu.size)
    t_end = t[0] + seconds
    keep = t <= t_end
    cut = {"imu": ImuArrays(t[keep], dtheta[keep], dv[keep])}
    for stamp, names in (("odo_t", ("odo_t", "odo_distance", "odo_direction")),
                         ("ram_t", ("ram_t", "ram_support", "ram_extension", "ram_valid")),
                         ("mag_t", ("mag_t", "mag_b"))):
        keep = getattr(log, stamp) <= t_end
        cut.update({n: getattr(log, n)[keep] for n in names})
    return dataclasses.replace(log, **cut)


def pyins_feedback_time(log, cfg, seconds: float) -> tuple[int, float]:
    """pyins's feedback EKF (run_feedback_filter) on the first `seconds` of the log: IMU increments at the log's
    rate, an odometer body velocity (along the machine, zero across and up: the same constraint our filter uses)
    every 0.1 s, covariance propagation every 0.1 s (our filter rate), gyro and accelerometer bias states from the
    same noise budget. Frames turned into pyins's (NED, body forward-right-down). Returns (IMU samples, wall s)."""
    import pandas as pd
    from pyins import filters, inertial_sensor, measurements, strapdown

    part = head(log, seconds)
    t, dtheta, dv = imu_arrays({"t": part.imu_t, **{f"dtheta_{a}": part.dtheta[:, i] for i, a in enumerate("xyz")},
                                **{f"dv_{a}": part.dv[:, i] for i, a in enumerate("xyz")}})
    to_frd = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])  # ours: x right, y forward, z up
    imu = pd.DataFrame(np.hstack([dtheta @ to_frd.T, dv @ to_frd.T]), index=t,
                       columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    t_meas = np.arange(t[1], t[-1], 1.0 / cfg.filter_rate_hz)[1:]
    dist = np.interp(t_meas, part.odo_t, part.odo_distance)
    speed = np.gradient(dist, t_meas)
    odo = pd.DataFrame({"VX": speed, "VY": 0.0, "VZ": 0.0}, index=t_meas)
    lat, lon, h = part.survey_llh[0]
    heading = -np.degrees(part.survey_yaw[0]) % 360.0  # yaw is counter-clockwise from north
    pva = pd.Series({"lat": np.degrees(lat), "lon": np.degrees(lon), "alt": h, "VN": 0.0, "VE": 0.0, "VD": 0.0,
                     "roll": 0.0, "pitch": 0.0, "heading": heading}, name=t[0])

    def run(imu, odo):
        gyro = inertial_sensor.EstimationModel(bias_sd=cfg.imu.gyro_bias, noise=cfg.imu.gyro_arw)
        accel = inertial_sensor.EstimationModel(bias_sd=cfg.imu.accel_bias, noise=cfg.imu.accel_vrw)
        inc = strapdown.compute_increments_from_imu(imu, "increment")
        filters.run_feedback_filter(pva, 1.0, 0.01, 0.3, 1.0, inc, gyro, accel,
                                    [measurements.BodyVelocity(odo, 0.02)], time_step=1.0 / cfg.filter_rate_hz)

    run(imu.iloc[:400], odo.iloc[:15])  # pyins's numba kernels compile outside the timing
    start = time.perf_counter()
    run(imu, odo)
    return t.size - 1, time.perf_counter() - start


def stage_filter(scn, streams, pyins_seconds: float, have_pyins: bool) -> dict:
    from bench_positioning import log_of

    from estimators.shearer.methods import estimate
    from twin.pipeline.estimate import positioning_config

    log = log_of(streams)
    cfg = positioning_config(scn)
    out: dict = {"samples": int(log.imu.size), "hours": float(log.imu_t[-1] - log.imu_t[0]) / 3600}
    try:  # compile (numba's cache) outside the timing, on the first two minutes
        estimate(head(log, 120.0), cfg, ("kf_cpoem_rts",))
        out["warm"] = True
    except Exception as err:  # noqa: BLE001 - a warm-up that cannot run leaves the compile inside the timing
        out["warm"] = f"warm-up failed ({type(err).__name__}: {err}); compile time included"
    start = time.perf_counter()
    estimate(log, cfg, ("kf_cpoem_rts",))
    out["wall"] = time.perf_counter() - start
    if have_pyins:
        secs = min(pyins_seconds, float(log.imu_t[-1] - log.imu_t[0])) if pyins_seconds > 0 else np.inf
        try:
            out["pyins_samples"], out["pyins_wall"] = pyins_feedback_time(log, cfg, secs)
        except Exception as err:  # noqa: BLE001 - the peer's failure is reported in the table
            out["pyins_error"] = f"failed: {type(err).__name__}: {err}"
    return out


def stage_strapdown(streams, have_pyins: bool) -> dict:
    from bench_strapdown import ours, pyins_time

    t, dtheta, dv = imu_arrays(streams["imu"])
    out = {"samples": int(t.size - 1), "ours": ours(t, dtheta, dv)}  # ours() compiles before its timing
    if have_pyins:
        try:
            pyins_time(t[:1000], dtheta[:1000], dv[:1000])  # pyins's numba integrator compiles outside the timing
            out["pyins"] = pyins_time(t, dtheta, dv)
        except Exception as err:  # noqa: BLE001
            out["pyins_error"] = f"failed: {type(err).__name__}: {err}"
    return out


def _best(fn: Callable, repeats: int) -> float:
    walls = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - start)
    return min(walls)


def stage_support(seconds: float, ahrs_supports: int, ahrs_seconds: float, have_ahrs: bool) -> dict:
    import numba
    from bench_support_attitude import RATE_HZ, SUPPORTS, face_readings

    from estimators.support.error_state import ours
    from estimators.support.filters_002 import ukf
    from twin.pipeline.support_estimate import UNTUNED_VAR_DEG2_S2

    w, f, m, model, settings = face_readings(seconds, np.random.default_rng(0))
    dt = 1.0 / RATE_HZ
    var = np.full(3, np.radians(np.sqrt(UNTUNED_VAR_DEG2_S2)) ** 2)
    out = {"supports": SUPPORTS, "rate": RATE_HZ, "samples": int(w.shape[0] * w.shape[1]), "seconds": seconds,
           "threads": numba.get_num_threads()}
    runs = {"ukf": lambda a, b, c: ukf(a, b, c, dt, model, var),
            "ours": lambda a, b, c: ours(a, b, c, dt, model, settings)}
    for name, run in runs.items():
        run(w[:2, :200], f[:2, :200], m[:2, :200])  # compile outside the timing
        out[name] = _best(lambda run=run: run(w, f, m), 2)
    if have_ahrs:
        from ahrs.filters import UKF

        k = min(int(ahrs_seconds * RATE_HZ), w.shape[1])
        n = min(ahrs_supports, w.shape[0])
        try:
            start = time.perf_counter()
            for i in range(n):  # the package's batch mode: one filter per support over its readings
                UKF(gyr=w[i, :k], acc=f[i, :k], mag=m[i, :k] * 1e6, frequency=RATE_HZ)  # mag in uT (normalized)
            out["ahrs"] = time.perf_counter() - start
            out["ahrs_samples"] = n * k
        except Exception as err:  # noqa: BLE001
            out["ahrs_error"] = f"failed: {type(err).__name__}: {err}"
    return out


# ------------------------------------------------------------------------------------------------------------
# The run


def missing(dist: str) -> str:
    return f"not installed ({INSTALL_HINT} or pip install {dist})"


def main(argv: Sequence[str] | None = None) -> list[Row]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "bench" / "speed.md",
                        help="Markdown path; the CSV goes beside it (default runs/bench/speed.md)")
    parser.add_argument("--quick", action="store_true", help="scenarios/default.toml instead of seed004 (development)")
    parser.add_argument("--scenario", type=Path, default=None, help="any scenario instead (overrides --quick)")
    parser.add_argument("--pyins-seconds", type=float, default=60.0,
                        help="log length pyins's feedback filter runs on [s] (0: all; it runs ~10^2 samples/s)")
    parser.add_argument("--support-seconds", type=float, default=60.0, help="support readings per unit [s]")
    parser.add_argument("--ahrs-supports", type=int, default=3, help="supports the ahrs UKF runs on")
    parser.add_argument("--ahrs-seconds", type=float, default=10.0, help="readings per support for the ahrs UKF [s]")
    args = parser.parse_args(argv)

    from twin.config.scenario import load_scenario

    path = args.scenario or ROOT / "scenarios" / ("default.toml" if args.quick else "seed004.toml")
    scn = load_scenario(path)
    pyins_v = peer_version("python-ins", "pyins")
    ahrs_v = peer_version("ahrs", "ahrs")
    pyins_name = f"pyins {pyins_v}" if pyins_v else "pyins (python-ins)"
    ahrs_name = f"ahrs {ahrs_v}" if ahrs_v else "ahrs"
    for name, v in (("python-ins (pyins)", pyins_v), ("ahrs", ahrs_v)):
        if v is None:
            print(f"peer {name} is not installed: its ratios are skipped ({INSTALL_HINT})", file=sys.stderr)
    mem = Memory()
    rows: list[Row] = []

    def say(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    say(f"simulating {path.name} ...")
    result, sim_s, wall = mem.measure("twin", stage_twin, scn)
    rows.append(Row("twin real-time factor", "x", sim_s / wall, target=">= 400x (issue 2)", target_min=400.0,
                    note=f"{path.name}: {sim_s / 3600:.2f} h simulated in {wall:.1f} s (twin.pipeline.simulate.simulate; "
                         "bench_twin.py adds the Parquet and Rerun writing)"))

    say("sensor streams ...")
    streams, n_imu, wall = mem.measure("sensors", stage_sensors, scn, result.tables)
    rows.append(Row("sensor streams, IMU samples/s", "/s", n_imu / wall, target=">= 1,000,000/s (issue 24; issue 3: 500,000)",
                    target_min=TARGET_SENSORS,
                    note=f"ideal increments + every stream of trial 0: {n_imu:,} IMU samples in {wall:.2f} s"))

    say("strapdown ...")
    sd = mem.measure("strapdown", stage_strapdown, streams, pyins_v is not None)
    n = sd["samples"]
    rows.append(Row("strapdown mechanization, IMU samples/s", "/s", n / sd["ours"], pyins_name,
                    n / sd["pyins"] if "pyins" in sd else None,
                    sd.get("pyins_error", "") if pyins_v else missing("python-ins"),
                    ">= 5,000,000/s (issue 24; issue 4: 1,000,000)", TARGET_STRAPDOWN,
                    note=f"{n:,} increments of {scn.name}'s IMU stream; ours: estimators.sins.strapdown.mechanize, "
                         "4-sample coning/sculling; pyins: compute_increments_from_imu (2-sample) + Integrator"))

    say("filter + smoother ...")
    fl = mem.measure("filter", stage_filter, scn, streams, args.pyins_seconds, pyins_v is not None)
    ours_fs = fl["samples"] / fl["wall"]
    peer_fs = fl["pyins_samples"] / fl["pyins_wall"] if "pyins_wall" in fl else None
    note = (f"ours: KF + CPOEM + online RTS (estimate kf_cpoem_rts) on all {fl['samples']:,} samples "
            f"({fl['hours']:.2f} h) in {fl['wall']:.1f} s")
    if fl["warm"] is not True:
        note += f", {fl['warm']}"
    if peer_fs is not None:
        note += (f"; pyins: run_feedback_filter (EKF, 15 states: 9 navigation + gyro and accel biases; pyins has no "
                 f"smoother) with body velocity from the odometer at 10 Hz, on the first {fl['pyins_samples']:,} "
                 f"samples of the same log in {fl['pyins_wall']:.1f} s")
    rows.append(Row("filter + smoother, IMU samples/s", "/s", ours_fs, pyins_name, peer_fs,
                    fl.get("pyins_error", "") if pyins_v else missing("python-ins"),
                    ">= 500,000/s (issue 24; issue 5: 100,000)", TARGET_FILTER, note=note))
    del streams, result

    say("support attitude ...")
    try:
        su = mem.measure("support", stage_support, args.support_seconds, args.ahrs_supports, args.ahrs_seconds,
                         ahrs_v is not None)
    except Exception as err:  # noqa: BLE001 - the support modules are someone else's; report, don't crash
        su = None
        rows.append(Row("support attitude", "/s", None, note=f"failed: {type(err).__name__}: {err}"))
    if su is not None:
        real = su["supports"] * su["rate"]
        peer_ss = su["ahrs_samples"] / su["ahrs"] if "ahrs" in su else None
        ahrs_miss = su.get("ahrs_error", "") if ahrs_v else missing("ahrs")
        ahrs_note = (f"; ahrs: ahrs.filters.UKF (accel + mag, 4-state quaternion) on {su['ahrs_samples']:,} "
                     f"support-samples of the same readings" if peer_ss else "")
        for key, label, target, tmin in (
                ("ukf", "support UKF (002), support-samples/s", "", None),
                ("ours", "support attitude (ours), support-samples/s",
                 f">= {TARGET_SUPPORT_RTF * real:,.0f}/s = 100x real time (issue 8)", TARGET_SUPPORT_RTF * real)):
            rate = su["samples"] / su[key]
            rows.append(Row(label, "/s", rate, ahrs_name, peer_ss, ahrs_miss, target, tmin,
                            note=f"{su['supports']} supports at {su['rate']:g} Hz, {su['seconds']:g} s: "
                                 f"{rate / real:,.0f}x real time on {su['threads']} numba threads" + ahrs_note))

    for stage, gb in mem.stages.items():
        tgt = ("<= 4 GB (issue 2)", 4.0) if stage == "twin" else ("", None)
        rows.append(Row(f"peak memory, {stage} stage", "GB", gb, target=tgt[0], target_max=tgt[1],
                        note="" if mem.reset_ok else "process ru_maxrss so far (the high-water mark could not "
                                                     "be reset)"))
    rows.append(Row("peak memory, whole run", "GB", mem.overall_gb(), note="largest stage peak (ru_maxrss)"))

    title = f"Speed table, {scn.name}"
    print(title)
    print(format_text(rows))
    md, csv_path = write_table(rows, args.out, title)
    print(f"\nwritten: {md}, {csv_path}")
    return rows


if __name__ == "__main__":
    main()
