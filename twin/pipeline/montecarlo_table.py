"""The Monte Carlo trials' metrics gathered: `trials.parquet` (and `.csv`), one row per trial and method, the
"monte_carlo" section of metrics.json and its printed table."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

from twin.pipeline.montecarlo import TrialResult

WINDOW_KEYS = frozenset({"cycle", "t_start", "t_end", "samples"})
"""Keys of run_estimators' per-cycle entries that describe the window, not the error: not tabulated."""
HEADLINE = (("all.sep", "SEP"), ("all.rmse_e", "RMSE E"), ("all.rmse_n", "RMSE N"), ("all.rmse_u", "RMSE U"),
            ("all.max_horizontal", "max horiz."))
"""Whole-run metrics (flattened names) and their headings in the printed Monte Carlo table."""


def flatten_metrics(entry: dict) -> dict[str, float]:
    """One method's run_estimators entry as scalar columns: per-cycle statistics as cycle0.sep, ...,
    all.rmse_e, all.straight_cut.max_3d, and the calibration as odo_scale.estimate, odo_mount_deg.x.truth."""
    out: dict[str, float] = {}

    def walk(prefix: str, value) -> None:
        if isinstance(value, dict):
            for key, item in value.items():
                if key not in WINDOW_KEYS:
                    walk(f"{prefix}.{key}", item)
        elif isinstance(value, int | float) and not isinstance(value, bool):
            out[prefix] = float(value)

    for cycle in entry.get("cycles", []):
        walk("all" if cycle["cycle"] == "all" else f"cycle{cycle['cycle']}", cycle)
    for key, value in entry.items():
        if key != "cycles":
            walk(key, value)
    return out


def trials_table(results: list[TrialResult], methods: list[str]) -> pa.Table:
    """One row per trial and method: trial, method, status (ok/failed), error, then the flattened metrics
    (null where a method has none or its trial failed). A failed trial gets a row for each of `methods`."""
    rows = []
    for result in results:
        if result.error is None:
            rows += [(result.trial, name, "ok", None, flatten_metrics(entry)) for name, entry in result.metrics.items()]
        else:
            rows += [(result.trial, name, "failed", result.error, {}) for name in methods or [""]]
    columns = list(dict.fromkeys(key for *_, values in rows for key in values))
    return pa.table({"trial": pa.array([r[0] for r in rows], pa.int64()),
                     "method": pa.array([r[1] for r in rows], pa.string()),
                     "status": pa.array([r[2] for r in rows], pa.string()),
                     "error": pa.array([r[3] for r in rows], pa.string()),
                     **{c: pa.array([r[4].get(c) for r in rows], pa.float64()) for c in columns}})


def summarize(table: pa.Table, results: list[TrialResult], runner: str) -> dict:
    """The metrics.json "monte_carlo" section: trial and failure counts, the failures' reasons and, per method
    and metric, mean, sd (sample, None below two values), min, max and n over the trials with a finite value."""
    failures = [{"trial": r.trial, "error": r.error} for r in results if r.error is not None]
    ok = table.filter(pc.equal(table["status"], "ok"))
    methods: dict[str, dict] = {}
    for name in dict.fromkeys(ok["method"].to_pylist()):
        rows = ok.filter(pc.equal(ok["method"], name))
        stats = {}
        for column in table.column_names[4:]:
            values = rows[column].to_numpy()  # nulls become NaN
            values = values[np.isfinite(values)]
            if values.size:
                stats[column] = {"mean": float(values.mean()),
                                 "sd": float(values.std(ddof=1)) if values.size > 1 else None,
                                 "min": float(values.min()), "max": float(values.max()), "n": int(values.size)}
        methods[name] = stats
    return {"trials": len(results), "failed": len(failures), "runner": runner, "failures": failures,
            "methods": methods}


def write_monte_carlo(run_dir: Path, results: list[TrialResult], methods: list[str], runner: str) -> dict:
    """Write trials.parquet, trials.csv and the "monte_carlo" section of metrics.json; returns the section."""
    run_dir = Path(run_dir)
    table = trials_table(results, methods)
    pq.write_table(table, run_dir / "trials.parquet", compression="zstd")
    pcsv.write_csv(table, run_dir / "trials.csv")
    section = summarize(table, results, runner)
    path = run_dir / "metrics.json"
    data = json.loads(path.read_text()) if path.is_file() else {}
    data["monte_carlo"] = section
    path.write_text(json.dumps(data, indent=2) + "\n")
    return section


def format_monte_carlo(section: dict) -> str:
    """The headline metrics per method as mean ± sd over the trials, and the failed trials with their reason."""
    title = (f"shearer position, Monte Carlo over {section['trials']} trials ({section['runner']}, "
             f"{section['failed']} failed), whole run, mean ± sd [m]")
    lines = ["", title,
             f"{'method':16s}" + "".join(f"{title:>18s}" for _, title in HEADLINE)]
    for name, stats in section["methods"].items():
        cells = [stats[key] for key, _ in HEADLINE if key in stats]
        lines.append(f"{name:16s}" + "".join(
            f"{c['mean']:.3f} ± {'-' if c['sd'] is None else format(c['sd'], '.3f')}".rjust(18) for c in cells))
    lines += [f"trial {f['trial']} failed: {f['error']}" for f in section["failures"]]
    return "\n".join(lines)
