"""`longwall report DIR`: a run directory as plots on one self-contained HTML page.

Writes DIR/report/report.html (every figure embedded as a base64 PNG data URI, so the page can be mailed on its
own) and the same figures as PNG files beside it, each with a caption saying what it shows and in which units.
Cutting cycles are named A1, A2, ... as `longwall run` prints them (estimators.io.metrics.cycle_label).

* `top_view.png`     the true shearer path and each estimator's path, East/North in the tangent plane t of the
                     scenario's reference point, equal scales (with truth: a second panel zoomed onto the face)
* `plan_view.png`    the face frame F (twin.view.report_face): across the face (towards the coal wall) against along
                     it, one panel per cycle's straight cut, the lateral scale exaggerated by a stated factor: the
                     pans as they stood, the target line (the face alignment system's in a run with [alignment],
                     else the cut's best-fit straight line), the true path and the best MAX_METHODS estimates with
                     their +-1 sigma bands
* `profile.png`      the same cuts' height (up) along the face: the true path and the estimates with their bands
* `errors.png`       per estimator (rows) and axis east/north/up (columns): the error against time over the
                     estimate's own +-N_SIGMA band (its sd_pos_*) and the share inside it; `sigma.png` in its place
                     without truth: the bands alone
* `cycle_errors.png` RMSE east/north/up per cutting cycle per estimator (metrics.json, else recomputed)
* `detectors_METHOD.png`  for a run with estimates/METHOD_detectors.parquet (004's rail-model filter): residual
                     and dual-state chi-square against their threshold, the fading SPRT against T1/T0, the
                     rail model's isolation shaded
* `supports.png`     heat maps support x time: the push-ram strokes and the leg pressures read
* `pressures.png`    the legs' and push rams' pressures across the face against time, with the set and yield
* `face_line.png`    straightness (RMS, max) and creep per cycle; the offsets each support's push applied, when any
* `pan_line.png`     the pans' lateral deviation from their best-fit straight line at installation and at the end
                     of each cutting cycle

A run without truth (e.g. imported with `longwall import`) gets the plots that need no truth, what each estimate says
of itself (metrics.json's "self") in place of the error table, and a note naming what was left out. The run's data:
twin.view.run_data; the figures: twin.view.report_figures and, in the face frame, twin.view.report_face.
"""

from __future__ import annotations

import base64
import html
import io
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from estimators.io.metrics import column, cycle_label
from twin.pipeline.estimate import (
    SELF_COLUMNS,
    detector_thresholds,
    self_assessment_rows,
)
from twin.view.report_face import (
    MAX_METHODS,
    PLAN,
    PROFILE,
    aligned,
    best_methods,
    cuts,
    section_plot,
    sections,
)
from twin.view.report_figures import (
    N_SIGMA,
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
    support_plot,
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
    n_cycles = max(len(rows) - 1 for rows in stats.values()) if stats else 0
    per_cycle = _table(["method", *(cycle_label(k) for k in range(n_cycles)), "all"],
                       [[m] + [float(r["sep"]) for r in rows] for m, rows in stats.items()])
    if stats:
        return (facts + "<h3>Shearer position over the run</h3>" + per_method
                + "<h3>Shearer position, SEP per cutting cycle [m]</h3>" + per_cycle)
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


def _face_figures(run: RunData, figs: Figures, stats: dict[str, list[dict]], colors: dict[str, tuple]) -> None:
    """The plan view and the vertical profile in the face frame (twin.view.report_face)."""
    ranked = best_methods(run, stats)
    shown, left_out = ranked[:MAX_METHODS], ranked[MAX_METHODS:]
    drawn = cuts(run)
    parts = sections(run, shown, drawn)
    which = ""
    if shown:
        ranking = "SEP over the run" if stats else "median horizontal one-sigma"
        which = (f" Estimates: the {len(shown)} best by {ranking} ({', '.join(shown)}), each with its own ±1σ band"
                 + (f"; left out: {', '.join(left_out)} (see the errors against time)." if left_out else "."))
    cycles = run.truth.get("truth_cycles")
    panels = "The whole run (no truth_cycles)"
    if drawn[0].row is not None:
        panels = "One panel per cutting cycle's straight cut" + (
            f" ({len(drawn)} of {cycles.num_rows} cycles, evenly spread)" if len(drawn) < cycles.num_rows else "")
    target = ("target line: the face alignment system's from the true cut" if aligned(run)
              else "target line: the true cut's best-fit straight line")
    truth = " No truth in this run: the estimates alone."
    if "truth_shearer" in run.truth:
        truth = (" The true path of the shearer's body point, the pans' centres as they stood when the cut began, and "
                 "the target line: " + (
                     "the one the face alignment system (the scenario's [alignment] settings) sets at the shields "
                     "from the true cut (straight; turned towards square by at most max_turn_deg for target = "
                     "\"square\"; none where it holds the last offsets)." if aligned(run) else
                     "the least-squares straight line through the true cut (no face alignment in this run)."))
    fig, factor = section_plot(drawn, parts, colors, PLAN, target)
    figs.add("plan_view.png", fig, "Plan view in the face frame",
             f"{panels}: x towards the coal wall against y along the face from the headgate [m], the lateral scale "
             f"exaggerated x{factor}." + truth + which + " An estimate far off the truth is clipped at the edge.")
    fig, factor = section_plot(drawn, parts, colors, PROFILE)
    figs.add("profile.png", fig, "Vertical profile along the face",
             f"{panels}: z (up) against y along the face from the headgate [m], the vertical scale exaggerated "
             f"x{factor}." + (" The true path of the shearer's body point." if "truth_shearer" in run.truth
                              else " No truth in this run.") + which)


def build_report(run_dir: Path) -> Path:
    """Write run_dir/report/report.html and its PNG files; returns the page's path."""
    run = load_run(run_dir)
    colors = colors_for(list(run.estimates))
    stats = method_stats(run)
    cycles = run.truth.get("truth_cycles")
    figs = Figures()
    figs.add("top_view.png", top_view(run, colors), "Top view",
             "Shearer body point, East/North [m] in the tangent plane of the scenario's reference point, equal "
             "scales.")
    if run.scenario is not None and (run.estimates or "truth_shearer" in run.truth):
        _face_figures(run, figs, stats, colors)
    if run.estimates:
        with_truth = "truth_shearer" in run.truth
        figs.add("errors.png" if with_truth else "sigma.png", error_plot(error_series(run), cycles, colors),
                 "Position error and one-sigma against time" if with_truth else "Position one-sigma against time",
                 ("Each estimator's error (estimate - truth at the truth point) east, north and up [m] against "
                  f"t [min], over its own ±{N_SIGMA}σ band (the estimate's sd_pos_e/n/u) and the share of samples "
                  "inside it; each row on its own scale" if with_truth else
                  f"Each estimator's own ±{N_SIGMA}σ band (sd_pos_e/n/u) east, north and up [m] against t [min], "
                  "about zero (no truth: no errors); each row on its own scale")
                 + "; dotted: cutting-cycle boundaries (A1, A2, ... as `longwall run` prints them).")
    if run.estimates and not stats:
        run.notes.append("no errors scored (metrics.json holds none, and the run has no truth to score against): "
                         "left out the errors per cutting cycle")
    if stats:
        figs.add("cycle_errors.png", cycle_plot(stats, colors), "Error per cutting cycle",
                 "RMSE east/north/up [m] per cutting cycle and estimator" + (
                     " (metrics.json)." if run.metrics.get("estimators") else " (recomputed against the truth)."))
    thresholds = detector_thresholds(run.scenario) if run.scenario else None
    for m, table in run.detectors.items():
        figs.add(f"detectors_{m}.png", detector_plot(m, table, thresholds, cycles), f"Fault detectors: {m}",
                 "One point per rail-model fix against t [min]; red: thresholds (chi-square at the false-alarm "
                 "probability, fading SPRT T1/T0); shaded: the rail model isolated.")
    readings = {title: (table, name, valid, label) for title, table, name, valid, label in (
        ("push-ram strokes", run.pushram, "extension", "valid", "ram extension [m]"),
        ("leg pressures", run.pressure, "leg", "valid_leg", "leg pressure [MPa]")) if table is not None
        and table.num_rows}
    if readings:
        figs.add("supports.png", support_plot(readings, cycles), "Supports: ram strokes and leg pressures",
                 "Each support's readings (rows, 0 at the headgate) against t [min], the mean over each time bin: "
                 "the push-ram sensors' extension [m] and the legs' pressure transducers [MPa]; dropouts left out; "
                 "dotted: cutting-cycle boundaries.")
    if run.pressure is not None and run.pressure.num_rows:
        legs = run.scenario.supports.legs if run.scenario else None
        figs.add("pressures.png", pressure_plot(run.pressure, cycles, legs and legs.set_pressure_mpa,
                                                legs and legs.yield_pressure_mpa), "Support pressures",
                 "Pressure transducers of the legs and the push rams [MPa] against t [min] (the PRESSURE stream, "
                 "readings with their faults): the face's median, 5-95 % band and extreme; dashed: the set and "
                 "yield pressures of the scenario.")
    if {"truth_pans", "truth_cycles"} <= run.truth.keys() and run.scenario is not None:
        azimuth = np.radians(run.scenario.face.azimuth_deg)
        offsets = run.alignment if run.alignment is not None and np.any(column(run.alignment, "offset")) else None
        figs.add("face_line.png", face_line_plot(run.truth["truth_pans"], cycles, azimuth, offsets),
                 "Face line per cycle",
                 "Straightness (RMS and largest deviation of the pans from their best-fit line) [mm] and creep (the "
                 "pans' mean shift along the face) [mm] at the end of each cycle" + (
                     "; below, the offset [mm] each support's push applied per cycle (the scenario's and the face "
                     "alignment system's)." if offsets is not None else " (no push offsets in this run)."))
    pan_html = ""
    if {"truth_pans", "truth_cycles"} <= run.truth.keys():
        labels, along_m, lateral_m = pan_line(run.truth["truth_pans"], cycles)
        figs.add("pan_line.png", pan_line_plot(labels, along_m, lateral_m), "Pan line straightness",
                 "Each pan's lateral deviation [mm] from the best-fit straight line of the pans against the distance "
                 "along the face [m], at installation and at the end of each cutting cycle.")
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
