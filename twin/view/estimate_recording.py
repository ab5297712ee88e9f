"""The estimators' Rerun recording: `estimates.rrd` beside a run's `run.rrd`, merged with it by the viewer.

The file carries the application id and the recording id of run.rrd (read from it; the scenario's when the run has
none, e.g. an imported log; written reproducibly by twin.view.rrd_stream), so `longwall view` shows the truth replay and the estimates as one recording, in
the run's layout with a second "Estimates" tab of plots (twin.view.layout). A run without truth (truth_shearer None, e.g.
a real face's log) gets everything but the errors: paths, sigmas, flags, sensor states, fusion, detectors.
Everything is logged column-wise with `send_columns` on the `sim_time` timeline, cut to what a person can see at the
record rate (twin.view.visible_cut.visible_rows: at most the rate, without the samples a plotted line passes within
a pixel of; flags and alarms OR-ed over each interval so a brief one stays; every sample at FULL rate).

Entities, per estimator METHOD (errors as estimators.io.metrics defines them: estimate - truth in East/North/Up at
the truth point; attitude the psi-angle phi, C_b^n(true) = (I + [phi x]) C_b^n(est)):

* `world/estimates/METHOD/path`       static LineStrips3D of the estimated body path in t, one strip per cycle
                                      (one strip without truth), within PATH_TOLERANCE_M of every estimate
* `world/estimates/METHOD/position`   Points3D, the estimated body point in t at the record rate, after each
                                      MARKER_STEP_M of travel
* `plan/estimates/METHOD/{path,position}`  the same in the plan view (twin.view.plan)
* `plots/errors/METHOD/{east,north,up,horizontal}`    Scalars, position error [m]; horizontal: its length in the
                                                      level plane
* `plots/attitude_errors/METHOD/{e,n,u}`              Scalars, attitude error phi [deg]
* `plots/sigma/METHOD/position/{east,north,up}`       Scalars, +- one-sigma of the position [m]
* `plots/sigma/METHOD/attitude/{e,n,u}`               Scalars, +- one-sigma of the attitude [deg]
* `plots/flags/METHOD`                                Scalars 0/1: position fix, ZUPT, skipped measurement in
                                                      each plot interval (estimators.io.logformat FLAG_*)
* `plots/states/METHOD/{gyro_bias,accel_bias,odo_mount,odo_scale}`   Scalars, the filter's sensor states
  [deg/h, mg, deg, 1], with the true values as flat series where given
* `plots/sigma/METHOD/{gyro_bias,accel_bias,odo_mount,odo_scale}`    Scalars, +- their one-sigma

and for a federated filter (ESTIMATE_FUSION, 003 section 4):

* `plots/fusion/METHOD/beta`                          Scalars, information-sharing coefficients per sub-filter
* `plots/fusion/METHOD/r_yaw`                         Scalars, the yaw noise sd the magnetometer sub-filter used
                                                      (estimated from its innovations) [deg]
* `plots/fusion/METHOD/yaw_innovation`                Scalars, yaw closing-error innovation [deg]
* `plots/fusion/METHOD/magnetometer`                  Scalars 0/1: reading used, disturbed, gated in each plot
                                                      interval (estimators.shearer.federated_filter MAG_*)
* `plots/fusion/METHOD/subfilter_errors/{east,north}` Scalars, position error of the global estimate and of each
                                                      sub-filter's own estimate before the fusion [m]; without
                                                      truth their offsets from the global estimate (global: 0)

and for the rail kinematics model's filter (ESTIMATE_DETECTORS, 004 section IV):

* `plots/detectors/METHOD/{residual,dual_state,fsprt}`  Scalars, each detector's statistic per fix (the largest in
                                                      each interval of the record rate) with its thresholds
* `plots/detectors/METHOD/isolated`                   Scalars 0/1, the rail model isolated (in each interval)
* `world/estimates/METHOD/rail`                       static Points3D, the rail model's predicted points (the
                                                      shearer's path it predicts), beside the true path of run.rrd

and for the supports' canopy attitude (twin.pipeline.support_estimate.SupportAttitude, issue 8; ANGLE pitch, roll, yaw):

* `plots/support_attitude/angles/ANGLE/SUPPORT/{METHOD,truth}`  Scalars, each method's angle and the truth [deg]
* `plots/support_attitude/errors/ANGLE/SUPPORT/METHOD`  Scalars, estimate - truth [deg]
* `plots/support_attitude/magnetometer/SUPPORT`      Scalars: ours' disturbance flags 0/1 (norm, dip, gate,
                                                      accelerating) in each plot interval, and the shearer's field
                                                      at the unit over its peak
* `plots/support_attitude/gd_objective`              static BarChart, the GD-UKF's objective per iteration [deg]
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from itertools import chain
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr

from estimators.io.logformat import FLAG_POSITION, FLAG_SKIPPED, FLAG_ZUPT, NONORTH_AXES
from estimators.io.metrics import TruthTrack, attitude_errors, column, columns, position_errors
from estimators.nav import earth
from estimators.shearer.federated_filter import MAG_DISTURBED, MAG_GATED, MAG_USED
from estimators.shearer.methods import METHODS
from twin.config.imu_grades import DEG, DEG_PER_H, MG
from twin.config.scenario import Scenario
from twin.pipeline.support_estimate import SupportAttitude
from twin.view import plan
from twin.view.recording import run_recording_id
from twin.view.record_rate import FULL, RECORD_RATE_HZ, check_record_rate
from twin.view.rerun_columns import PlottedSeries, RowBatches, SeriesBlock, time_column
from twin.view.row_cuts import (
    Blocks,
    IntervalReduce,
    MarkerCut,
    PathStrips,
    RowsOf,
    blocks_of,
    bounded,
    decimate,
    decimated_blocks,
)
from twin.view.rrd_stream import recording_id, recording_stream
from twin.view.support_attitude_recording import SUPPORT_PLOT_RATE_HZ, log_support_attitude

POSITION_AXES = ("east", "north", "up")
ATTITUDE_AXES = ("e", "n", "u")
STATE_GROUPS = {  # state column prefix: (axes, SI value per display unit, display unit)
    "gyro_bias": ("xyz", DEG_PER_H, "deg/h"),
    "accel_bias": ("xyz", MG, "mg"),
    "odo_mount": ("xyz", DEG, "deg"),
    "odo_scale": ("", 1.0, "1"),
    "accel_nonorth": (NONORTH_AXES, DEG, "deg"),
}
FLAG_SERIES = (("position fix", FLAG_POSITION), ("ZUPT", FLAG_ZUPT), ("skipped", FLAG_SKIPPED))
MAG_SERIES = (("used", MAG_USED), ("disturbed", MAG_DISTURBED), ("gated", MAG_GATED))
SUBFILTERS = ("odometer", "aiding")
METHOD_RGB = dict(zip(METHODS, np.array([[150, 150, 150], [60, 200, 90], [200, 80, 220], [240, 200, 40],
                                          [40, 120, 240], [0, 200, 200], [255, 130, 170], [150, 100, 50],
                                          [120, 80, 255]], np.uint8)))
"""Each method's colour in the 3-D and plan views (the truth's is twin.view.recording.TRUTH_RGB)."""


def _names(group: str) -> list[str]:
    axes = STATE_GROUPS[group][0]
    return [f"{group}_{a}" for a in axes] if axes else [group]


def plot_rows(table: pa.Table, rate_hz: float | None) -> tuple[pa.Table, np.ndarray]:
    """The rows kept for plotting (first of each 1/rate_hz interval and the last; all at FULL rate) and their
    times."""
    keep = decimate(column(table, "t"), rate_hz)
    sub = table.take(pa.array(keep))
    return sub, column(sub, "t")


def _record_rows(data: Blocks, rate_hz: float | None,
                 each: Callable[[pa.Table], None] | None = None) -> Iterator[tuple[pa.Table, np.ndarray]]:
    """A stream's rows at the record rate (decimated_blocks: the first of each 1/rate_hz interval and the last; all
    at FULL rate) a block at a time, with their times; `each` is called with every block read."""
    for sub in decimated_blocks(bounded(data), rate_hz, each):
        yield sub, column(sub, "t")


def _has_rows(data: Blocks) -> bool:
    return any(block.num_rows for block in blocks_of(data))


def _flag_rows(t: np.ndarray, flags: np.ndarray, bits) -> tuple[np.ndarray, np.ndarray]:
    """OR-ed flags (K,) as 0/1 series, a column per (label, bit) of `bits`."""
    flags = np.asarray(flags, np.int64)
    return t, np.column_stack([(flags & bit) != 0 for _, bit in bits]).reshape(t.size, len(bits)).astype(float)


def _flag_series(data: Blocks, name: str, bits, rate_hz: float | None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """A stream's flag column `name` OR-ed over each plot interval (a single-sample fix is not decimated away, and the
    0/1 steps keep their edges in visible_rows) as 0/1 series (_flag_rows), a block at a time."""
    flags = IntervalReduce(rate_hz, np.bitwise_or)
    for block in bounded(data):
        yield _flag_rows(*flags.push(column(block, "t"), np.asarray(block.column(name).to_numpy(), np.int64)), bits)
    yield _flag_rows(*flags.finish(), bits)


def _estimate_plots(method: str, truth: bool) -> dict[str, list[str]]:
    names = {}
    if truth:
        names[f"plots/errors/{method}/horizontal"] = [f"{method} [m]"]
        for axis, a in zip(POSITION_AXES, ATTITUDE_AXES):
            names[f"plots/errors/{method}/{axis}"] = [f"{method} {axis} [m]"]
            names[f"plots/attitude_errors/{method}/{a}"] = [f"{method} phi_{a} [deg]"]
    for axis, a in zip(POSITION_AXES, ATTITUDE_AXES):
        names[f"plots/sigma/{method}/position/{axis}"] = [f"{sign}1 sigma {method} {axis} [m]" for sign in "+-"]
        names[f"plots/sigma/{method}/attitude/{a}"] = [f"{sign}1 sigma {method} phi_{a} [deg]" for sign in "+-"]
    names[f"plots/flags/{method}"] = [f"{method} {label}" for label, _ in FLAG_SERIES]
    return names


def _estimate_series(method: str, truth: TruthTrack | None, estimate: Blocks, rate_hz: float | None,
                     each: Callable[[pa.Table], None] | None = None) -> Iterator[SeriesBlock]:
    """_estimate_plots' series a block at a time: errors against the truth (read forwards once), sigmas, flags."""
    flags = _flag_series(estimate, "flags", FLAG_SERIES, rate_hz)
    for sub, t in _record_rows(estimate, rate_hz, each):
        block = {}
        if truth is not None:
            err, phi = position_errors(sub, truth)[1], attitude_errors(sub, truth)[1]
            block[f"plots/errors/{method}/horizontal"] = (t, np.hypot(err[:, 0], err[:, 1])[:, None])
            for i, (axis, a) in enumerate(zip(POSITION_AXES, ATTITUDE_AXES)):
                block[f"plots/errors/{method}/{axis}"] = (t, err[:, i:i + 1])
                block[f"plots/attitude_errors/{method}/{a}"] = (t, np.degrees(phi[:, i:i + 1]))
        sd_pos, sd_att = columns(sub, "sd_pos"), np.degrees(columns(sub, "sd_att"))
        for i, (axis, a) in enumerate(zip(POSITION_AXES, ATTITUDE_AXES)):
            block[f"plots/sigma/{method}/position/{axis}"] = (t, np.column_stack([sd_pos[:, i], -sd_pos[:, i]]))
            block[f"plots/sigma/{method}/attitude/{a}"] = (t, np.column_stack([sd_att[:, i], -sd_att[:, i]]))
        yield block
    for rows in flags:
        yield {f"plots/flags/{method}": rows}


def _log_estimate(rec: rr.RecordingStream, scn: Scenario, truth: TruthTrack | None, method: str, estimate: Blocks,
                  rate_hz: float | None, color: np.ndarray) -> None:
    """An estimate's path and point (3-D and plan) and its plots, from its file read once a block at a time: the
    path, the points and the plots' ranges, then the plots cut and sent from their spool (PlottedSeries)."""
    if not _has_rows(estimate):
        return
    site = scn.site
    path, plan_path, markers = PathStrips(rate_hz), PathStrips(rate_hz), MarkerCut(rate_hz)
    entity = f"world/estimates/{method}/position"
    points = RowBatches(lambda t, p: rec.send_columns(entity, indexes=[time_column(t)],
                                                      columns=rr.Points3D.columns(positions=p.astype(np.float32))),
                        lambda: rec.log(entity, rr.Points3D.from_fields(radii=0.15, colors=color), static=True))
    plan_entity = f"{plan.PLAN_ROOT}/estimates/{method}"
    plan_points = plan.position_batches(rec, scn, plan_entity, color)
    last = []

    def draw_path(block: pa.Table) -> None:
        if not block.num_rows:
            return
        t = column(block, "t")
        p = earth.lla_to_enu(column(block, "lat"), column(block, "lon"), column(block, "h"),
                             np.radians(site.lat_deg), np.radians(site.lon_deg), site.height_m)
        cycle = None if truth is None else truth.at(t)["cycle"]  # of the truth sample at or before each estimate
        path.push(t, p, cycle)
        cycle = np.zeros(t.size, np.int64) if cycle is None else cycle
        plan_path.push(t, plan.face_coordinates(scn, p, cycle), cycle)
        moved = markers.push(t, p) - markers_pushed[0]
        points.add(t[moved], p[moved])
        plan_points.add(t[moved], p[moved], cycle[moved])
        markers_pushed[0] += t.size
        last[:] = [t[-1:], p[-1:], cycle[-1:]]

    markers_pushed = [0]
    plots = PlottedSeries(_estimate_plots(method, truth is not None), rate_hz, [f"plots/flags/{method}"])
    plots.measure(_estimate_series(method, truth, estimate, rate_hz, draw_path))
    if markers.finish().size:  # the last row, unless kept
        points.add(*last[:2])
        plan_points.add(*last)
    rec.log(f"world/estimates/{method}/path", rr.LineStrips3D(path.strips(), radii=0.03, colors=color), static=True)
    points.flush()
    plan.log_path(rec, plan_entity, plan_path, color)
    plan_points.flush()
    # +- one-sigma series are left out when there is no sigma at all (NaN throughout).
    plots.drop(*(e for e in plots.names if e.startswith(f"plots/sigma/{method}/") and not plots.finite(e)))
    plots.send(rec)


def _log_fusion(rec: rr.RecordingStream, truth: TruthTrack | None, method: str, estimate: Blocks, fusion: Blocks,
                rate_hz: float | None) -> None:
    root = f"plots/fusion/{method}"
    names = {f"{root}/r_yaw": [f"{method} sd yaw [deg]"], f"{root}/yaw_innovation": [f"{method} yaw innovation [deg]"],
             f"{root}/magnetometer": [f"{method} {label}" for label, _ in MAG_SERIES],
             f"{root}/beta": [f"{method} beta {s}" for s in SUBFILTERS]}
    for axis in POSITION_AXES[:2]:
        names[f"{root}/subfilter_errors/{axis}"] = ([f"{method} global {axis} [m]"]
                                                    + [f"{method} {s} sub-filter {axis} [m]" for s in SUBFILTERS])

    def blocks() -> Iterator[SeriesBlock]:
        estimated = RowsOf(decimated_blocks(bounded(estimate), rate_hz))
        for sub, t in _record_rows(fusion, rate_hz):
            block = {f"{root}/r_yaw": (t, np.degrees(np.sqrt(column(sub, "r_yaw")))[:, None]),
                     f"{root}/yaw_innovation": (t, np.degrees(column(sub, "yaw_innovation"))[:, None]),
                     f"{root}/beta": (t, np.column_stack([column(sub, f"beta_{s}") for s in SUBFILTERS]))}
            err = np.zeros((t.size, 3)) if truth is None else position_errors(estimated.take(t.size), truth)[1]
            for i, axis in enumerate(POSITION_AXES[:2]):
                d = np.column_stack([np.zeros(t.size)] + [column(sub, f"{s}_d_pos_{'en'[i]}") for s in SUBFILTERS])
                block[f"{root}/subfilter_errors/{axis}"] = (t, err[:, i:i + 1] + d)
            yield block
        for rows in _flag_series(fusion, "mag_flags", MAG_SERIES, rate_hz):
            yield {f"{root}/magnetometer": rows}

    plots = PlottedSeries(names, rate_hz, [f"{root}/magnetometer"])
    plots.measure(blocks())
    if not plots.finite(f"{root}/beta"):  # a centralized filter: no sub-filters
        plots.drop(f"{root}/beta", *(f"{root}/subfilter_errors/{axis}" for axis in POSITION_AXES[:2]))
    plots.send(rec)


def _log_states(rec: rr.RecordingStream, method: str, states: Blocks, truth: dict[str, float] | None,
                rate_hz: float | None) -> None:
    if not _has_rows(states):
        return
    names = {}
    for group, (_, _, unit) in STATE_GROUPS.items():
        known = [n for n in _names(group) if truth and n in truth]
        names[f"plots/states/{method}/{group}"] = ([f"{n} [{unit}]" for n in _names(group)]
                                                   + [f"{n} true [{unit}]" for n in known])
        names[f"plots/sigma/{method}/{group}"] = [f"{sign}1 sigma {n} [{unit}]" for sign in "+-" for n in _names(group)]

    def blocks() -> Iterator[SeriesBlock]:
        for sub, t in _record_rows(states, rate_hz):
            block = {}
            for group, (_, per_unit, _) in STATE_GROUPS.items():
                group_names = _names(group)
                values = np.column_stack([column(sub, n) for n in group_names]) / per_unit
                known = [n for n in group_names if truth and n in truth]
                if known:
                    flat = np.broadcast_to(np.array([truth[n] for n in known]) / per_unit, (t.size, len(known)))
                    values = np.column_stack([values, flat])
                block[f"plots/states/{method}/{group}"] = (t, values)
                sd = np.column_stack([column(sub, f"sd_{n}") for n in group_names]) / per_unit
                block[f"plots/sigma/{method}/{group}"] = (t, np.column_stack([sd, -sd]))
            yield block

    PlottedSeries(names, rate_hz).log(rec, blocks())


DETECTOR_PEAKS = ("residual", "dual_state", "fsprt", "isolated")
"""The detector statistics drawn by their peak in each interval of the record rate."""


def _log_detectors(rec: rr.RecordingStream, scn: Scenario, method: str, detectors: Blocks,
                   thresholds: dict[str, float], rate_hz: float | None) -> None:
    """Each statistic's largest value in each interval of the record rate (an alarm is a peak: it is not decimated
    away), with its thresholds; the isolation as 0/1 in each interval."""
    if not _has_rows(detectors):
        return
    root = f"plots/detectors/{method}"
    names = {f"{root}/{name}": [f"{method} {name}", f"{name} threshold"] for name in ("residual", "dual_state")}
    names[f"{root}/fsprt"] = [f"{method} fsprt", "fsprt T1 (fault)", "fsprt T0 (clear)"]
    names[f"{root}/isolated"] = [f"{method} isolated"]
    site, rail = scn.site, []

    def blocks() -> Iterator[SeriesBlock]:
        peaks = IntervalReduce(rate_hz, np.fmax)
        for block in chain(bounded(detectors), [None]):
            if block is None:
                t, peak = peaks.finish()
            else:
                t, peak = peaks.push(column(block, "t"),
                                     np.column_stack([column(block, name) for name in DETECTOR_PEAKS]))
            if block is not None:
                rail.append(earth.lla_to_enu(column(block, "lat"), column(block, "lon"), column(block, "h"),
                                             np.radians(site.lat_deg), np.radians(site.lon_deg),
                                             site.height_m).astype(np.float32))
            peak = peak.reshape(t.size, len(DETECTOR_PEAKS))
            flat = {name: np.full(t.size, thresholds[name]) for name in ("residual", "dual_state", "t_on", "t_off")}
            yield {f"{root}/residual": (t, np.column_stack([peak[:, 0], flat["residual"]])),
                   f"{root}/dual_state": (t, np.column_stack([peak[:, 1], flat["dual_state"]])),
                   f"{root}/fsprt": (t, np.column_stack([peak[:, 2], flat["t_on"], flat["t_off"]])),
                   f"{root}/isolated": (t, peak[:, 3:])}

    plots = PlottedSeries(names, rate_hz, [f"{root}/isolated"])
    plots.log(rec, blocks())
    rec.log(f"world/estimates/{method}/rail", rr.Points3D(np.concatenate(rail), radii=0.08, colors=[240, 120, 40]),
            static=True)


def write_estimate_recording(path: Path, scn: Scenario, truth_shearer, estimates: Mapping[str, Blocks],
                             states: Mapping[str, Blocks], states_truth: dict[str, float] | None = None,
                             rate_hz: float | None = RECORD_RATE_HZ, fusion: Mapping[str, Blocks] | None = None,
                             detectors: Mapping[str, tuple[Blocks, dict[str, float]]] | None = None,
                             supports: SupportAttitude | None = None) -> None:
    """Write the estimators' outputs as `path` (normally RUN_DIR/estimates.rrd) with the recording id of
    RUN_DIR/run.rrd.

    `truth_shearer`: the truth_shearer table (or its columns as arrays, or an estimators.io.metrics.TruthTrack);
    `estimates`: method name -> ESTIMATE table; `states`: method name -> ESTIMATE_STATES table (filters with sensor
    states only); each table may come in blocks (twin.view.row_cuts.Blocks: an estimate file read a row group at a
    time, twice; the truth is read forwards with it, estimators.io.metrics.TruthTrack); `states_truth`:
    true values of the sensor states by ESTIMATE_STATES column name in SI units (e.g. "gyro_bias_x" [rad/s],
    "odo_scale"), drawn as flat series; `fusion`: method name -> ESTIMATE_FUSION table (federated filters);
    `detectors`: method name -> (ESTIMATE_DETECTORS table, thresholds by statistic: residual, dual_state, t_on,
    t_off); `supports`: the supports' canopy attitude (twin.pipeline.support_estimate.support_attitude); `rate_hz`:
    the record rate (twin.view.record_rate: Hz, or FULL for every row).
    With truth, estimate times must lie within its span (LogError otherwise); without (None) the errors are left
    out, and without a run.rrd beside `path` the recording gets the world's axes and the scenario's name itself.
    """
    fusion = fusion or {}
    detectors = detectors or {}
    rate_hz = check_record_rate(rate_hz)
    truth = truth_shearer if truth_shearer is None or isinstance(truth_shearer, TruthTrack) else TruthTrack(truth_shearer)
    run_id = run_recording_id(Path(path).parent)
    with recording_stream(path, run_id or recording_id(scn)) as rec:
        if run_id is None:  # no run.rrd to merge with: this recording is the whole view
            rec.send_recording_name(scn.name)
            rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for method, table in estimates.items():
            _log_estimate(rec, scn, truth, method, table, rate_hz, METHOD_RGB.get(method, METHOD_RGB["dr"]))
        for method, table in states.items():
            _log_states(rec, method, table, states_truth, rate_hz)
        for method, table in fusion.items():
            _log_fusion(rec, truth, method, estimates[method], table, rate_hz)
        for method, (table, thresholds) in detectors.items():
            _log_detectors(rec, scn, method, table, thresholds, rate_hz)
        if supports is not None:
            log_support_attitude(rec, supports, FULL if rate_hz is FULL else min(rate_hz, SUPPORT_PLOT_RATE_HZ))
