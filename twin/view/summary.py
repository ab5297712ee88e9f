"""Run summaries: the face and shearer facts a mining engineer checks after a run, as a dict and a table."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from estimators.face.straightness import face_drift
from estimators.io.metrics import cycle_label
from twin.config.scenario import Scenario


def latest_per_id(t: np.ndarray, ident: np.ndarray, n: int, t_max: float) -> np.ndarray:
    """Row index of the latest row of each id 0..n-1 at or before t_max (rows sorted by time); -1 if none."""
    rows = np.flatnonzero(t <= t_max)
    out = np.full(n, -1)
    out[ident[rows]] = rows  # later rows overwrite earlier ones
    return out


class LatestAt:
    """Each id's latest value at or before each of the (increasing) times `t_at`, from rows given in blocks in time
    order (`add`): latest_per_id over the whole table, one block held at a time. `finish` gives the values
    (len(t_at), n), NaN for an id with no row by then."""

    def __init__(self, t_at: np.ndarray, n: int):
        self.t_at = np.asarray(t_at, float)
        self.values = np.full((self.t_at.size, n), np.nan)
        self.current = np.full(n, np.nan)
        self.done = 0  # times whose values are final

    def add(self, t: np.ndarray, ident: np.ndarray, value: np.ndarray) -> None:
        while self.done < self.t_at.size:
            upto = int(np.searchsorted(t, self.t_at[self.done], side="right"))
            if upto == t.size:
                break  # a later block may still hold rows at or before this time
            self.values[self.done] = self.current
            self.values[self.done][ident[:upto]] = value[:upto]  # later rows overwrite earlier ones
            self.done += 1
        self.current[ident] = value

    def finish(self) -> np.ndarray:
        self.values[self.done:] = self.current
        self.done = self.t_at.size
        return self.values


@dataclass
class ShearerStats:
    """What the summary says of the shearer's truth, gathered chunk by chunk as a run streams (`update`)."""

    samples: int = 0
    t_last: float = 0.0
    max_speed_m_s: float = 0.0

    def update(self, rows: dict[str, np.ndarray]) -> None:
        self.samples += rows["t"].size
        self.t_last = float(rows["t"][-1])
        self.max_speed_m_s = max(self.max_speed_m_s, float(np.hypot(rows["v_n_e"], rows["v_n_n"]).max()))


def twin_summary(scn: Scenario, tables: dict[str, dict[str, np.ndarray]], shearer: ShearerStats,
                 support_advance: np.ndarray, offsets_m: np.ndarray | None = None, sequences: list[int] | None = None,
                 path_errors: list[dict[str, float]] | None = None) -> dict:
    """The run's summary (metrics.json "twin") from the face's truth tables (pans and cycles), each support's advance
    at each cycle's end (`support_advance`, cycles x supports: LatestAt) and the shearer's statistics: per cycle
    the pans' and supports' advance errors, the face line's straightness (RMS and max deviation from its best-fit
    line) and creep (estimators.face.straightness), the offsets its push applied (`offsets_m`, cycles x supports) and
    the face alignment system's sequence number after its shear (`sequences`, in a closed loop) and, in a loop fed by
    an estimator, the errors of its path over the cycle's shear (`path_errors`: twin.pipeline.alignment_loop's SEP
    and RMS across the face about the best-fit line, what the offsets see)."""
    shear_errors = {e["shear"]: e for e in path_errors or []}
    pans, cycles = tables["truth_pans"], tables["truth_cycles"]
    n_pan = scn.face.pan_count
    duration = shearer.t_last
    line = face_drift(pans, cycles["t_end"], n_pan, np.radians(scn.face.azimuth_deg))
    per_cycle = []
    for k, t_end in enumerate(cycles["t_end"]):
        pan_adv = pans["advance"][latest_per_id(pans["t"], pans["pan"], n_pan, t_end)]
        sup_adv = support_advance[k]
        want = (k + 1) * scn.face.web_depth_m
        per_cycle.append({
            "cycle": k, "t_start_s": float(cycles["t"][k]), "t_end_s": float(t_end),
            "pan_advance_error_max_mm": float(np.abs(pan_adv - want).max() * 1e3),
            "support_advance_error_max_mm": float(np.abs(sup_adv - want).max() * 1e3),
            "straightness_rms_mm": float(line.straightness_rms[k] * 1e3),
            "straightness_max_mm": float(line.straightness_max[k] * 1e3), "creep_mm": float(line.creep[k] * 1e3),
            "offsets_rms_mm": float(np.sqrt(np.mean(offsets_m[k] ** 2)) * 1e3) if offsets_m is not None else 0.0,
            **({"alignment_sequence": int(sequences[k])} if sequences else {}),
            **({"path_sep_mm": shear_errors[k]["sep_m"] * 1e3, "path_across_rms_mm": shear_errors[k]["x_rms_m"] * 1e3}
               if k in shear_errors else {})})
    return {
        "scenario": scn.name, "seed": scn.seed, "simulated_s": duration,
        "shearer_samples": shearer.samples, "pan_updates": int(pans["t"].size),
        "max_bend_horizontal_deg": float(np.degrees(np.nanmax(np.abs(pans["bend_h"])))),
        "max_bend_vertical_deg": float(np.degrees(np.nanmax(np.abs(pans["bend_v"])))),
        "max_speed_m_min": shearer.max_speed_m_s * 60, "alignment": scn.alignment.mode, "cycles": per_cycle}


def format_summary(summary: dict, wall_s: float) -> str:
    """The summary as printed after a run that took `wall_s` seconds (timing.json's figure)."""
    lines = [
        f"scenario {summary['scenario']} (seed {summary['seed']}): {summary['simulated_s'] / 3600:.2f} h simulated "
        f"in {wall_s:.1f} s ({summary['simulated_s'] / max(wall_s, 1e-9):.0f}x real time)",
        f"shearer samples {summary['shearer_samples']:,}, pan updates {summary['pan_updates']:,}, "
        f"max speed {summary['max_speed_m_min']:.1f} m/min",
        f"max bend: horizontal {summary['max_bend_horizontal_deg']:.3f} deg, "
        f"vertical {summary['max_bend_vertical_deg']:.3f} deg",
        "",
        f"{'cycle':>5} {'start [s]':>10} {'end [s]':>10} {'pan adv err [mm]':>17} {'support adv err [mm]':>21}"
        f" {'straightness rms':>17} {'max':>6} {'creep':>7} {'offsets rms':>12}   [mm]",
    ]
    for c in summary["cycles"]:
        lines.append(f"{cycle_label(c['cycle']):>5} {c['t_start_s']:>10.1f} {c['t_end_s']:>10.1f} "
                     f"{c['pan_advance_error_max_mm']:>17.1f} {c['support_advance_error_max_mm']:>21.1f}"
                     f" {c['straightness_rms_mm']:>17.1f} {c['straightness_max_mm']:>6.1f} {c['creep_mm']:>7.1f}"
                     f" {c['offsets_rms_mm']:>12.1f}")
    if summary.get("alignment", "none") != "none":
        lines.append(f"face alignment: {summary['alignment']} path, offsets applied on the next shear")
    scored = [c for c in summary["cycles"] if "path_sep_mm" in c]
    if scored:
        lines.append(f"its path over {len(scored)} shears: SEP median "
                     f"{np.median([c['path_sep_mm'] for c in scored]):.0f} mm, across the face about its best-fit line "
                     f"RMS median {np.median([c['path_across_rms_mm'] for c in scored]):.1f} mm")
    return "\n".join(lines)
