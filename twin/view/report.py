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

A run without truth (e.g. imported with `longwall import`) gets the plots that need no truth, what each estimate says
of itself (metrics.json's "self") in place of the error table, and a note naming what was left out. The run's data: twin.view.run_data; the figures: twin.view.report_figures.
"""

from __future__ import annotations

import base64
import html
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from estimators.io.metrics import column
from twin.pipeline.estimate import (
    SELF_COLUMNS,
    detector_thresholds,
    self_assessment_rows,
)
from twin.view.report_figures import (
    colors_for,
    cycle_plot,
    detector_plot,
    error_plot,
    error_series,
    face_line_plot,
    method_stats,
    pan_line,
    pan_line_plot,
    pressure_plot,
    top_view,
)
from twin.view.run_data import RunData, load_run

REPORT_DIR = "report"
REPORT_HTML = "report.html"
DPI = 100


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


# ------------------------------------------------------------------------------------------------ the page

_CSS = """body{font-family:sans-serif;max-width:1350px;margin:1em auto;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1em}td,th{border:1px solid #bbb;padding:2px 8px;text-align:right}
th{background:#eee}td:first-child,th:first-child{text-align:left}img{max-width:100%}
figure{margin:1em 0}figcaption{font-size:90%;color:#444}.note{background:#fff4d6;padding:4px 8px}"""


def _table(header: list[str], rows: list[list]) -> str:
    def cell(v) -> str:
        return f"{v:.3f}" if isinstance(v, float) else "-" if v is None else html.escape(str(v))
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
    if stats:
        return facts + "<h3>Shearer position over the run</h3>" + per_method
    unscored = {m: e for m, e in run.metrics.get("estimators", {}).items() if m in run.estimates and "self" in e}
    if not unscored:
        return facts
    return facts + ("<h3>Shearer estimates on their own (no truth: no errors scored)</h3>"
                    + _table(["method", *SELF_COLUMNS], self_assessment_rows(unscored)))


def _figure_html(figs: Figures, name: str) -> str:
    data = base64.b64encode(figs.png[name]).decode()
    return (f"<h2>{html.escape(figs.title[name])}</h2><figure><img src=\"data:image/png;base64,{data}\" "
            f"alt=\"{html.escape(figs.title[name])}\"><figcaption>{html.escape(figs.caption[name])} "
            f"File: <a href=\"{name}\">{name}</a></figcaption></figure>")


def build_report(run_dir: Path) -> Path:
    """Write run_dir/report/report.html and its PNG files; returns the page's path."""
    run = load_run(run_dir)
    colors = colors_for(list(run.estimates))
    stats = method_stats(run)
    cycles = run.truth.get("truth_cycles")
    figs = Figures()
    figs.add("top_view.png", top_view(run, colors), "Top view",
             "Shearer body point, East/North [m] in the tangent plane of the scenario's reference point.")
    if run.estimates and "truth_shearer" in run.truth:
        figs.add("errors.png", error_plot(error_series(run), cycles, colors), "Position error against time",
                 "Estimate - truth at the truth point; dotted: cutting-cycle boundaries.")
    if run.estimates and not stats:
        run.notes.append("no errors scored (metrics.json holds none, and the run has no truth to score against): "
                         "left out the errors per cutting cycle")
    if stats:
        figs.add("cycle_errors.png", cycle_plot(stats, colors), "Error per cutting cycle",
                 "RMSE east/north/up per cutting cycle and estimator" + (
                     " (metrics.json)." if run.metrics.get("estimators") else " (recomputed against the truth)."))
    thresholds = detector_thresholds(run.scenario) if run.scenario else None
    for m, table in run.detectors.items():
        figs.add(f"detectors_{m}.png", detector_plot(m, table, thresholds, cycles), f"Fault detectors: {m}",
                 "One point per rail-model fix; red: thresholds (chi-square at the false-alarm probability, fading "
                 "SPRT T1/T0); shaded: the rail model isolated.")
    if run.pressure is not None and run.pressure.num_rows:
        legs = run.scenario.supports.legs if run.scenario else None
        figs.add("pressures.png", pressure_plot(run.pressure, cycles, legs and legs.set_pressure_mpa,
                                                legs and legs.yield_pressure_mpa), "Support pressures",
                 "Pressure transducers of the legs and the push rams (the PRESSURE stream, readings with their faults); "
                 "dashed: the set and yield pressures of the scenario.")
    if {"truth_pans", "truth_cycles"} <= run.truth.keys() and run.scenario is not None:
        azimuth = np.radians(run.scenario.face.azimuth_deg)
        figs.add("face_line.png", face_line_plot(run.truth["truth_pans"], cycles, azimuth, run.alignment),
                 "Face line per cycle",
                 "Straightness (RMS and largest deviation of the pans from their best-fit line) and creep (the pans' "
                 "mean shift along the face) at the end of each cycle; below, the offset each support's push applied "
                 "(the scenario's and the face alignment system's).")
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
