"""The report's figures (`longwall report`) in time and per support: top view, errors with their sigma bands against
time, errors per cycle, fault detectors, the supports' ram strokes and leg pressures, pan line straightness, the face
line per cycle and the push offsets, as matplotlib Figures without pyplot (Agg canvas, nothing global to close). The
face-frame figures: twin.view.report_face.

Errors are estimate - truth in metres East/North/Up at the truth point (estimators.io.metrics). Long series are
decimated to about MAX_POINTS samples for plotting. Cycles are labelled A1, A2, ... (estimators.io.metrics.cycle_label).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import FuncFormatter, MaxNLocator

from estimators.face.straightness import face_drift
from estimators.io.metrics import column, columns, cycle_label, cycle_metrics, position_errors
from estimators.nav import earth
from twin.view.estimate_recording import plot_rows
from twin.view.run_data import RunData
from twin.view.summary import latest_per_id

MAX_POINTS = 4000
"""About the largest number of samples plotted per series."""
N_SIGMA = 1
"""Half-width of the error plots' bands in one-sigma."""
SUPPORT_COLUMNS = 1500
"""At most this many time bins in the supports' heat maps."""
LEGEND_ENTRIES = 12
"""At most about this many lines of a sequence (one per cycle) named in a legend."""


def tangent_origin(run: RunData) -> tuple[float, float, float]:
    """(lat, lon [rad], h [m]) of the tangent plane t: the scenario's reference point, else the first position."""
    if run.scenario is not None:
        site = run.scenario.site
        return float(np.radians(site.lat_deg)), float(np.radians(site.lon_deg)), float(site.height_m)
    first = run.truth["truth_shearer"] if "truth_shearer" in run.truth else next(iter(run.estimates.values()))
    return tuple(float(column(first, k)[0]) for k in ("lat", "lon", "h"))


def decimated(table: pa.Table) -> tuple[pa.Table, np.ndarray]:
    """About MAX_POINTS rows of `table` spread evenly in time, and their times [s]."""
    t = column(table, "t")
    return plot_rows(table, MAX_POINTS / max(t[-1] - t[0], 1e-9) if t.size else 1.0)


def enu_t(table: pa.Table, origin: tuple[float, float, float]) -> np.ndarray:
    """(K, 3) East/North/Up [m] of a table's lat/lon/h in the tangent plane at `origin`."""
    return earth.lla_to_enu(column(table, "lat"), column(table, "lon"), column(table, "h"), *origin)


def colors_for(methods: list[str]) -> dict[str, tuple]:
    """One tab10 colour per method, the same in every figure."""
    cmap = colormaps["tab10"]
    return {m: cmap(k % 10) for k, m in enumerate(methods)}


def cycle_lines(ax, cycles: pa.Table | None, labelled: bool = True) -> None:
    """Cutting-cycle boundaries as vertical lines [min], labelled (A1, A2, ...: cycle_label) at the top of the
    axes."""
    if cycles is None:
        return
    starts_min = column(cycles, "t") / 60
    ax.vlines(np.r_[starts_min, column(cycles, "t_end")[-1] / 60], 0, 1, transform=ax.get_xaxis_transform(),
              colors="0.4", linestyles=":", linewidth=1)
    for cycle, t_min in zip(column(cycles, "cycle").astype(int), starts_min) if labelled else ():
        ax.text(t_min, 1.0, f" {cycle_label(cycle)}", transform=ax.get_xaxis_transform(), va="bottom", fontsize=8,
                color="0.3")


def cycle_axis(axis) -> None:
    """An axis whose integer positions are 0-based cycles, ticked with their labels (A1, A2, ...)."""
    axis.set_major_locator(MaxNLocator(integer=True))
    axis.set_major_formatter(FuncFormatter(lambda v, _: cycle_label(round(v)) if v >= 0 else ""))


def outside_legend(fig: Figure, ax, ncols: int = 1) -> None:
    """The legend of `ax`'s labelled artists to the right of the figure's axes, clear of the traces."""
    fig.legend(*ax.get_legend_handles_labels(), loc="outside right upper", fontsize=8, ncols=ncols)


def top_view(run: RunData, colors: dict[str, tuple]) -> Figure:
    """The true path (grey) and each estimated path, East/North [m] in t, equal scales; with truth a second panel
    zoomed onto the true path (equal scales too)."""
    origin = tangent_origin(run)
    truth = run.truth.get("truth_shearer")
    paths_en = {m: enu_t(decimated(table)[0], origin)[:, :2] for m, table in run.estimates.items()}
    true_en = enu_t(decimated(truth)[0], origin)[:, :2] if truth is not None else None
    fig = Figure(figsize=(13, 6), layout="constrained")
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
    axes[0].set_title("every path")
    outside_legend(fig, axes[0])
    if true_en is not None:
        mid_en = 0.5 * (true_en.min(axis=0) + true_en.max(axis=0))
        half_m = 0.5 + 0.6 * float(np.ptp(true_en, axis=0).max())
        axes[1].set_xlim(mid_en[0] - half_m, mid_en[0] + half_m)
        axes[1].set_ylim(mid_en[1] - half_m, mid_en[1] + half_m)
        axes[1].set_aspect("equal", adjustable="box")
        axes[1].set_title("zoomed onto the true path")
    return fig


@dataclass(frozen=True)
class ErrorSeries:
    """One estimate's position at about MAX_POINTS of its times: its error and its own one-sigma."""

    t: np.ndarray
    """[s]"""
    err_enu: np.ndarray | None
    """(K, 3) estimate - truth East/North/Up [m] at the truth point (None: the run has no truth)."""
    sd_enu: np.ndarray
    """(K, 3) the estimate's sd_pos_e/n/u [m]."""


def error_series(run: RunData) -> dict[str, ErrorSeries]:
    """Per method its ErrorSeries (errors when the run has truth_shearer)."""
    truth = run.truth.get("truth_shearer")
    out = {}
    for m, table in run.estimates.items():
        rows, t = decimated(table)
        out[m] = ErrorSeries(t, position_errors(rows, truth)[1] if truth is not None else None,
                             columns(rows, "sd_pos"))
    return out


def error_plot(series: dict[str, ErrorSeries], cycles: pa.Table | None, colors: dict[str, tuple]) -> Figure:
    """One row per estimator, one column per axis (east, north, up): the error against time [min] over the
    estimate's own +-N_SIGMA one-sigma band about zero (the band alone without truth), each row on its own scale, with
    the share of samples inside the band; cycle boundaries dotted."""
    fig = Figure(figsize=(13, 1.2 + 1.7 * len(series)), layout="constrained")
    axes = fig.subplots(len(series), 3, sharex=True, sharey="row", squeeze=False)
    for j, (row, (m, one)) in enumerate(zip(axes, series.items())):
        t_min = one.t / 60
        band_m = N_SIGMA * one.sd_enu
        for k, ax in enumerate(row):
            ax.fill_between(t_min, -band_m[:, k], band_m[:, k], color=colors[m], alpha=0.25, linewidth=0)
            if one.err_enu is not None:
                ax.plot(t_min, one.err_enu[:, k], color=colors[m], linewidth=0.8)
                inside = (f"{np.mean(np.abs(one.err_enu[:, k]) <= band_m[:, k]):.0%} inside"
                          if np.isfinite(band_m[:, k]).any() else "no one-sigma")
                ax.text(0.99, 0.95, inside, transform=ax.transAxes, ha="right", va="top", fontsize=8,
                        bbox={"facecolor": "white", "alpha": 0.7, "linewidth": 0})
            ax.axhline(0, color="0.5", linewidth=0.6)
            ax.grid(alpha=0.3)
            cycle_lines(ax, cycles, labelled=j == 0)
        reach = [np.abs(v) for v in (band_m, one.err_enu) if v is not None and np.isfinite(v).any()]
        lim = max((float(np.nanpercentile(v, 99.5)) for v in reach), default=1.0) * 1.15
        row[0].set_ylim(-lim, lim)
        row[0].set_ylabel(f"{m}\n[m]")
    for ax, axis in zip(axes[0], ("east", "north", "up")):
        ax.set_title(axis, pad=14)
    for ax in axes[-1]:
        ax.set_xlabel("t [min]")
    fig.legend([Patch(color="0.5", alpha=0.35, linewidth=0), Line2D([], [], color="0.2", linewidth=0.8)],
               [f"±{N_SIGMA}σ: the estimate's own one-sigma (sd_pos_e/n/u)", "error (estimate - truth)"],
               loc="outside upper left", fontsize=8, ncols=2)
    return fig


def method_stats(run: RunData) -> dict[str, list[dict]]:
    """Per method the rows of estimators.io.metrics.cycle_metrics (each cutting cycle, then "all"): from
    metrics.json, else recomputed against the truth; methods with neither (no truth) are left out."""
    stats = {}
    recorded = run.metrics.get("estimators", {})
    for m, table in run.estimates.items():
        if "cycles" in recorded.get(m, {}):
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
    axes[-1].set_xticks(cycles, [cycle_label(c) for c in cycles])
    axes[-1].set_xlabel("cutting cycle")
    outside_legend(fig, axes[0])
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
        cycle_lines(ax, cycles)
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
    labels = ["installed"] + [f"after {cycle_label(c)}" for c in column(truth_cycles, "cycle").astype(int)]
    return labels, along_m - along_m[:, :1], np.einsum("cpk,ck->cp", d_en, wall_en)


def pan_line_plot(labels: list[str], along_m: np.ndarray, lateral_m: np.ndarray) -> Figure:
    """Lateral deviation [mm] of each pan from its line's best fit, one line per cycle."""
    fig = Figure(figsize=(13, 5), layout="constrained")
    ax = fig.subplots()
    viridis = colormaps["viridis"](np.linspace(0, 0.9, len(labels)))
    step = -(-len(labels) // LEGEND_ENTRIES)
    for k, (label, a, lat, c) in enumerate(zip(labels, along_m, lateral_m, viridis)):
        named = k % step == 0 or k == len(labels) - 1
        ax.plot(a, lat * 1e3, ".-", color=c, markersize=3, linewidth=1, label=label if named else "_nolegend_")
    ax.axhline(0, color="0.5", linewidth=0.8)
    ax.set_xlabel("along the face from the headgate [m]")
    ax.set_ylabel("lateral deviation, + towards the coal wall [mm]")
    ax.grid(alpha=0.3)
    outside_legend(fig, ax)
    return fig


def pressure_plot(pressure: pa.Table, cycles: pa.Table | None, set_mpa: float | None, yield_mpa: float | None
                  ) -> Figure:
    """The supports' leg and ram pressure readings against time: the face's median, its 5-95 % band, the lowest leg
    and the highest ram (a support that failed to set or leaks, a stalled ram), with the set and yield pressures."""
    t, support = column(pressure, "t"), column(pressure, "support").astype(int)
    times, inverse = np.unique(t, return_inverse=True)
    fig = Figure(figsize=(13, 6), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    for ax, name, label in zip(axes, ("leg", "ram"), ("legs", "push ram")):
        grid = np.full((times.size, support.max() + 1), np.nan)
        grid[inverse, support] = column(pressure, name)
        rows = np.isfinite(grid).any(axis=1)
        tm, g = times[rows] / 60, grid[rows]
        lo, med, hi = np.nanpercentile(g, [5, 50, 95], axis=1)
        ax.fill_between(tm, lo, hi, color="C0", alpha=0.25, linewidth=0, label="5-95 % of the supports")
        ax.plot(tm, med, color="C0", linewidth=1, label="median")
        extreme = np.nanmin(g, axis=1) if name == "leg" else np.nanmax(g, axis=1)
        ax.plot(tm, extreme, color="C3", linewidth=0.8, label="lowest" if name == "leg" else "highest")
        if name == "leg":
            for value, what in ((set_mpa, "set"), (yield_mpa, "yield")):
                if value is not None:
                    ax.axhline(value, color="0.4", linestyle="--", linewidth=0.8)
                    ax.annotate(what, (tm[0], value), fontsize=8, va="bottom")
        cycle_lines(ax, cycles)
        ax.set_ylabel(f"{label} [MPa]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("t [min]")
    return fig


def support_grid(t: np.ndarray, support: np.ndarray, value: np.ndarray, n_bins: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """(edges [s] (B + 1,), grid (S, B)): readings binned in time, the mean of each support's readings in each of
    at most n_bins equal bins (NaN where it has none)."""
    n_sup = int(support.max()) + 1
    n_bins = max(min(n_bins, np.unique(t).size), 1)
    edges = np.linspace(t.min(), t.max(), n_bins + 1)
    cell = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n_bins - 1) + n_bins * support
    count = np.bincount(cell, minlength=n_sup * n_bins)
    with np.errstate(invalid="ignore"):
        grid = np.bincount(cell, value, minlength=n_sup * n_bins) / count
    return edges, grid.reshape(n_sup, n_bins)


def support_plot(streams: dict[str, tuple[pa.Table, str, str, str]], cycles: pa.Table | None) -> Figure:
    """Heat maps support x time [min], one per reading: `streams` maps a title to (table, value column, valid
    column, colour bar label); readings flagged invalid are left out; the colours span the readings' 5th percentile
    (below: the darkest, a lowered leg, a closed ram) to their largest."""
    fig = Figure(figsize=(13, 0.8 + 2.6 * len(streams)), layout="constrained")
    axes = fig.subplots(len(streams), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (title, (table, name, valid, label)) in zip(axes, streams.items()):
        ok = column(table, valid) > 0
        support = column(table, "support").astype(int)[ok]
        edges, grid = support_grid(column(table, "t")[ok], support, column(table, name)[ok], SUPPORT_COLUMNS)
        image = ax.imshow(grid, aspect="auto", origin="lower", interpolation="nearest", cmap="viridis",
                          vmin=np.nanpercentile(grid, 5), extent=(edges[0] / 60, edges[-1] / 60, -0.5,
                                                                  grid.shape[0] - 0.5))
        fig.colorbar(image, ax=ax, label=label, extend="min")
        cycle_lines(ax, cycles)
        ax.set_xlim(edges[0] / 60, edges[-1] / 60)
        ax.set_title(title, loc="left", fontsize=10, pad=12)
        ax.set_ylabel("support (0: headgate)")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    axes[-1].set_xlabel("t [min]")
    return fig


def face_line_plot(truth_pans: pa.Table, truth_cycles: pa.Table, azimuth_rad: float,
                   alignment: pa.Table | None) -> Figure:
    """The face line at the end of each cycle (estimators.face.straightness): straightness RMS and max, creep; and,
    when the log has them, the offsets each cycle's push applied per support (mm, towards the coal wall)."""
    pans = {name: column(truth_pans, name) for name in ("t", "pan", "p_t_e", "p_t_n", "p_t_u")}
    n_pans = int(pans["pan"].max()) + 1
    drift = face_drift(pans, column(truth_cycles, "t_end"), n_pans, azimuth_rad)
    cycle = column(truth_cycles, "cycle")
    fig = Figure(figsize=(13, 7 if alignment is not None else 4), layout="constrained")
    axes = fig.subplots(2 if alignment is not None else 1, 1, squeeze=False)[:, 0]
    ax = axes[0]
    ax.plot(cycle, drift.straightness_rms * 1e3, "o-", color="C0", markersize=3, label="straightness RMS")
    ax.plot(cycle, drift.straightness_max * 1e3, "s--", color="C0", markersize=3, alpha=0.6, label="straightness max")
    ax.set_xlabel("cutting cycle (at its end)")
    cycle_axis(ax.xaxis)
    ax.set_ylabel("deviation from the best-fit line [mm]")
    creep = ax.twinx()
    creep.plot(cycle, drift.creep * 1e3, "^-", color="C3", markersize=3, label="creep (mean pan)")
    creep.set_ylabel("creep, + towards the tailgate [mm]", color="C3")
    ax.grid(alpha=0.3)
    fig.legend(fontsize=8, loc="outside upper right", ncols=3)
    if alignment is not None:
        grid = np.zeros((int(column(alignment, "cycle").max()) + 1, int(column(alignment, "support").max()) + 1))
        grid[column(alignment, "cycle").astype(int), column(alignment, "support").astype(int)] = (
            column(alignment, "offset") * 1e3)
        lim = max(float(np.abs(grid).max()), 1.0)
        image = axes[1].imshow(grid, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest",
                               extent=(-0.5, grid.shape[1] - 0.5, grid.shape[0] - 0.5, -0.5))
        axes[1].set_xlabel("support (from the headgate)")
        axes[1].set_ylabel("cutting cycle")
        cycle_axis(axes[1].yaxis)
        fig.colorbar(image, ax=axes[1], label="push offset [mm]")
    return fig
