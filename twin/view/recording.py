"""The run's Rerun recording: the truth streams as a 3-D replay plus plots, written to one .rrd file.

Everything is logged column-wise with `send_columns` on the duration timeline `sim_time` (seconds from the
scenario start): one call per entity carries its whole history (the pans' and the supports', a call per
CHUNK_GEOMS geoms), with the per-time instance batches given by partition lengths. The Rerun world is the tangent plane t (ENU,
metres, Z up), the frame of the truth tables' `p_t_*` columns.

Entities (fixed names, checked by tests):

* `world/floor`             static Mesh3D of the floor
* `world/pans/{boxes,spheres}`         every pan's geoms of the MJCF piece (trough, rack, feet) at every pan-update
                                        time (twin.view.geometry; the trough's colour: horizontal bend vs limit)
* `world/supports/{boxes,cylinders}`   every support's geoms (base, leg cylinders; canopy, leg columns on the leg
                                        slide) at every support-update time (a lowered support's canopy orange)
* `world/rams`              LineStrips3D, support point to support point + ram * advance direction
* `world/shearer`           Transform3D (t <- body) at the record rate, as either end of the body moves MARKER_STEP_M;
                            static children `boxes` (body, ranging arms), `cylinders` (drums): the MJCF piece's geoms
* `world/shearer_path`      static LineStrips3D of the path, one strip per cycle, within PATH_TOLERANCE_M of every
                            sample (stops and reversals kept)
* `plots/shearer_speed`     Scalars, horizontal ground speed [m/s]
* `plots/cycle`             Scalars, cycle index
* `plots/bend_horizontal_deg`, `plots/bend_vertical_deg`   BarChart per chute at every pan-update time
* `plots/ram_length`        BarChart per support at every support-update time
* `face/pan_line_mm`        BarChart per pan at the run's start and each cycle's end: the pan line's deviation from
                            its best-fit straight line [mm, + towards the coal wall] (estimators.face.straightness)
* `face/straightness_mm`, `face/creep_mm`   Scalars at the same times: straightness RMS and max; creep of the pans'
                            mean and of the tailgate drive frame since the start [mm, + towards the tailgate]
* `plan/...`                the plan view in the face frame: axes, pan line, target line (face alignment runs), true
                            path (twin.view.plan)
* `sensors/...`, `alignment/...`, `faults/...`   the sensor streams (twin.view.sensor_recording)

Time series are cut to what a person can see at the record rate (twin.view.visible_cut.visible_rows; every sample
at FULL rate).
"""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.chunk import RrdReader

from estimators.face.straightness import face_drift, line_deviation, pan_lines
from estimators.nav.earth import mat_en
from estimators.nav.rotations import mat_to_quat, quat_mul, quat_rotate
from twin.config.scenario import Scenario
from twin.face.model import piece_model
from twin.view import plan
from twin.view.geometry import BodyGeoms, body_geoms, log_body, send_bodies
from twin.view.record_rate import FULL, RECORD_RATE_HZ, check_record_rate
from twin.view.rerun_columns import (
    PlottedSeries,
    RowBatches,
    SeriesBlock,
    latest_frames,
    send_bar_chart,
    series,
    time_column,
    vec,
    xyzw,
)
from twin.view.row_cuts import Blocks, MarkerCut, PathStrips, blocks_of, bounded, col, decimated_blocks
from twin.view.rrd_stream import recording_id, recording_stream
from twin.view.sensor_recording import log_sensors

RUN_RRD = "run.rrd"
ESTIMATES_RRD = "estimates.rrd"
"""The estimators' recording beside run.rrd: same application and recording id, so the viewer merges the two."""

TRUTH_RGB = np.array([240, 120, 40], np.uint8)
"""Colour of the true shearer path (3-D and plan)."""
SUPPORT_FRAME_HZ = 1.0
"""Most support states a second of run time in the recording: a ram at 0.1-0.3 m/s moves 0.1-0.3 m between two."""
CHUNK_GEOMS = 250_000
"""Geoms (each geom of a pan's or a support's bodies at one frame) built and sent at a time: the pans' and supports'
part of the recording's memory is a chunk's, about 130-170 bytes a geom at its peak (40 MB), whatever the run's
length; 200 frames of a face of 200 supports."""
_GREY = np.array([150, 150, 150], float)
_RED = np.array([230, 30, 30], float)
_LOWERED_RGBA = np.array([240, 160, 40, 255], np.uint8)


def _advance_axis(scn: Scenario) -> np.ndarray:
    a = np.radians(scn.face.azimuth_deg)
    return np.array([np.cos(a), -np.sin(a), 0.0])


def _face_quat_wxyz(scn: Scenario) -> np.ndarray:
    """Rotation of the face frame F in t: about z by -azimuth."""
    half = -0.5 * np.radians(scn.face.azimuth_deg)
    return np.array([np.cos(half), 0.0, 0.0, np.sin(half)])


# --------------------------------------------------------------------------------------------------------------
# Entities


def _log_floor(rec: rr.RecordingStream, floor_mesh: tuple[np.ndarray, np.ndarray]) -> None:
    vertices = np.asarray(floor_mesh[0], float)
    triangles = np.asarray(floor_mesh[1], np.int64)
    # Area-weighted vertex normals.
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    face_n = np.cross(b - a, c - a)
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, triangles[:, k], face_n)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    z = vertices[:, 2]
    span = max(float(np.ptp(z)), 1e-6) if z.size else 1.0
    s = ((z - z.min()) / span)[:, None] if z.size else np.zeros((0, 1))
    colors = ((1 - s) * np.array([90, 80, 70]) + s * np.array([170, 160, 140])).astype(np.uint8)
    rec.log("world/floor", rr.Mesh3D(vertex_positions=vertices.astype(np.float32),
                                     triangle_indices=triangles.astype(np.uint32),
                                     vertex_normals=normals.astype(np.float32), vertex_colors=colors),
            static=True)


def _log_pans(rec: rr.RecordingStream, scn: Scenario, pans: pa.Table, cycles: pa.Table | None,
              pan: BodyGeoms) -> None:
    """Every pan's geoms (the MJCF piece's) at each pan-update time, the trough coloured by its horizontal bend against
    the limit (grey to red), the bend per chute, and the pan line in the plan view; built and sent CHUNK_GEOMS geoms
    at a time."""
    names = ("p_t_e", "p_t_n", "p_t_u", "q_tp_w", "q_tp_x", "q_tp_y", "q_tp_z", "bend_h", "bend_v")
    limit = np.radians(scn.face.bend_limit_horizontal_deg)
    for k, (times, state) in enumerate(latest_frames(pans, "pan", names, FULL, CHUNK_GEOMS // len(pan))):
        n_t, n_p = state["bend_h"].shape
        p = np.stack([state[f"p_t_{a}"] for a in "enu"], axis=-1)  # (n_t, n_p, 3)
        q = np.stack([state[f"q_tp_{a}"] for a in "wxyz"], axis=-1)  # (n_t, n_p, 4)
        ratio = np.clip(np.nan_to_num(np.abs(state["bend_h"]), nan=0.0) / limit, 0.0, 1.0)[..., None]
        colors = np.array(np.broadcast_to(pan.rgba, (n_t, n_p, len(pan), 4)))
        colors[:, :, pan.index("trough"), :3] = ((1 - ratio) * _GREY + ratio * _RED).astype(np.uint8)
        send_bodies(rec, "world/pans", times, [(pan, p, q)], colors, static=k == 0)
        plan.send_pan_line(rec, scn, times, p, _cycle_starts(cycles), static=k == 0)
        if n_p > 1:  # per-chute bends: the last pan dropped (no next pan, NaN)
            for bend, entity in (("bend_h", "plots/bend_horizontal_deg"), ("bend_v", "plots/bend_vertical_deg")):
                send_bar_chart(rec, entity, times, np.nan_to_num(np.degrees(state[bend][:, :-1]), nan=0.0))


def _cycle_starts(cycles: pa.Table | None) -> np.ndarray | None:
    return None if cycles is None or cycles.num_rows == 0 else col(cycles, "t")


def _log_supports(rec: rr.RecordingStream, scn: Scenario, supports: Blocks, rate_hz: float | None,
                  base: BodyGeoms, canopy_body: BodyGeoms) -> None:
    """Every support's geoms (the MJCF piece's base and canopy bodies; a lowered support's canopy in orange) and ram at
    each time one changes, at most SUPPORT_FRAME_HZ (the last state of each interval, so that an event's end shows at
    once; every time at FULL rate), built and sent CHUNK_GEOMS geoms at a time."""
    frame_hz = rate_hz if rate_hz is FULL else min(rate_hz, SUPPORT_FRAME_HZ)
    x_t = _advance_axis(scn)
    chunks = latest_frames(supports, "support", SUPPORT_COLUMNS[2:], frame_hz,
                           CHUNK_GEOMS // (len(base) + len(canopy_body)))
    for k, (times, state) in enumerate(chunks):
        n_t, n_s = state["ram"].shape
        p = np.stack([state["p_t_e"], state["p_t_n"], state["p_t_u"]], axis=-1)  # (n_t, n_s, 3) ram connection
        ram, is_set = state["ram"], state["set"] != 0

        # The support body stands in F; its canopy body rides the leg slide (z) from its place on the base.
        q_tf = np.broadcast_to(_face_quat_wxyz(scn), (n_t, n_s, 4))
        canopy_f = canopy_body.body_pos + state["canopy"][..., None] * np.array([0.0, 0.0, 1.0])
        p_canopy = p + quat_rotate(q_tf, canopy_f)
        colors = np.array(np.broadcast_to(np.concatenate([base.rgba, canopy_body.rgba]),
                                          (n_t, n_s, len(base) + len(canopy_body), 4)))
        colors[~is_set, len(base) + canopy_body.index("canopy")] = _LOWERED_RGBA
        send_bodies(rec, "world/supports", times, [(base, p, q_tf), (canopy_body, p_canopy, q_tf)], colors,
                    static=k == 0)
        lengths = np.full(n_t, n_s)
        strips = np.stack([p, p + ram[..., None] * x_t], axis=2)  # (n_t, n_s, 2, 3)
        rec.send_columns(
            "world/rams",
            indexes=[time_column(times)],
            columns=rr.LineStrips3D.columns(strips=strips.reshape(-1, 2, 3).astype(np.float32)).partition(lengths),
        )
        if k == 0:
            rec.log("world/rams", rr.LineStrips3D.from_fields(radii=0.05, colors=[200, 200, 60]), static=True)
        send_bar_chart(rec, "plots/ram_length", times, ram)


SHEARER_COLUMNS = ("t", "lat", "lon", "p_t_e", "p_t_n", "p_t_u", "q_nb_w", "q_nb_x", "q_nb_y", "q_nb_z", "v_n_e", "v_n_n",
                   "cycle")
"""The truth_shearer columns the recording draws (a run reads only these back from its Parquet)."""
SUPPORT_COLUMNS = ("t", "support", "p_t_e", "p_t_n", "p_t_u", "ram", "canopy", "set")
"""The truth_supports columns the recording draws."""
STREAM_COLUMNS = {"truth_shearer": SHEARER_COLUMNS, "truth_supports": SUPPORT_COLUMNS}
"""The columns a run reads back of the streams the recording draws only some of."""
BLOCK_STREAMS = ("truth_shearer", "truth_supports", "imu", "odometer", "mag", "pushram", "pressure")
"""The streams write_recording takes in blocks (a run reads them back a row group at a time)."""


def _log_shearer(rec: rr.RecordingStream, scn: Scenario, shearer: Blocks, rate_hz: float | None,
                 body: BodyGeoms) -> None:
    """The shearer's geoms (the MJCF piece's, static in its body frame) under its pose, its path (3-D and plan) and
    speed, from its stream read twice a block at a time: first its record-rate rows turned into poses (those logged
    sent SEND_ROWS at a time), the path and the plots' ranges, then the plots cut and sent."""
    log_body(rec, "world/shearer", body)
    if not any(block.num_rows for block in blocks_of(shearer)):
        return
    path, plan_path = PathStrips(rate_hz), PathStrips(rate_hz)  # the whole path, at every sample

    def draw_path(block: pa.Table) -> None:
        t, p, cycle = col(block, "t"), vec(block, "p_t"), col(block, "cycle")
        path.push(t, p, cycle)
        plan_path.push(t, plan.face_coordinates(scn, p, cycle), cycle)

    # n (ENU at the shearer) to t (ENU at the site origin): C_n^t = (C_t^e)^T C_n^e.
    c_te = mat_en(np.radians(scn.site.lat_deg), np.radians(scn.site.lon_deg))
    half_length = np.array([0.0, 0.5 * scn.shearer.length_m, 0.0])
    markers, pushed, last = MarkerCut(rate_hz), [0], []
    poses = RowBatches(lambda t, p, q: rec.send_columns(
        "world/shearer", indexes=[time_column(t)],
        columns=rr.Transform3D.columns(translation=p.astype(np.float32), quaternion=xyzw(q))))
    plan_points = plan.position_batches(rec, scn, f"{plan.PLAN_ROOT}/truth", TRUTH_RGB)

    def draw_poses(sub: pa.Table) -> None:
        """The record-rate rows' poses, those logged as either end of the drawn body moves MARKER_STEP_M (travel or
        turn)."""
        t, p, cycle = col(sub, "t"), vec(sub, "p_t"), col(sub, "cycle")
        c_nt = np.swapaxes(c_te, -1, -2) @ mat_en(col(sub, "lat"), col(sub, "lon"))
        q_tb = quat_mul(mat_to_quat(c_nt), vec(sub, "q_nb", "wxyz"))
        half = quat_rotate(q_tb, half_length)
        kept = markers.push(t, np.hstack([p - half, p + half])) - pushed[0]
        poses.add(t[kept], p[kept], q_tb[kept])
        plan_points.add(t[kept], p[kept], cycle[kept])
        pushed[0] += t.size
        last[:] = [t[-1:], p[-1:], q_tb[-1:], cycle[-1:]]

    def blocks() -> Iterator[SeriesBlock]:
        for sub in decimated_blocks(bounded(shearer), rate_hz, draw_path):
            if sub.num_rows:
                draw_poses(sub)
            t = col(sub, "t")
            yield {"plots/shearer_speed": (t, np.hypot(col(sub, "v_n_e"), col(sub, "v_n_n"))[:, None]),
                   "plots/cycle": (t, col(sub, "cycle").astype(float)[:, None])}

    plots = PlottedSeries({"plots/shearer_speed": ["horizontal speed [m/s]"], "plots/cycle": ["cycle"]}, rate_hz,
                          ["plots/cycle"])
    plots.measure(blocks())
    if markers.finish().size:  # the last row, unless kept
        poses.add(*last[:3])
        plan_points.add(last[0], last[1], last[3])
    poses.flush()
    rec.log("world/shearer_path", rr.LineStrips3D(path.strips(), radii=0.03, colors=TRUTH_RGB), static=True)
    plan.log_path(rec, f"{plan.PLAN_ROOT}/truth", plan_path, TRUTH_RGB)
    plan_points.flush()
    plots.send(rec)


def _log_face_line(rec: rr.RecordingStream, scn: Scenario, pans: pa.Table, cycles: pa.Table) -> None:
    """The pan line at the start and at each cycle's end (truth_cycles' t_end) as its deviation per pan from its
    best-fit straight line (the straightness metric's reference, and the face alignment's straight target, drawn in
    the plan view of a face alignment run), with straightness and creep at those times
    (estimators.face.straightness)."""
    columns = {name: col(pans, name) for name in ("t", "pan", "p_t_e", "p_t_n", "p_t_u")}
    times = np.concatenate([[float(columns["t"].min())], col(cycles, "t_end")])
    n_pans, azimuth = int(columns["pan"].max()) + 1, np.radians(scn.face.azimuth_deg)
    lines = pan_lines(columns, times, n_pans, azimuth)
    send_bar_chart(rec, "face/pan_line_mm", times, line_deviation(lines[..., 0], lines[..., 1]) * 1e3)
    if scn.alignment.mode != "none":
        plan.send_target_line(rec, scn, columns, times, col(cycles, "t"))
    drift = face_drift(columns, times, n_pans, azimuth)
    series(rec, "face/straightness_mm", times, np.column_stack([drift.straightness_rms, drift.straightness_max]) * 1e3,
           ["straightness RMS", "straightness max"])
    series(rec, "face/creep_mm", times, np.column_stack([drift.creep, drift.creep_tailgate]) * 1e3,
           ["creep, mean pan", "creep, tailgate drive frame"])


# --------------------------------------------------------------------------------------------------------------
# Public API


def write_recording(path: Path, scn: Scenario, truth: dict[str, Blocks],
                    floor_mesh: tuple[np.ndarray, np.ndarray], rate_hz: float | None = RECORD_RATE_HZ,
                    sensors: dict[str, Blocks] | None = None) -> None:
    """Write the truth streams of a run as a Rerun recording (.rrd) with its blueprint, reproducibly
    (twin.view.rrd_stream: the recording id from the scenario and seed).

    `truth` maps "truth_shearer", "truth_pans", "truth_supports" (required) and "truth_cycles" (optional: the
    face line at each cycle's end) to tables with the columns of `estimators.io.logformat` (truth_shearer and
    truth_supports may come in blocks: twin.view.row_cuts.Blocks; so may the `sensors` of BLOCK_STREAMS).
    `floor_mesh` is (vertices (V, 3) in t, triangle indices (T, 3)). `rate_hz` is the record rate
    (twin.view.rerun_columns: Hz, or FULL for every sample) of the shearer and the time series.
    """
    missing = [k for k in ("truth_shearer", "truth_pans", "truth_supports") if k not in truth]
    if missing:
        raise KeyError(f"write_recording: missing truth streams {', '.join(missing)}")
    rate_hz = check_record_rate(rate_hz)
    with recording_stream(path, recording_id(scn)) as rec:
        rec.send_recording_name(scn.name)
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        _log_floor(rec, floor_mesh)
        plan.log_axes(rec, scn)
        cycles = truth.get("truth_cycles")
        support = piece_model(scn, "support")
        _log_pans(rec, scn, truth["truth_pans"], cycles, body_geoms(piece_model(scn, "pan"), "pan"))
        _log_supports(rec, scn, truth["truth_supports"], rate_hz, body_geoms(support, "support"),
                      body_geoms(support, "canopy"))
        _log_shearer(rec, scn, truth["truth_shearer"], rate_hz, body_geoms(piece_model(scn, "shearer"), "shearer"))
        if cycles is not None and cycles.num_rows:
            _log_face_line(rec, scn, truth["truth_pans"], cycles)
        log_sensors(rec, sensors or {}, rate_hz)


def run_recording_id(run_dir: Path) -> str | None:
    """The recording id of `run_dir/run.rrd` (None without a readable one): recordings written beside it with
    this id and APPLICATION_ID merge with it in the viewer."""
    rrd = Path(run_dir) / RUN_RRD
    try:
        with warnings.catch_warnings():  # our recordings have no footer, on purpose (twin.view.rrd_stream)
            warnings.simplefilter("ignore")
            recordings = RrdReader(rrd).recordings() if rrd.is_file() else []
    except (OSError, ValueError, RuntimeError):
        return None
    return recordings[0].recording_id if recordings else None
