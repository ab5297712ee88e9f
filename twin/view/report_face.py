"""The report's figures in the face frame F (estimators.face.straightness.mat_ft: x towards the coal wall, y along the
face from the headgate, z up): the plan view (x against y) and the vertical profile (z against y) of each cycle's
straight cut, one panel per cut, with the true path and the best few estimates with their one-sigma bands; the plan
view adds the pans as they stood when the cut began and the face alignment system's target line. The scale across
the face is exaggerated by a factor the axis label states (`exaggeration`), the same in every panel.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
from matplotlib.figure import Figure

from estimators.face.alignment import path_in_face_frame
from estimators.face.straightness import pan_lines
from estimators.io.metrics import column, columns, cycle_label
from twin.pipeline.alignment_loop import AlignmentLoop
from twin.view.report_figures import decimated, enu_t, tangent_origin
from twin.view.run_data import RunData

MAX_METHODS = 3
"""The estimates drawn in the face-frame figures: the best this many."""
MAX_PANELS = 4
"""At most this many cuts drawn (evenly spread over the run, the first and the last among them)."""
PANEL_RATIO = 6.0
"""A panel is at least this many times as wide as it is high (the exaggeration is the largest 1-2-5 step that
keeps it so)."""
PANEL_WIDTH_IN = 11.5
"""Width of a panel [in]."""
MIN_SPAN_M = 0.02
"""The across range of a panel is at least this [m]."""
MAX_WIDEN = 4.0
"""An estimate widens a panel's across range to at most this many times that of the truth, the pans and the target
(beyond, it is clipped)."""
PLAN, PROFILE = 0, 2
"""The F axis across the face a figure draws: x (plan view) or z (vertical profile)."""


@dataclass(frozen=True)
class Cut:
    """A time window drawn as one panel: a cycle's straight cut, or the whole run."""

    label: str
    t0: float
    t1: float
    row: int | None = None
    """Its row of truth_cycles (None: the whole run)."""


@dataclass
class Section:
    """One cut's paths in F [m]: each (K, 3), each estimate with its one-sigma along F's x and z ((K, 3), y NaN)."""

    truth: np.ndarray | None = None
    pans: np.ndarray | None = None
    target_yx: np.ndarray | None = None
    """(S, 2) the target line: along y, across x (`_targets`)."""
    estimates: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)


def cuts(run: RunData) -> list[Cut]:
    """The straight cuts drawn (truth_cycles' t to t_cut_end), at most MAX_PANELS; without truth_cycles the whole
    run."""
    cycles = run.truth.get("truth_cycles")
    if cycles is None or not cycles.num_rows:
        return [Cut("whole run", -np.inf, np.inf)]
    shown = np.unique(np.linspace(0, cycles.num_rows - 1, min(MAX_PANELS, cycles.num_rows)).round().astype(int))
    t0, t1, direction = column(cycles, "t"), column(cycles, "t_cut_end"), column(cycles, "direction")
    return [Cut(f"{cycle_label(column(cycles, 'cycle')[k])}: straight cut "
                f"{'headgate to tailgate' if direction[k] > 0 else 'tailgate to headgate'}, "
                f"t {t0[k] / 60:.1f} to {t1[k] / 60:.1f} min", t0[k], t1[k], int(k)) for k in shown]


def best_methods(run: RunData, stats: dict[str, list[dict]]) -> list[str]:
    """The estimates ranked best first: by their SEP over the run (`stats`' "all" rows), else (no truth) by their
    median horizontal one-sigma."""
    if stats:
        return sorted(stats, key=lambda m: stats[m][-1]["sep"])
    def spread(table: pa.Table) -> float:  # dr's estimates have no sigma: last
        sd = np.hypot(column(table, "sd_pos_e"), column(table, "sd_pos_n"))
        return float(np.median(sd[np.isfinite(sd)])) if np.isfinite(sd).any() else np.inf

    spreads = {m: spread(table) for m, table in run.estimates.items()}
    return sorted(spreads, key=spreads.__getitem__)


def _window(table: pa.Table, cut: Cut) -> pa.Table:
    """About MAX_POINTS rows of `table` within the cut."""
    t = column(table, "t")
    return decimated(table.filter(pa.array((t >= cut.t0) & (t <= cut.t1))))[0]


def aligned(run: RunData) -> bool:
    """The run's face is aligned by the face alignment system (its scenario's [alignment] mode is not "none")."""
    return run.scenario is not None and run.scenario.alignment.mode != "none"


def _straight_line(p_f: np.ndarray) -> np.ndarray:
    """(2, 2) the least-squares straight line x = a + b y of a path in F at its two ends: along y, across x."""
    y = np.array([p_f[:, 1].min(), p_f[:, 1].max()])
    return np.column_stack([y, np.polyval(np.polyfit(p_f[:, 1], p_f[:, 0], 1), y)])


def _targets(run: RunData) -> dict[int, np.ndarray]:
    """By truth_cycles row, the target line (S, 2: along y, across x at the shields) the face alignment system
    (estimators.face.alignment) sets from that cycle's true cut, with the scenario's [alignment] settings
    (twin.pipeline.alignment_loop fed the true path, as in its mode truth); none for a cut it holds (not a full
    shear)."""
    loop = AlignmentLoop(run.scenario, {k: column(run.truth["truth_cycles"], k) for k in ("t", "t_cut_end", "t_end")})
    loop.observe({k: column(run.truth["truth_shearer"], k) for k in ("t", "p_t_e", "p_t_n", "p_t_u")})
    return {k: np.column_stack([loop.cfg.station_y_m + shear.creep_m, shear.target_x_m])
            for k, shear in enumerate(loop.published) if not shear.held}


def sections(run: RunData, methods: list[str], drawn: list[Cut]) -> list[Section]:
    """Each cut's paths in F (needs the scenario's face azimuth)."""
    azimuth = np.radians(run.scenario.face.azimuth_deg)
    origin = tangent_origin(run)
    truth = run.truth.get("truth_shearer")
    pans = run.truth.get("truth_pans")
    pan_cols = ({name: column(pans, name) for name in ("t", "pan", "p_t_e", "p_t_n", "p_t_u")}
                if pans is not None and pans.num_rows else None)
    targets = _targets(run) if aligned(run) and truth is not None and "truth_cycles" in run.truth else {}
    out = []
    for cut in drawn:
        one = Section(target_yx=targets.get(cut.row))
        if truth is not None:
            one.truth = path_in_face_frame(columns(_window(truth, cut), "p_t"), None, azimuth)[0]
            if not aligned(run) and cut.row is not None:
                one.target_yx = _straight_line(one.truth)
        if pan_cols is not None and cut.row is not None:
            one.pans = pan_lines(pan_cols, np.array([cut.t0]), int(pan_cols["pan"].max()) + 1, azimuth)[0]
        for m in methods:
            rows = _window(run.estimates[m], cut)
            sd_enu = columns(rows, "sd_pos")
            p_f, sd_x = path_in_face_frame(enu_t(rows, origin), sd_enu[:, :2], azimuth)
            one.estimates[m] = (p_f, np.column_stack([sd_x, np.full(sd_x.size, np.nan), sd_enu[:, 2]]))
        out.append(one)
    return out


def exaggeration(along_span_m: float, across_span_m: float) -> int:
    """The largest of 1, 2, 5, 10, 20, ... that draws a panel `along_span_m` wide and `across_span_m` high at least
    PANEL_RATIO times as wide as high (1: equal scales)."""
    limit = along_span_m / (PANEL_RATIO * max(across_span_m, 1e-6))
    steps = [m * 10 ** e for e in range(6) for m in (1, 2, 5)]
    return max([s for s in steps if s <= limit] or [1])


def _robust_range(values: list[np.ndarray]) -> tuple[float, float]:
    """The 0.5-99.5 % range of the finite values."""
    v = np.concatenate([np.ravel(x) for x in values])
    v = v[np.isfinite(v)]
    return (float(np.percentile(v, 0.5)), float(np.percentile(v, 99.5))) if v.size else (0.0, 1.0)


def section_plot(drawn: list[Cut], parts: list[Section], colors: dict[str, tuple], axis: int, target_label: str = ""
                 ) -> tuple[Figure, int]:
    """The cuts' paths across the face (F's x: PLAN, with the pans and the target line named `target_label`, or z:
    PROFILE) against along it, one panel per cut, and the exaggeration of the across scale the panels are drawn
    with."""
    def across(p: np.ndarray | None) -> list[np.ndarray]:
        return [] if p is None else [p[:, axis]]
    reference = [across(s.truth) + (across(s.pans) if axis == PLAN else [])
                 + ([s.target_yx[:, 1]] if axis == PLAN and s.target_yx is not None else []) for s in parts]
    estimated = [[p[:, axis] for p, _ in s.estimates.values()] for s in parts]
    ranges = []
    for ref, est in zip(reference, estimated):
        lo, hi = _robust_range(ref or est)
        e_lo, e_hi = _robust_range(est) if est and ref else (lo, hi)
        reach = MAX_WIDEN * max(hi - lo, MIN_SPAN_M)
        ranges.append((max(min(lo, e_lo), hi - reach), min(max(hi, e_hi), lo + reach)))
    along = _robust_range([p[:, 1] for s in parts for p in [s.truth, s.pans, *[e[0] for e in s.estimates.values()]]
                           if p is not None])
    span = max(max(hi - lo for lo, hi in ranges) * 1.25, MIN_SPAN_M)
    along_span = along[1] - along[0] + 2.0
    factor = exaggeration(along_span, span)
    panel_h_in = PANEL_WIDTH_IN * factor * span / along_span
    fig = Figure(figsize=(13, 1.1 + len(parts) * (panel_h_in + 0.7)), layout="constrained")
    axes = fig.subplots(len(parts), 1, squeeze=False)[:, 0]
    handles = {}
    for ax, cut, part, (lo, hi) in zip(axes, drawn, parts, ranges):
        if part.pans is not None and axis == PLAN:
            ax.plot(part.pans[:, 1], part.pans[:, 0], ".-", color="0.6", markersize=3, linewidth=0.8,
                    label="pans when the cut began")
        if part.target_yx is not None and axis == PLAN:
            ax.plot(part.target_yx[:, 0], part.target_yx[:, 1], "--", color="tab:red", linewidth=1.2,
                    label=target_label)
        if part.truth is not None:
            ax.plot(part.truth[:, 1], part.truth[:, axis], color="k", linewidth=2, alpha=0.7, label="truth")
        for m, (p_f, sd_f) in part.estimates.items():
            ax.fill_between(p_f[:, 1], p_f[:, axis] - sd_f[:, axis], p_f[:, axis] + sd_f[:, axis], color=colors[m],
                            alpha=0.2, linewidth=0, label=f"{m} ±1σ")
            ax.plot(p_f[:, 1], p_f[:, axis], color=colors[m], linewidth=1, label=m)
        mid = 0.5 * (lo + hi)
        ax.set_xlim(along[0] - 1.0, along[1] + 1.0)
        ax.set_ylim(mid - span / 2, mid + span / 2)
        ax.set_aspect(factor, adjustable="box")
        ax.set_title(cut.label, loc="left", fontsize=9)
        ax.set_ylabel(("x, towards the coal wall [m]" if axis == PLAN else "z, up [m]")
                      + f"\n({'lateral' if axis == PLAN else 'vertical'} x{factor})", fontsize=9)
        ax.grid(alpha=0.3)
        handles.update(zip(*ax.get_legend_handles_labels()[::-1]))
    axes[-1].set_xlabel("y, along the face from the headgate [m]")
    fig.legend(list(handles.values()), list(handles), loc="outside upper center", fontsize=8, ncols=5)
    return fig, factor
