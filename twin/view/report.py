"""`longwall report DIR`: a run directory as plots on one self-contained HTML page.

Writes DIR/report/report.html (every figure embedded as a base64 PNG data URI, so the page can be mailed on its
own) and the same figures as PNG files beside it:

* `top_view.png`     the true shearer path and each estimator's path, East/North in the tangent plane t of the
                     scenario's reference point (with truth: a second panel zoomed onto the face)
* `errors.png`       horizontal and |up| position error against time per estimator, cutting-cycle boundaries
* `cycle_errors.png` RMSE east/north/up per cutting cycle per estimator (metrics.json, else recomputed)
* `detectors_METHOD.png`  for a run with estimates/METHOD_detectors.parquet (004's rail-model filter): residual
                     and dual-state chi-square against their threshold, the fading SPRT against T1/T0, the
                     rail model's isolation shaded
* `pan_line.png`     the pans' lateral deviation from their best-fit straight line at installation and at the end
                     of each cutting cycle

Errors are estimate - truth in metres East/North/Up at the truth point (estimators.io.metrics). A run without truth
(e.g. imported with `longwall import`) gets the plots that need no truth and a note naming what was left out.
Long series are decimated to about MAX_POINTS samples for plotting. Figures are matplotlib `Figure` objects
without pyplot (Agg canvas, nothing global to close), as matplotlib recommends for servers.
"""

from __future__ import annotations

import base64
import html
import io
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from matplotlib import colormaps
from matplotlib.figure import Figure

from estimators.io.logformat import (
    ESTIMATE,
    ESTIMATE_DETECTORS,
    ESTIMATES_DIR,
    STREAMS,
    Stream,
    estimate_path,
    read_estimate,
    read_stream,
)
from estimators.io.metrics import column, cycle_metrics, position_errors
from estimators.nav import earth
from twin.config.scenario import Scenario, load_scenario
from twin.pipeline.estimate import detector_thresholds
from twin.pipeline.rundir import RunDirError
from twin.view.estimate_recording import plot_rows
from twin.view.summary import latest_per_id

REPORT_DIR = "report"
REPORT_HTML = "report.html"
MAX_POINTS = 4000
"""About the largest number of samples plotted per series."""
DPI = 100
TRUTH_NAMES = ("truth_shearer", "truth_cycles", "truth_pans")


@dataclass
class RunData:
    """What a run directory holds for the report; an absent stream is missing from its dict."""

    run_dir: Path
    scenario: Scenario | None
    metrics: dict
    truth: dict[str, pa.Table]
    estimates: dict[str, pa.Table]
    detectors: dict[str, pa.Table]
    notes: list[str] = field(default_factory=list)
    """What the report leaves out and why."""


@dataclass
class Figures:
    """Rendered figures by file name, with their titles and captions, in page order."""

    png: dict[str, bytes] = field(default_factory=dict)
    title: dict[str, str] = field(default_factory=dict)
    caption: dict[str, str] = field(default_factory=dict)

    def add(self, name: str, fig: Figure, title: str, caption: str) -> None:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=DPI)
        self.png[name], self.title[name], self.caption[name] = buf.getvalue(), title, caption


def _methods(run_dir: Path, stream: Stream) -> list[str]:
    """Methods with a file of `stream` in run_dir/estimates (file names as estimate_path gives them)."""
    suffix = estimate_path(Path(), "m", stream).stem.removeprefix("m")
    methods = []
    for path in sorted((run_dir / ESTIMATES_DIR).glob(f"*{suffix}.parquet")):
        if (pq.read_schema(path).metadata or {}).get(b"stream") == stream.name.encode():
            methods.append(path.stem.removesuffix(suffix))
    return methods


def load_run(run_dir: Path) -> RunData:
    """Read what the report plots; RunDirError when run_dir is missing or holds neither truth nor estimates."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunDirError(f"{run_dir}: no such run directory")
    truth = {name: read_stream(run_dir, STREAMS[name]) for name in TRUTH_NAMES
             if (run_dir / STREAMS[name].filename).is_file()}
    estimates = {m: read_estimate(run_dir, m) for m in _methods(run_dir, ESTIMATE)}
    if not truth and not estimates:
        raise RunDirError(f"{run_dir}: nothing to report (no truth_*.parquet, no {ESTIMATES_DIR}/*.parquet); "
                          f"give a directory written by `longwall run`, `longwall import` or `longwall estimate`")
    scenario = run_dir / "scenario.toml"
    metrics_path = run_dir / "metrics.json"
    data = RunData(run_dir, load_scenario(scenario) if scenario.is_file() else None,
                   json.loads(metrics_path.read_text()) if metrics_path.is_file() else {}, truth, estimates,
                   {m: read_estimate(run_dir, m, ESTIMATE_DETECTORS) for m in _methods(run_dir, ESTIMATE_DETECTORS)})
    missing = [STREAMS[name].filename for name in TRUTH_NAMES if name not in truth]
    if missing:
        data.notes.append(f"no {', '.join(missing)} (a run without truth, e.g. imported): left out "
                          + "; ".join(what for name, what in (
                              ("truth_shearer", "the true path in the top view and the errors against time"),
                              ("truth_cycles", "the cutting-cycle boundaries"),
                              ("truth_pans", "the pan line's straightness")) if name not in truth))
    if not estimates:
        data.notes.append(f"no estimates in {ESTIMATES_DIR}/: left out every estimator plot "
                          f"(`longwall estimate {run_dir}` writes them)")
    if data.scenario is None:
        data.notes.append("no scenario.toml: the top view's origin is the first position in the run, and the "
                          "detector thresholds are left out")
    return data


def _origin(run: RunData) -> tuple[float, float, float]:
    """(lat, lon [rad], h [m]) of the tangent plane t: the scenario's reference point, else the first position."""
    if run.scenario is not None:
        site = run.scenario.site
        return float(np.radians(site.lat_deg)), float(np.radians(site.lon_deg)), float(site.height_m)
    first = run.truth["truth_shearer"] if "truth_shearer" in run.truth else next(iter(run.estimates.values()))
    return tuple(float(column(first, k)[0]) for k in ("lat", "lon", "h"))


def _decimated(table: pa.Table) -> tuple[pa.Table, np.ndarray]:
    """About MAX_POINTS rows of `table` spread evenly in time, and their times [s]."""
    t = column(table, "t")
    return plot_rows(table, MAX_POINTS / max(t[-1] - t[0], 1e-9) if t.size else 1.0)


def _enu_t(table: pa.Table, origin: tuple[float, float, float]) -> np.ndarray:
    """(K, 3) East/North/Up [m] of a table's lat/lon/h in the tangent plane at `origin`."""
    return earth.lla_to_enu(column(table, "lat"), column(table, "lon"), column(table, "h"), *origin)


def _colors(methods: list[str]) -> dict[str, tuple]:
    """One tab10 colour per method, the same in every figure."""
    cmap = colormaps["tab10"]
    return {m: cmap(k % 10) for k, m in enumerate(methods)}


def _cycle_lines(ax, cycles: pa.Table | None) -> None:
    """Cutting-cycle boundaries as vertical lines [min] labelled with the cycle at the top of the axes."""
    if cycles is None:
        return
    starts_min = column(cycles, "t") / 60
    ax.vlines(np.r_[starts_min, column(cycles, "t_end")[-1] / 60], 0, 1, transform=ax.get_xaxis_transform(),
              colors="0.4", linestyles=":", linewidth=1)
    for cycle, t_min in zip(column(cycles, "cycle").astype(int), starts_min):
        ax.text(t_min, 1.0, f" cycle {cycle}", transform=ax.get_xaxis_transform(), va="bottom", fontsize=8,
                color="0.3")


def top_view(run: RunData, colors: dict[str, tuple]) -> Figure:
    """The true path (grey) and each estimated path, East/North [m] in t; with truth a second panel zoomed onto the
    true path."""
    origin = _origin(run)
    truth = run.truth.get("truth_shearer")
    paths_en = {m: _enu_t(_decimated(table)[0], origin)[:, :2] for m, table in run.estimates.items()}
    true_en = _enu_t(_decimated(truth)[0], origin)[:, :2] if truth is not None else None
    fig = Figure(figsize=(13, 6.5), layout="constrained")
    axes = fig.subplots(1, 2 if true_en is not None else 1, squeeze=False)[0]
    for ax in axes:
        for m, en in paths_en.items():
            ax.plot(en[:, 0], en[:, 1], color=colors[m], linewidth=1, label=m)
        if true_en is not None:
            ax.plot(true_en[:, 0], true_en[:, 1], color="k", linewidth=2.5, alpha=0.6, label="truth", zorder=0)
        ax.set_xlabel("east [m]")
        ax.set_ylabel("north [m]")
        ax.grid(alpha=0.3)
    axes[0].set_aspect("equal", adjustable="datalim")
    axes[0].set_title("top view, equal scales")
    axes[0].legend(fontsize=8, loc="best")
    if true_en is not None:
        lo, hi = true_en.min(axis=0), true_en.max(axis=0)
        margin = 0.5 + 0.1 * (hi - lo)
        axes[1].set_xlim(lo[0] - margin[0], hi[0] + margin[0])
        axes[1].set_ylim(lo[1] - margin[1], hi[1] + margin[1])
        axes[1].set_title("zoomed onto the true path")
    return fig


def error_series(run: RunData) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per method (t [s], err_enu [m] (K, 3)) at about MAX_POINTS estimate times (needs truth_shearer)."""
    truth = run.truth["truth_shearer"]
    return {m: position_errors(_decimated(table)[0], truth) for m, table in run.estimates.items()}


def error_plot(errors: dict[str, tuple[np.ndarray, np.ndarray]], cycles: pa.Table | None,
               colors: dict[str, tuple]) -> Figure:
    """Horizontal and |up| position error against time per estimator (log scale), cycle boundaries dotted."""
    fig = Figure(figsize=(13, 7), layout="constrained")
    ax_h, ax_u = fig.subplots(2, 1, sharex=True)
    for m, (t, err_enu) in errors.items():
        ax_h.plot(t / 60, np.hypot(err_enu[:, 0], err_enu[:, 1]), color=colors[m], linewidth=1, label=m)
        ax_u.plot(t / 60, np.abs(err_enu[:, 2]), color=colors[m], linewidth=1, label=m)
    for ax, label in ((ax_h, "horizontal error [m]"), (ax_u, "|up error| [m]")):
        ax.set_yscale("log")
        ax.set_ylim(bottom=1e-3)  # below a millimetre is noise for a shearer
        ax.set_ylabel(label)
        ax.grid(alpha=0.3, which="both")
        _cycle_lines(ax, cycles)
    ax_u.set_xlabel("t [min]")
    ax_h.legend(fontsize=8, loc="upper left", ncols=min(len(errors), 4))
    return fig


def method_stats(run: RunData) -> dict[str, list[dict]]:
    """Per method the rows of estimators.io.metrics.cycle_metrics (each cutting cycle, then "all"): from
    metrics.json, else recomputed against the truth; methods with neither are left out."""
    stats = {}
    recorded = run.metrics.get("estimators", {})
    for m, table in run.estimates.items():
        if m in recorded:
            stats[m] = recorded[m]["cycles"]
        elif {"truth_shearer", "truth_cycles"} <= run.truth.keys():
            stats[m] = cycle_metrics(*position_errors(table, run.truth["truth_shearer"]), run.truth["truth_cycles"])
    return stats


def cycle_plot(stats: dict[str, list[dict]], colors: dict[str, tuple]) -> Figure:
    """RMSE east/north/up per cutting cycle (`method_stats` rows but "all") as grouped bars, one bar per estimator
    (log scale)."""
    stats = {m: rows[:-1] for m, rows in stats.items()}
    fig = Figure(figsize=(13, 8), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    width = 0.8 / len(stats)
    for k, (m, rows) in enumerate(stats.items()):
        x = np.array([r["cycle"] for r in rows], float) - 0.4 + (k + 0.5) * width
        for ax, key in zip(axes, ("rmse_e", "rmse_n", "rmse_u")):
            ax.bar(x, [r[key] for r in rows], width, color=colors[m], label=m)
    for ax, axis in zip(axes, ("east", "north", "up")):
        ax.set_yscale("log")
        ax.set_ylabel(f"RMSE {axis} [m]")
        ax.grid(alpha=0.3, axis="y", which="both")
    cycles = sorted({r["cycle"] for rows in stats.values() for r in rows})
    axes[-1].set_xticks(cycles, [f"cycle {c}" for c in cycles])
    axes[0].legend(fontsize=8, ncols=min(len(stats), 4))
    return fig


def detector_plot(method: str, table: pa.Table, thresholds: dict[str, float] | None,
                  cycles: pa.Table | None) -> Figure:
    """Each detector statistic per rail-model fix with its threshold(s); the rail model's isolation shaded."""
    t_min = column(table, "t") / 60
    isolated = column(table, "isolated") > 0
    fig = Figure(figsize=(13, 8), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    lines = {"residual": (("threshold", "residual"),), "dual_state": (("threshold", "dual_state"),),
             "fsprt": (("T1 (fault)", "t_on"), ("T0 (clear)", "t_off"))}
    for ax, (name, limits) in zip(axes, lines.items()):
        ax.plot(t_min, column(table, name), ".", markersize=3, color="tab:blue", label=f"{method} {name}")
        for (label, key), style in zip(limits, ("--", ":")) if thresholds else ():
            ax.axhline(thresholds[key], color="tab:red", linestyle=style, label=f"{label} {thresholds[key]:.3g}")
        ax.fill_between(t_min, 0, 1, where=isolated, step="post", transform=ax.get_xaxis_transform(),
                        color="tab:orange", alpha=0.25, label="rail model isolated")
        ax.set_yscale("log" if name != "fsprt" else "linear")
        ax.set_ylabel(name.replace("_", "-"))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
        _cycle_lines(ax, cycles)
    axes[-1].set_xlabel("t [min]")
    return fig


def pan_line(truth_pans: pa.Table, truth_cycles: pa.Table) -> tuple[list[str], np.ndarray, np.ndarray]:
    """(labels, along_m (C, P), lateral_m (C, P)) of the pans' running-line centres at installation (t = 0) and at
    the end of each cycle: distance along and across their best-fit straight line (total least squares in the
    horizontal plane), along from headgate to tailgate, lateral positive towards the coal wall (the face's x)."""
    t, pan = column(truth_pans, "t"), column(truth_pans, "pan").astype(int)
    t_end = np.r_[0.0, column(truth_cycles, "t_end")]
    rows = np.stack([latest_per_id(t, pan, pan.max() + 1, te) for te in t_end])
    p_en = np.column_stack([column(truth_pans, "p_t_e"), column(truth_pans, "p_t_n")])[rows]  # (C, P, 2)
    d_en = p_en - p_en.mean(axis=1, keepdims=True)
    along_en = np.linalg.svd(d_en, full_matrices=False)[2][:, 0, :]  # principal direction per line (C, 2)
    along_en *= np.sign(np.einsum("ck,ck->c", p_en[:, -1] - p_en[:, 0], along_en))[:, None]
    wall_en = np.column_stack([along_en[:, 1], -along_en[:, 0]])  # x = y rotated -90 deg about up
    along_m = np.einsum("cpk,ck->cp", d_en, along_en)
    labels = ["installed"] + [f"cycle {c}" for c in column(truth_cycles, "cycle").astype(int)]
    return labels, along_m - along_m[:, :1], np.einsum("cpk,ck->cp", d_en, wall_en)


def pan_line_plot(labels: list[str], along_m: np.ndarray, lateral_m: np.ndarray) -> Figure:
    """Lateral deviation [mm] of each pan from its line's best fit, one line per cycle."""
    fig = Figure(figsize=(13, 5), layout="constrained")
    ax = fig.subplots()
    viridis = colormaps["viridis"](np.linspace(0, 0.9, len(labels)))
    for label, a, lat, c in zip(labels, along_m, lateral_m, viridis):
        ax.plot(a, lat * 1e3, ".-", color=c, markersize=3, linewidth=1, label=label)
    ax.axhline(0, color="0.5", linewidth=0.8)
    ax.set_xlabel("along the face from the headgate [m]")
    ax.set_ylabel("lateral deviation, + towards the coal wall [mm]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncols=min(len(labels), 6))
    return fig


# ------------------------------------------------------------------------------------------------ the page

_CSS = """body{font-family:sans-serif;max-width:1350px;margin:1em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1em}td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}img{max-width:100%}
figure{margin:1em 0}figcaption{font-size:90%;color:#444}.note{background:#fff4d6;padding:4px 8px}"""


def _table(header: list[str], rows: list[list]) -> str:
    def cell(v) -> str:
        return f"{v:.3f}" if isinstance(v, float) else html.escape(str(v))
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _duration_s(run: RunData) -> float:
    twin = run.metrics.get("twin", {})
    if "simulated_s" in twin:
        return float(twin["simulated_s"])
    tables = list(run.truth.values()) + list(run.estimates.values())
    return max(float(column(tab, "t")[-1]) for tab in tables if tab.num_rows and "t" in tab.column_names)


def _header(run: RunData, stats: dict[str, list[dict]]) -> str:
    scn = run.scenario
    name = f"{scn.name} (seed {scn.seed})" if scn else run.metrics.get("twin", {}).get("scenario", "unknown")
    duration_s = _duration_s(run)
    facts = _table(["run", ""], [["directory", run.run_dir.resolve()], ["scenario", name],
                                 ["duration", f"{duration_s:.0f} s ({duration_s / 3600:.2f} h)"],
                                 ["methods", ", ".join(run.estimates) or "none"]])
    keys = ("rmse_e", "rmse_n", "rmse_u", "max_horizontal", "max_3d", "sep")
    per_method = _table(["method", "RMSE east [m]", "RMSE north [m]", "RMSE up [m]", "max horizontal [m]",
                         "max 3-D [m]", "SEP [m]"],
                        [[m] + [float(rows[-1][k]) for k in keys] for m, rows in stats.items()])
    return facts + ("<h3>Shearer position over the run</h3>" + per_method if stats else "")


def _figure_html(figs: Figures, name: str) -> str:
    data = base64.b64encode(figs.png[name]).decode()
    return (f"<h2>{html.escape(figs.title[name])}</h2><figure><img src=\"data:image/png;base64,{data}\" "
            f"alt=\"{html.escape(figs.title[name])}\"><figcaption>{html.escape(figs.caption[name])} "
            f"File: <a href=\"{name}\">{name}</a></figcaption></figure>")


def build_report(run_dir: Path) -> Path:
    """Write run_dir/report/report.html and its PNG files; returns the page's path."""
    run = load_run(run_dir)
    colors = _colors(list(run.estimates))
    stats = method_stats(run)
    cycles = run.truth.get("truth_cycles")
    figs = Figures()
    figs.add("top_view.png", top_view(run, colors), "Top view",
             "Shearer body point, East/North [m] in the tangent plane of the scenario's reference point.")
    if run.estimates and "truth_shearer" in run.truth:
        figs.add("errors.png", error_plot(error_series(run), cycles, colors), "Position error against time",
                 "Estimate - truth at the truth point; dotted: cutting-cycle boundaries.")
    if stats:
        figs.add("cycle_errors.png", cycle_plot(stats, colors), "Error per cutting cycle",
                 "RMSE east/north/up per cutting cycle and estimator" + (
                     " (metrics.json)." if run.metrics.get("estimators") else " (recomputed against the truth)."))
    thresholds = detector_thresholds(run.scenario) if run.scenario else None
    for m, table in run.detectors.items():
        figs.add(f"detectors_{m}.png", detector_plot(m, table, thresholds, cycles), f"Fault detectors: {m}",
                 "One point per rail-model fix; red: thresholds (chi-square at the false-alarm probability, fading "
                 "SPRT T1/T0); shaded: the rail model isolated.")
    pan_html = ""
    if {"truth_pans", "truth_cycles"} <= run.truth.keys():
        labels, along_m, lateral_m = pan_line(run.truth["truth_pans"], cycles)
        figs.add("pan_line.png", pan_line_plot(labels, along_m, lateral_m), "Pan line straightness",
                 "Each pan's lateral deviation from the best-fit straight line of the pans at installation and at "
                 "the end of each cutting cycle.")
        t_end_min = np.r_[0.0, column(cycles, "t_end")] / 60
        pan_html = _table(["line", "t [min]", "max |lateral deviation| [mm]"],
                          [[label, f"{t:.1f}", float(np.abs(lat).max() * 1e3)]
                           for label, t, lat in zip(labels, t_end_min, lateral_m)])
    out = Path(run_dir) / REPORT_DIR
    out.mkdir(exist_ok=True)
    for name, png in figs.png.items():
        (out / name).write_bytes(png)
    notes = "".join(f"<p class=\"note\">{html.escape(n)}</p>" for n in run.notes)
    body = "".join(_figure_html(figs, name) + (pan_html if name == "pan_line.png" else "") for name in figs.png)
    page = (f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>longwall report: "
            f"{html.escape(run.run_dir.name)}</title><style>{_CSS}</style></head><body>"
            f"<h1>longwall report: {html.escape(run.run_dir.name)}</h1>{_header(run, stats)}{notes}{body}"
            f"</body></html>\n")
    path = out / REPORT_HTML
    path.write_text(page)
    return path
