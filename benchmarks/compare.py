"""The comparison table of issue 9: each paper's headline figures beside ours, with the issues' targets.

Runs the paper-reproduction benchmarks' figure functions (their own code, imported: no benchmark logic here)
and builds one table, printed and written as Markdown and CSV (DIR/compare.md, DIR/compare.csv):

  paper, table/section, figure, paper's value, ours, target, met

"ours" is the Monte Carlo mean +- sd over N trials (sensor errors redrawn from one simulation; for 000's
alignment, N IMU error draws; for 002's turntable, N seeds) or the single value where the benchmark has no
trials (000's coning, sculling and lever-arm experiments are deterministic; 001's Par 1-12 sweep, 004's
detectors and INS/odometer column are trial 0). "met" compares the mean with the target (yes / no), "-" where
the issue sets none. A benchmark that fails gives its rows with "failed: <reason>" and the table goes on.

Sources (benchmark: rows):
  000  twin.papers.sins_experiments.run_shipped (bench_coning_sculling.py, bench_lever_arm.py): sections 7.2, 7.4, Tables 2-3
       bench_alignment.main: Table 1, both IMU grades, seeds 0..N-1
       bench_strapdown.schuler: 24 h stationary against the linear error model (Schuler, issue 4; no paper figure)
  001  bench_positioning_mc.main: Table 3 SEP per cycle (KF + CPOEM + RTS), N trials
       bench_positioning.figures: the Table 2 sweep (Par 1-12), worst cycle
  002  bench_support_attitude.turntable: section 4.1 turntable RMSE, GD-UKF and ours, N seeds
  003  bench_federated.run_trials + summary: Table 2 maximum errors, improvement, interference case, N trials
  004  bench_rail.figures: Table 2 RMSE per cycle (N fault-free trials), detectors on seed004_fault, false alarms

The speed table of issue 9 (benchmarks/bench_speed.py) follows in the same run, written as DIR/speed.md and .csv,
unless --no-speed.

Run: python benchmarks/compare.py [--trials N] [--only PAPER,...] [--out DIR] [--no-speed] [--verbose]
     (the whole table with the default 20 trials takes about an hour on a 2-core machine, 004 most of it: 6.5 min
     with 1 trial; --only 000 --trials 2 takes under a minute, --only 002,003 --trials 2 about 1.5 min)
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

if str(Path(__file__).resolve().parent) not in sys.path:
    sys.path.insert(0, str(Path(__file__).resolve().parent))  # the sibling benchmarks, when imported from tests

from tables import markdown_table, text_table  # a sibling: after the path above

PAPERS = ("000", "001", "002", "003", "004")
COLUMNS = ["paper", "table/section", "figure", "paper's value", "ours", "target", "met"]

# ------------------------------------------------------------------------------------------------------------
# Rows: specification and the built table


@dataclass
class Failed:
    """A source (benchmark) that raised: its rows say so."""

    reason: str


Check = Callable[[np.ndarray, object], bool]
"""met: the row's values (one per trial, or one) and the source's figures -> bool."""


@dataclass
class RowSpec:
    paper: str
    section: str
    figure: str
    paper_value: str
    source: str
    get: Callable[[object], object]  # the source's figures -> a value or one value per trial
    target: str = "-"
    check: Check | None = None
    fmt: str = ".3f"


@dataclass
class Row:
    paper: str
    section: str
    figure: str
    paper_value: str
    ours: str
    target: str
    met: str
    mean: float | None = None
    sd: float | None = None
    n: int = 0

    def cells(self) -> list[str]:
        return [self.paper, self.section, self.figure, self.paper_value, self.ours, self.target, self.met]


def one_line(exc: BaseException) -> str:
    text = f"{type(exc).__name__}: {exc}".strip()
    return text.splitlines()[0] if text else type(exc).__name__


def at_most(limit: float) -> Check:
    return lambda v, _figs: bool(np.nanmean(v) <= limit)


def at_least(limit: float) -> Check:
    return lambda v, _figs: bool(np.nanmean(v) >= limit)


def fmt_ours(values: np.ndarray, fmt: str) -> str:
    """One value as is; several as mean +- sd (population sd, nan-aware; the count of finite values if some are
    not)."""
    if values.size == 1:
        return f"{values[0]:{fmt}}"
    finite = np.isfinite(values)
    if not finite.any():
        return "nan"
    text = f"{np.nanmean(values):{fmt}} ± {np.nanstd(values):{fmt}}"
    return text if finite.all() else f"{text} ({int(finite.sum())}/{values.size} finite)"


def build_row(spec: RowSpec, figs: object) -> Row:
    base = {"paper": spec.paper, "section": spec.section, "figure": spec.figure, "paper_value": spec.paper_value,
            "target": spec.target}
    if isinstance(figs, Failed):
        return Row(**base, ours=f"failed: {figs.reason}", met="-")
    try:
        values = np.atleast_1d(np.asarray(spec.get(figs), dtype=float)).ravel()
        if values.size == 0:
            raise ValueError("no values (no trials)")
        met = "-" if spec.check is None else ("yes" if spec.check(values, figs) else "no")
        mean = float(np.nanmean(values)) if np.isfinite(values).any() else math.nan
        sd = float(np.nanstd(values)) if values.size > 1 and np.isfinite(values).any() else None
        return Row(**base, ours=fmt_ours(values, spec.fmt), met=met, mean=mean, sd=sd, n=int(values.size))
    except Exception as exc:  # noqa: BLE001 -- a row that cannot be read says why, the table goes on
        return Row(**base, ours=f"failed: {one_line(exc)}", met="-")


def build_table(specs: Sequence[RowSpec], figures: dict[str, object]) -> list[Row]:
    """Rows of the sources present in `figures` (source -> figures or Failed), in the order of `specs`."""
    return [build_row(s, figures[s.source]) for s in specs if s.source in figures]


def markdown(rows: Sequence[Row], title: str, notes: Sequence[str] = ()) -> str:
    return markdown_table(title, [COLUMNS, *(r.cells() for r in rows)], notes)


def write_table(rows: Sequence[Row], out_dir: Path, title: str, notes: Sequence[str] = ()) -> tuple[Path, Path]:
    """DIR/compare.md and DIR/compare.csv (the CSV adds the mean, sd and number of values of ours)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    md, csv_path = out_dir / "compare.md", out_dir / "compare.csv"
    md.write_text(markdown(rows, title, notes), encoding="utf-8")
    with csv_path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow([*COLUMNS, "ours_mean", "ours_sd", "ours_n"])
        for r in rows:
            w.writerow([*r.cells(), "" if r.mean is None else f"{r.mean:.6g}", "" if r.sd is None else f"{r.sd:.6g}",
                        r.n])
    return md, csv_path


def format_text(rows: Sequence[Row]) -> str:
    return text_table([COLUMNS, *(r.cells() for r in rows)])


# ------------------------------------------------------------------------------------------------------------
# Sources: each runs one benchmark's figure function (its printout captured) and returns its figures


def src_000_experiments(trials: int) -> dict:
    from twin.papers.sins_experiments import run_shipped

    return {name: run_shipped(name).ours for name in ("seed000_coning", "seed000_sculling", "seed000_lever_arm")}


def src_000_alignment(trials: int) -> list[dict]:
    import bench_alignment

    return [bench_alignment.main(seed) for seed in range(trials)]


def src_000_schuler(trials: int) -> dict:
    import bench_strapdown

    return bench_strapdown.schuler()


def src_001_mc(trials: int) -> dict:
    import bench_positioning_mc

    return bench_positioning_mc.main(trials, ("kf_cpoem_rts",))


def src_001_sweep(trials: int) -> dict:
    import bench_positioning

    return bench_positioning.figures(sweep=True)


def src_002_turntable(trials: int) -> dict:
    import bench_support_attitude

    return bench_support_attitude.turntable(trials)


def src_003_federated(trials: int) -> dict:
    import bench_federated

    results = {name: bench_federated.run_trials(name, trials) for name in bench_federated.PAPER}
    return {"results": results, "summary": bench_federated.summary(results)}


def src_004_rail(trials: int) -> dict:
    import bench_rail

    return bench_rail.figures(trials)


SOURCES: dict[str, tuple[str, Callable[[int], object]]] = {
    "000 experiments": ("000", src_000_experiments),
    "000 alignment": ("000", src_000_alignment),
    "000 schuler": ("000", src_000_schuler),
    "001 monte carlo": ("001", src_001_mc),
    "001 sweep": ("001", src_001_sweep),
    "002 turntable": ("002", src_002_turntable),
    "003 federated": ("003", src_003_federated),
    "004 rail": ("004", src_004_rail),
}


# ------------------------------------------------------------------------------------------------------------
# The rows of each paper (the papers' figures are the benchmarks' constants)


def _rows_000() -> list[RowSpec]:
    from twin.papers.alignment import PAPER_TABLE1
    from twin.papers.coning_sculling import PAPER_CONING, PAPER_SCULLING
    from twin.papers.lever_arm import PAPER_LEVER_ARM

    src = "000 experiments"
    rows = [
        RowSpec("000", "7.2 coning", "largest coning error, reduction by 3-sample compensation [%]",
                f"{max(PAPER_CONING['reduction_pct']):.1f}", src, lambda f: f["seed000_coning"]["reduction_pct"],
                ">= 99 % (issue 4)", at_least(99.0), ".2f"),
        RowSpec("000", "7.2 coning", "attitude drift after 40 s, reduction [%]", "-", src,
                lambda f: f["seed000_coning"]["drift_reduction_pct"], ">= 99 % (issue 4)", at_least(99.0), ".2f"),
        RowSpec("000", "7.4 sculling", "largest velocity error (Y), reduction by compensation [%]",
                f"{PAPER_SCULLING['reduction_pct'][1]:.1f}", src, lambda f: f["seed000_sculling"]["reduction_pct"],
                ">= 99 % (issue 4)", at_least(99.0), ".2f"),
    ]
    for ref in PAPER_LEVER_ARM.values():
        group = f"table{ref['table']}"
        for i, axis in enumerate("ENU"):
            paper = ref["reduction_pct"][i]
            rows.append(RowSpec(
                "000", f"Table {ref['table']} lever arm", f"max attitude error {axis}, reduction [%]", f"{paper:.1f}",
                src, lambda f, g=group, i=i: f["seed000_lever_arm"][g]["reduction_pct"][i],
                ">= paper (issue 4)", at_least(paper), ".1f"))
    import bench_alignment

    src = "000 alignment"
    for grade in bench_alignment.SECONDS:
        for m in bench_alignment.METHODS:
            label = f"{bench_alignment.NAMES[m]} {{}}, {grade} {bench_alignment.SECONDS[grade]:.0f} s"
            for i, angle in enumerate(("phi_E", "phi_N", "phi_U")):
                # The level errors are the biases' (a draw's floor), not the filter's: the target is on the
                # deviation from the floor, its own row below; the heading's target is per draw.
                target, check = "-", None
                if i == 2:
                    target = ("within 10 % of the gyrocompassing floor (+ 3 ARW sigma) (issue 4)" if grade == "nav-004"
                              else "start error kept (MEMS cannot gyrocompass)")
                    check = (lambda _v, f, g=grade, m=m: all(d[g][m]["heading_ok"] for d in f))
                rows.append(RowSpec(
                    "000", "Table 1 (units not stated)", label.format(f"{angle} [deg]"),
                    f"{PAPER_TABLE1[m]['error'][i]:g}", src,
                    lambda f, g=grade, m=m, i=i: [d[g][m]["phi_deg"][i] for d in f], target, check, ".4f"))
            rows.append(RowSpec(
                "000", "Table 1 (issue 4 floor)", label.format("level deviation from the draw's floor [%]"),
                "-", src, lambda f, g=grade, m=m: [100 * d[g][m]["level_dev"] for d in f],
                "<= 10 % (issue 4; mean over draws)", at_most(10.0), ".1f"))
    for key, what in (("north_pct", "north position"), ("east_pct", "east position"), ("attitude_pct", "attitude")):
        rows.append(RowSpec(
            "000", "Schuler, 24 h stationary (issue 4)", f"{what} error vs linear error model, largest deviation [%]",
            "- (no figure in 000)", "000 schuler", lambda f, k=key: f[k], "<= 5 % (issue 4)", at_most(5.0), ".2f"))
    return rows


def _rows_001() -> list[RowSpec]:
    import bench_positioning

    paper = bench_positioning.TABLE3["proposed (KF + CPOEM + RTS)"]
    rows = [RowSpec("001", "Table 3", f"SEP cycle A{k + 1} [m], KF + CPOEM + RTS", f"{paper[k]:.2f}",
                    "001 monte carlo", lambda f, k=k: f["sep"]["kf_cpoem_rts"][:, k],
                    "<= paper, aim <= 0.10 m (issue 5)", at_most(paper[k])) for k in range(4)]
    rows.append(RowSpec("001", "Table 2 sweep (Par 1-12)", "worst cycle SEP over Par 1-12 [m], KF + CPOEM + RTS, "
                        "trial 0", "- (Figures 14-15 only)", "001 sweep",
                        lambda f: max(max(v) for v in f["sweep"].values())))
    return rows


def _rows_002() -> list[RowSpec]:
    from twin.papers.turntable import PAPER, TARGETS

    rows = []
    for name, label in (("gd_ukf", "002 GD-UKF"), ("ours", "ours")):
        for seg, key in (("dynamic", "dynamic_deg"), ("static", "static_deg")):
            for a in ("pitch", "roll"):
                rows.append(RowSpec(
                    "002", "4.2 turntable", f"{label}: {a} RMSE, {seg} [deg]", f"< {PAPER[f'gd_ukf_{key}'][a]:g}",
                    "002 turntable", lambda f, n=name, s=seg, a=a: [m[n][s][a] for m in f["metrics"]],
                    f"<= {TARGETS[key]:g} deg (issue 8)" if name == "ours" else "-",
                    at_most(TARGETS[key]) if name == "ours" else None))
        rows.append(RowSpec(
            "002", "4.2 turntable / 5 (yaw)", f"{label}: yaw max error with the shearer's field [deg]",
            f"< {PAPER['gd_ukf_yaw_disturbed_deg']:g}", "002 turntable",
            lambda f, n=name: [m[n]["max"]["yaw"] for m in f["metrics"]],
            f"<= {TARGETS['yaw_deg']:g} deg (issue 8)" if name == "ours" else "-",
            at_most(TARGETS["yaw_deg"]) if name == "ours" else None))
    return rows


def _rows_003() -> list[RowSpec]:
    import bench_federated

    paper, src = bench_federated.PAPER, "003 federated"

    def res(f, scn, m, col):
        return f["results"][scn][0][m][:, col]

    und, dis = paper["seed003"], paper["seed003_interference"]
    rows = []
    for i, axis in enumerate("EN"):
        rows.append(RowSpec("003", "Table 2", f"SINS/OD max {axis} error [m]", f"{und['kf'][i]:.4f}", src,
                            lambda f, i=i: res(f, "seed003", "kf", i)))
    for i, axis in enumerate("EN"):
        rows.append(RowSpec("003", "Table 2", f"AFKF (SINS/OD/MAG) max {axis} error [m]", f"{und['afkf'][i]:.4f}",
                            src, lambda f, i=i: res(f, "seed003", "afkf", i),
                            f"<= {und['afkf'][i]:.2f} m, aim <= 0.10 m (issue 6)", at_most(und["afkf"][i])))
    for i, (axis, p) in enumerate((("E", 75.64), ("N", 74.01))):
        rows.append(RowSpec("003", "Table 2", f"AFKF improvement over SINS/OD, max {axis} error [%]", f"{p:.2f}", src,
                            lambda f, i=i: 100 * f["summary"]["gain"][:, i], ">= 75 % (issue 6)", at_least(75.0),
                            ".1f"))
    rows += [
        RowSpec("003", "5.2 interference", "CKF max E error [m]", f"{dis['ckf_mag'][0]:.4f}", src,
                lambda f: res(f, "seed003_interference", "ckf_mag", 0)),
        RowSpec("003", "5.2 interference", "AFKF max E error [m]", f"{dis['afkf'][0]:.4f}", src,
                lambda f: res(f, "seed003_interference", "afkf", 0)),
        RowSpec("003", "5.2 interference", "AFKF max horizontal error [m]", f"{dis['afkf'][0]:.2f} (E)", src,
                lambda f: res(f, "seed003_interference", "afkf", 2), "<= 1.5 m, aim <= 0.3 m (issue 6)",
                at_most(1.5)),
        RowSpec("003", "5.2 interference", "CKF / AFKF max horizontal error",
                f"{dis['ckf_mag'][0] / dis['afkf'][0]:.2f} (E)", src, lambda f: f["summary"]["ratio"],
                ">= 3 (issue 6)", at_least(3.0), ".2f"),
    ]
    return rows


def _rows_004() -> list[RowSpec]:
    import bench_rail

    src, rows = "004 rail", []
    for k in range(5):
        for i, axis in enumerate("EN"):
            paper = bench_rail.TABLE2["fkf_rail"][i][k]
            rows.append(RowSpec(
                "004", "Table 2, assisted by model", f"cycle {k + 1} RMSE {axis} [m], fault-free trials",
                f"{paper:.3f}", src, lambda f, k=k, i=i: f["mc_rmse"][:, k, i],
                "<= paper, aim <= 0.10 m (issue 7)", at_most(paper)))
    for k in range(5):
        for i, axis in enumerate("EN"):
            rows.append(RowSpec("004", "Table 2, INS/ODO", f"cycle {k + 1} RMSE {axis} [m], trial 0",
                                f"{bench_rail.TABLE2['kf'][i][k]:.3f}", src, lambda f, k=k, i=i: f["rmse"]["kf"][k, i]))
    labels = {"residual": "residual chi-square", "dual_state": "dual-state chi-square", "fsprt": "fading SPRT"}
    for name, label in labels.items():
        fsprt = name == "fsprt"
        rows += [
            RowSpec("004", "V.A detectors (seed004_fault)", f"{label}: detection delay [s]", "- (figures only)", src,
                    lambda f, n=name: f["detectors"][n]["delay"], "<= 60 s (issue 7)" if fsprt else "-",
                    at_most(60.0) if fsprt else None, ".1f"),
            RowSpec("004", "V.A detectors (seed004_fault)", f"{label}: fault fixes missed", "- (figures only)", src,
                    lambda f, n=name: f["detectors"][n]["missed"], fmt=".0f"),
            RowSpec("004", "V.A detectors (seed004_fault)", f"{label}: false alarms per hour", "- (figures only)",
                    src, lambda f, n=name: f["detectors"][n]["false_per_h"], fmt=".2f"),
            RowSpec("004", "V.A detectors (seed004_fault)", f"{label}: max horizontal error in the fault [m]",
                    "- (figures only)", src, lambda f, n=name: f["detectors"][n]["error_in_fault"],
                    "<= fault-free + 0.05 m (issue 7)" if fsprt else "-",
                    (lambda v, f: bool(v[0] <= f["clean_error_in_fault"] + 0.05)) if fsprt else None),
        ]
    rows.append(RowSpec(
        "004", "V.A detectors (seed004_fault)", "fading SPRT: clearing delay after the fault [s]", "- (figures only)",
        src, lambda f: f["detectors"]["fsprt"]["clear"], "<= 60 s (issue 7)", at_most(60.0), ".1f"))
    rows.append(RowSpec("004", "fault-free Monte Carlo", "fading SPRT false alarms per trial", "-", src,
                        lambda f: f["alarms"], "0 over >= 20 trials (issue 7)",
                        lambda v, _f: bool(np.all(v == 0)), ".2f"))
    return rows


def _unbuildable(paper: str, exc: Exception) -> RowSpec:
    """A paper whose rows cannot be built (a benchmark module that does not import): one row saying why."""
    source = next(name for name, (p, _) in SOURCES.items() if p == paper)
    reason = one_line(exc)

    def fail(_figs):
        raise RuntimeError(f"rows not built: {reason}")

    return RowSpec(paper, "-", "all rows of this paper", "-", source, fail)


def row_specs() -> list[RowSpec]:
    out = []
    for paper, build in zip(PAPERS, (_rows_000, _rows_001, _rows_002, _rows_003, _rows_004)):
        try:
            out += build()
        except Exception as exc:  # noqa: BLE001 -- the other papers' rows still come
            out.append(_unbuildable(paper, exc))
    return out


# ------------------------------------------------------------------------------------------------------------
# Running


def run_sources(papers: Sequence[str], trials: int, verbose: bool = False) -> tuple[dict[str, object], dict]:
    """Figures per source of the chosen papers (Failed for a source that raised) and each source's wall time."""
    figures, seconds = {}, {}
    for name, (paper, fn) in SOURCES.items():
        if paper not in papers:
            continue
        print(f"running {name} ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        buf = io.StringIO()
        try:
            with contextlib.redirect_stdout(sys.stderr if verbose else buf):
                figures[name] = fn(trials)
        except Exception as exc:  # noqa: BLE001 -- a failing benchmark gives failed rows, not a stopped table
            figures[name] = Failed(one_line(exc))
        seconds[name] = time.perf_counter() - start
        state = f"failed ({figures[name].reason})" if isinstance(figures[name], Failed) else "done"
        print(f"  {name}: {state}, {seconds[name]:.1f} s", file=sys.stderr, flush=True)
    return figures, seconds


def main(argv: Sequence[str] | None = None) -> list[Row]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20, help="Monte Carlo trials (seeds) per benchmark (20)")
    parser.add_argument("--only", default=",".join(PAPERS), help="papers, comma-separated (000,001,002,003,004)")
    parser.add_argument("--out", type=Path, default=Path("runs/bench"), help="directory of compare.md and .csv")
    parser.add_argument("--verbose", action="store_true", help="show the benchmarks' own printout (on stderr)")
    parser.add_argument("--no-speed", action="store_true",
                        help="skip the speed table (bench_speed.py on seed004, about 5 min) that follows the comparison")
    args = parser.parse_args(argv)
    papers = [p.strip() for p in args.only.split(",") if p.strip()]
    unknown = [p for p in papers if p not in PAPERS]
    if unknown or args.trials < 1:
        parser.error(f"unknown paper {', '.join(unknown)} (choose from {', '.join(PAPERS)})" if unknown
                     else "--trials must be >= 1")
    start = time.perf_counter()
    figures, seconds = run_sources(papers, args.trials, args.verbose)
    rows = build_table(row_specs(), figures)
    title = f"Papers' figures beside ours ({args.trials} trials)"
    notes = [(f"ours: Monte Carlo mean ± sd over {args.trials} trials, or the single value where a figure has no "
              "trials; met: the mean against the issue's target."),
             "run times: " + ", ".join(f"{k} {v:.0f} s" for k, v in seconds.items())
             + f"; total {time.perf_counter() - start:.0f} s"]
    print(f"\n{title}\n{notes[0]}\n{notes[1]}\n")
    print(format_text(rows))
    md, csv_path = write_table(rows, args.out, title, notes)
    print(f"\nwritten: {md}, {csv_path}")
    if not args.no_speed:
        run_speed_table(args.out)
    return rows


def run_speed_table(out: Path) -> None:
    """The speed table of the same run (benchmarks/bench_speed.py), written beside the comparison as speed.md/.csv."""
    import bench_speed  # a sibling benchmark: imported only when the speed table is asked for

    print("\nrunning the speed table (bench_speed.py, seed004) ...", file=sys.stderr, flush=True)
    try:
        bench_speed.main(["--out", str(out / "speed.md")])
    except Exception as exc:  # noqa: BLE001 -- the comparison above stands without it
        print(f"speed table failed: {one_line(exc)}")


if __name__ == "__main__":
    main()
