"""The plan view in the face frame F: along the face (F's y) across the page, towards the coal wall (F's x) up the page,
the lateral scale exaggerated PLAN_SCALE times, so that centimetres of path and pan-line error show on a face of a
hundred metres.

The lateral coordinate is measured from one web depth a cycle (x_F - cycle * web depth, the cycle in progress at the
sample's time): each cycle's pan line and paths stay in the frame however far the face has advanced. A 2-D view draws
its y axis downwards, so the plotted y is -PLAN_SCALE times the lateral coordinate.

Entities (LineStrips2D unless said):

* `plan/axes`                     static Arrows2D: along the face, and PLAN_LATERAL_ARROW_M towards the coal wall, labelled
                                  with the scale
* `plan/pans`                     the pan line (the pans' running-line centres) at every pan-update time
* `plan/target`                   face alignment runs: the straight line through the pan line at the start and at each
                                  cycle's end, the alignment's target (estimators.face.alignment)
* `plan/truth/path`               the true shearer path of the cycle in progress (one strip per cycle, at its start);
                                  `plan/truth/position` Points2D
* `plan/estimates/METHOD/path`    an estimated path (estimates.rrd), the same way; `.../position` Points2D
"""

from __future__ import annotations

import numpy as np
import rerun as rr

from estimators.face.straightness import mat_ft, pan_lines
from twin.config.scenario import Scenario
from twin.view.rerun_columns import RowBatches, time_column
from twin.view.row_cuts import PathStrips

PLAN_SCALE = 20.0
"""Exaggeration of the plan view's lateral (towards the coal wall) scale."""
PLAN_LATERAL_ARROW_M = 0.5
"""True length of the plan view's lateral scale arrow [m]."""
PLAN_ROOT = "plan"
PLAN_NAME = f"Plan in the face frame: along the face [m], towards the coal wall x{PLAN_SCALE:g}"


def cycle_of(t: np.ndarray, cycle_starts: np.ndarray | None) -> np.ndarray:
    """The cycle in progress at each time (the last of the sorted start times at or before it; 0 without starts)."""
    if cycle_starts is None or len(cycle_starts) == 0:
        return np.zeros(np.shape(t), np.int64)
    return np.clip(np.searchsorted(np.asarray(cycle_starts, float), t, side="right") - 1, 0, None)


def face_coordinates(scn: Scenario, p_t: np.ndarray, cycle: np.ndarray) -> np.ndarray:
    """Points in t (..., 3) as (along the face, lateral from cycle * web depth, 0) [m] (module docstring)."""
    return _from_face(scn, np.asarray(p_t, float) @ mat_ft(np.radians(scn.face.azimuth_deg)).T, cycle)


def _from_face(scn: Scenario, p_f: np.ndarray, cycle: np.ndarray) -> np.ndarray:
    return np.stack([p_f[..., 1], p_f[..., 0] - scn.face.web_depth_m * cycle, np.zeros(p_f.shape[:-1])], axis=-1)


def plotted(face: np.ndarray) -> np.ndarray:
    """face_coordinates (..., 3) as the plan view's 2-D points (..., 2), float32."""
    return np.stack([face[..., 0], -PLAN_SCALE * face[..., 1]], axis=-1).astype(np.float32)


def plan_bounds(scn: Scenario) -> tuple[list[float], list[float]]:
    """The plan view's x and y ranges: the face's length, and from half a web behind the cycle's pan line to one and a
    half ahead (the sump into the next web, the cut) in plotted units."""
    length, web = scn.face.pan_count * scn.face.pan_length_m, scn.face.web_depth_m
    margin = 0.03 * length
    return [-margin, length + margin], [-PLAN_SCALE * 1.5 * web, PLAN_SCALE * 0.5 * web]


def bounds_of(points: np.ndarray) -> tuple[list[float], list[float]]:
    """x and y ranges of plotted points (K, 2), with a margin."""
    lo, hi = np.nanmin(points, axis=0), np.nanmax(points, axis=0)
    pad = 0.05 * (hi - lo) + 1.0
    return [float(lo[0] - pad[0]), float(hi[0] + pad[0])], [float(lo[1] - pad[1]), float(hi[1] + pad[1])]


def log_axes(rec: rr.RecordingStream, scn: Scenario) -> None:
    """The scale arrows, below the face's start: along the face, and PLAN_LATERAL_ARROW_M towards the coal wall."""
    length, below = scn.face.pan_count * scn.face.pan_length_m, 0.4 * PLAN_SCALE * scn.face.web_depth_m
    rec.log(f"{PLAN_ROOT}/axes", rr.Arrows2D(
        origins=[[0.0, below], [0.35 * length, below]],
        vectors=[[0.25 * length, 0.0], [0.0, -PLAN_SCALE * PLAN_LATERAL_ARROW_M]],
        labels=["along the face, to the tailgate", f"{PLAN_LATERAL_ARROW_M:g} m towards the coal wall "
                                                   f"(x{PLAN_SCALE:g})"],
        colors=[[200, 200, 200], [200, 200, 200]], show_labels=True), static=True)


def send_pan_line(rec: rr.RecordingStream, scn: Scenario, times: np.ndarray, p_t: np.ndarray,
                  cycle_starts: np.ndarray | None, static: bool = True) -> None:
    """The pan line (pans' origins p_t (T, N, 3) in t) at each of `times`; `static` False for the later chunks of a
    history sent in several (its look was logged with the first)."""
    strips = plotted(face_coordinates(scn, p_t, cycle_of(times, cycle_starts)[:, None]))
    if static:
        rec.log(f"{PLAN_ROOT}/pans", rr.LineStrips2D.from_fields(radii=0.15, colors=[150, 150, 160]), static=True)
    rec.send_columns(f"{PLAN_ROOT}/pans", indexes=[time_column(times)],
                     columns=rr.LineStrips2D.columns(strips=strips).partition(np.ones(times.size, np.int64)))


def send_target_line(rec: rr.RecordingStream, scn: Scenario, pans: dict[str, np.ndarray], times: np.ndarray,
                     cycle_starts: np.ndarray) -> None:
    """The straight line through the pan line (least squares, x on y) at each of `times`, from the first pan to the
    last (truth_pans columns t, pan, p_t_e/n/u)."""
    n_pans = int(pans["pan"].max()) + 1
    lines = pan_lines(pans, times, n_pans, np.radians(scn.face.azimuth_deg))  # (T, N, 3) in F
    ends_f = np.zeros((times.size, 2, 3))
    for k, line in enumerate(lines):  # one least-squares fit per time (a handful: start and cycle ends)
        ok = np.isfinite(line[:, 0])
        slope, intercept = np.polyfit(line[ok, 1], line[ok, 0], 1)
        ends_f[k, :, 1] = line[ok, 1][[0, -1]]
        ends_f[k, :, 0] = intercept + slope * ends_f[k, :, 1]
    strips = plotted(_from_face(scn, ends_f, cycle_of(times, cycle_starts)[:, None]))
    rec.log(f"{PLAN_ROOT}/target", rr.LineStrips2D.from_fields(radii=0.2, colors=[90, 220, 120]), static=True)
    rec.send_columns(f"{PLAN_ROOT}/target", indexes=[time_column(times)],
                     columns=rr.LineStrips2D.columns(strips=strips).partition(np.ones(times.size, np.int64)))


def log_path(rec: rr.RecordingStream, entity: str, path: PathStrips, color) -> None:
    """A shearer path as `entity/path`: `path` holds its face_coordinates, one strip per cycle without the samples it
    passes within PATH_TOLERANCE_M of (every sample at FULL rate; twin.view.row_cuts.PathStrips), each logged at
    its cycle's first sample (the plan shows the cycle in progress)."""
    strips = [plotted(s) for s in path.strips()]
    rec.log(f"{entity}/path", rr.LineStrips2D.from_fields(radii=0.12, colors=color), static=True)
    rec.send_columns(f"{entity}/path", indexes=[time_column(path.start_times())],
                     columns=rr.LineStrips2D.columns(strips=strips).partition(np.ones(len(strips), np.int64)))


def position_batches(rec: rr.RecordingStream, scn: Scenario, entity: str, color) -> RowBatches:
    """A shearer path's point as `entity/position`: rows (times, points (k, 3) in t, their cycles) sent as the
    plan's points, its look logged first."""
    return RowBatches(
        lambda t, p_t, cycle: rec.send_columns(f"{entity}/position", indexes=[time_column(t)], columns=rr.Points2D.columns(
            positions=plotted(face_coordinates(scn, p_t, cycle)))),
        lambda: rec.log(f"{entity}/position", rr.Points2D.from_fields(radii=0.6, colors=color), static=True))
