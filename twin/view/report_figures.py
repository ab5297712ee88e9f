"""The report's figures (`longwall report`): top view, errors against time, errors per cycle, fault detectors, pan
line straightness, the face line per cycle and the push offsets, as matplotlib Figures without pyplot (Agg canvas, nothing global to close).

Errors are estimate - truth in metres East/North/Up at the truth point (estimators.io.metrics). Long series are
decimated to about MAX_POINTS samples for plotting.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from estimators.face.straightness import face_drift
from estimators.io.metrics import column, cycle_metrics, position_errors
from estimators.nav import earth
from twin.view.estimate_recording import plot_rows
from twin.view.run_data import RunData
from twin.view.summary import latest_per_id

MAX_POINTS = 4000
"""About the largest number of samples plotted per series."""


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


def colors_for(methods: list[str]) -> dict[str, tuple]:
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
        _cycle_lines(ax, cycles)
        ax.set_ylabel(f"{label} [MPa]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[-1].set_xlabel("t [min]")
    return fig


def face_line_plot(truth_pans: pa.Table, truth_cycles: pa.Table, azimuth_rad: float,
                   alignment: pa.Table | None) -> Figure:
    """The face line at the end of each cycle (estimators.face.straightness): straightness RMS and max, creep; and,
    when the log has them, the offsets each cycle's push applied per support (mm, towards the coal wall)."""
    pans = {name: column(truth_pans, name) for name in ("t", "pan", "p_t_e", "p_t_n", "p_t_u")}
    n_pans = int(pans["pan"].max()) + 1
    drift = face_drift(pans, column(truth_cycles, "t_end"), n_pans, azimuth_rad)
    cycle = np.arange(1, drift.t.size + 1)
    fig = Figure(figsize=(13, 7 if alignment is not None else 4), layout="constrained")
    axes = fig.subplots(2 if alignment is not None else 1, 1, squeeze=False)[:, 0]
    ax = axes[0]
    ax.plot(cycle, drift.straightness_rms * 1e3, "o-", color="C0", markersize=3, label="straightness RMS")
    ax.plot(cycle, drift.straightness_max * 1e3, "s--", color="C0", markersize=3, alpha=0.6, label="straightness max")
    ax.set_xlabel("cutting cycle (at its end)")
    ax.set_ylabel("deviation from the best-fit line [mm]")
    creep = ax.twinx()
    creep.plot(cycle, drift.creep * 1e3, "^-", color="C3", markersize=3, label="creep (mean pan)")
    creep.set_ylabel("creep, + towards the tailgate [mm]", color="C3")
    ax.grid(alpha=0.3)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    fig.legend(fontsize=8, loc="outside upper right", ncols=3)
    if alignment is not None:
        grid = np.zeros((int(column(alignment, "cycle").max()) + 1, int(column(alignment, "support").max()) + 1))
        grid[column(alignment, "cycle").astype(int), column(alignment, "support").astype(int)] = (
            column(alignment, "offset") * 1e3)
        lim = max(float(np.abs(grid).max()), 1.0)
        image = axes[1].imshow(grid, aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim, interpolation="nearest",
                               extent=(-0.5, grid.shape[1] - 0.5, grid.shape[0] + 0.5, 0.5))
        axes[1].set_xlabel("support (from the headgate)")
        axes[1].set_ylabel("cutting cycle")
        axes[1].yaxis.set_major_locator(MaxNLocator(integer=True))
        fig.colorbar(image, ax=axes[1], label="push offset [mm]")
    return fig
