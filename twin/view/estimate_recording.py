"""The estimators' Rerun recording: `estimates.rrd` beside a run's `run.rrd`, merged with it by the viewer.

The file carries the application id and the recording id of run.rrd (read from it; the scenario's when the run has
none, e.g. an imported log; written reproducibly by twin.view.rrd_stream), so `longwall view` shows the truth replay and the estimates as one recording, in
the run's layout with a second "Estimates" tab of plots (twin.view.layout). A run without truth (truth_shearer None, e.g.
a real face's log) gets everything but the errors: paths, sigmas, flags, sensor states, fusion, detectors.
Everything is logged column-wise with `send_columns` on the `sim_time` timeline, cut to what a person can see at the
record rate (twin.view.row_cuts.visible_rows: at most the rate, without the samples a plotted line passes within
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

from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr

from estimators.io.logformat import FLAG_POSITION, FLAG_SKIPPED, FLAG_ZUPT, NONORTH_AXES
from estimators.io.metrics import attitude_errors, column, columns, position_errors, truth_at
from estimators.nav import earth
from estimators.shearer.federated_filter import MAG_DISTURBED, MAG_GATED, MAG_USED
from estimators.shearer.methods import METHODS
from twin.config.imu_grades import DEG, DEG_PER_H, MG
from twin.config.scenario import Scenario
from twin.pipeline.support_estimate import ANGLES, FLAG_NAMES, SupportAttitude
from twin.view import plan
from twin.view.recording import run_recording_id
from twin.view.record_rate import FULL, RECORD_RATE_HZ, check_record_rate
from twin.view.rerun_columns import series, time_column
from twin.view.row_cuts import PathStrips, decimate, marker_rows, path_strips
from twin.view.rrd_stream import recording_id, recording_stream

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


def _log_band(rec: rr.RecordingStream, entity: str, t: np.ndarray, sd: np.ndarray, label: str,
              rate_hz: float | None) -> None:
    """+- one-sigma of (K,) values as two series, unless there is no sigma at all (NaN throughout)."""
    if np.isfinite(sd).any():
        series(rec, entity, t, np.column_stack([sd, -sd]), [f"+1 sigma {label}", f"-1 sigma {label}"],
               rate_hz=rate_hz)


def _log_estimate(rec: rr.RecordingStream, scn: Scenario, truth_shearer, method: str, table: pa.Table,
                  rate_hz: float | None, color: np.ndarray) -> None:
    if table.num_rows == 0:
        return
    site = scn.site
    t_all = column(table, "t")
    p_all = earth.lla_to_enu(column(table, "lat"), column(table, "lon"), column(table, "h"), np.radians(site.lat_deg),
                             np.radians(site.lon_deg), site.height_m)
    # With truth one strip per cycle, the cycle of the truth sample at or before each estimate time.
    cycle = None
    if truth_shearer is not None:
        cycle = truth_at(truth_shearer, t_all)["cycle"]
    rec.log(f"world/estimates/{method}/path", rr.LineStrips3D(path_strips(t_all, p_all, cycle, rate_hz), radii=0.03,
                                                              colors=color), static=True)
    moved = marker_rows(t_all, p_all, rate_hz)
    rec.log(f"world/estimates/{method}/position", rr.Points3D.from_fields(radii=0.15, colors=color), static=True)
    rec.send_columns(f"world/estimates/{method}/position", indexes=[time_column(t_all[moved])],
                     columns=rr.Points3D.columns(positions=p_all[moved].astype(np.float32)))
    cycle = np.zeros(t_all.size, np.int64) if cycle is None else cycle
    plan_path = PathStrips(rate_hz)
    plan_path.push(t_all, plan.face_coordinates(scn, p_all, cycle), cycle)
    plan.log_path(rec, scn, f"{plan.PLAN_ROOT}/estimates/{method}", plan_path, t_all[moved], p_all[moved],
                  cycle[moved], color)
    sub, t = plot_rows(table, rate_hz)

    if truth_shearer is not None:
        _, err = position_errors(sub, truth_shearer)
        _, phi = attitude_errors(sub, truth_shearer)
        series(rec, f"plots/errors/{method}/horizontal", t, np.hypot(err[:, 0], err[:, 1])[:, None],
               [f"{method} [m]"], rate_hz=rate_hz)
        for i, (axis, a) in enumerate(zip(POSITION_AXES, ATTITUDE_AXES)):
            series(rec, f"plots/errors/{method}/{axis}", t, err[:, i:i + 1], [f"{method} {axis} [m]"],
                   rate_hz=rate_hz)
            series(rec, f"plots/attitude_errors/{method}/{a}", t, np.degrees(phi[:, i:i + 1]),
                   [f"{method} phi_{a} [deg]"], rate_hz=rate_hz)
    sd_pos, sd_att = columns(sub, "sd_pos"), np.degrees(columns(sub, "sd_att"))
    for i, (axis, a) in enumerate(zip(POSITION_AXES, ATTITUDE_AXES)):
        _log_band(rec, f"plots/sigma/{method}/position/{axis}", t, sd_pos[:, i], f"{method} {axis} [m]", rate_hz)
        _log_band(rec, f"plots/sigma/{method}/attitude/{a}", t, sd_att[:, i], f"{method} phi_{a} [deg]", rate_hz)

    _log_flags(rec, f"plots/flags/{method}", table, "flags", FLAG_SERIES, method, rate_hz)


def _log_flags(rec: rr.RecordingStream, entity: str, table: pa.Table, name: str, bits, method: str,
               rate_hz: float | None) -> None:
    """Flags are events: OR them over each plot interval so a single-sample fix is not decimated away (and the
    0/1 steps keep their edges in visible_rows); `bits` pairs a label with its flag bit."""
    t_all = column(table, "t")
    keep = decimate(t_all, rate_hz)
    flags = np.bitwise_or.reduceat(np.asarray(table.column(name).to_numpy(), np.int64), keep)
    series(rec, entity, t_all[keep], np.column_stack([(flags & bit) != 0 for _, bit in bits]).astype(float),
           [f"{method} {label}" for label, _ in bits], rate_hz=rate_hz, band=False)


def _log_fusion(rec: rr.RecordingStream, truth_shearer, method: str, estimate: pa.Table, fusion: pa.Table,
                rate_hz: float | None) -> None:
    sub, t = plot_rows(fusion, rate_hz)
    root = f"plots/fusion/{method}"
    series(rec, f"{root}/r_yaw", t, np.degrees(np.sqrt(column(sub, "r_yaw")))[:, None], [f"{method} sd yaw [deg]"],
           rate_hz=rate_hz)
    series(rec, f"{root}/yaw_innovation", t, np.degrees(column(sub, "yaw_innovation"))[:, None],
           [f"{method} yaw innovation [deg]"], rate_hz=rate_hz)
    _log_flags(rec, f"{root}/magnetometer", fusion, "mag_flags", MAG_SERIES, method, rate_hz)
    beta = np.column_stack([column(sub, f"beta_{s}") for s in SUBFILTERS])
    if not np.isfinite(beta).any():
        return  # a centralized filter: no sub-filters
    series(rec, f"{root}/beta", t, beta, [f"{method} beta {s}" for s in SUBFILTERS], rate_hz=rate_hz)
    est, _ = plot_rows(estimate, rate_hz)
    err = np.zeros((t.size, 3)) if truth_shearer is None else position_errors(est, truth_shearer)[1]
    for i, axis in enumerate(POSITION_AXES[:2]):
        d = np.column_stack([np.zeros(t.size)] + [column(sub, f"{s}_d_pos_{'en'[i]}") for s in SUBFILTERS])
        series(rec, f"{root}/subfilter_errors/{axis}", t, err[:, i:i + 1] + d,
               [f"{method} global {axis} [m]"] + [f"{method} {s} sub-filter {axis} [m]" for s in SUBFILTERS],
               rate_hz=rate_hz)


def _log_states(rec: rr.RecordingStream, method: str, table: pa.Table, truth: dict[str, float] | None,
                rate_hz: float | None) -> None:
    if table.num_rows == 0:
        return
    sub, t = plot_rows(table, rate_hz)
    for group, (_, per_unit, unit) in STATE_GROUPS.items():
        names = _names(group)
        values = np.column_stack([column(sub, n) for n in names]) / per_unit
        labels = [f"{n} [{unit}]" for n in names]
        known = [n for n in names if truth and n in truth]
        if known:
            flat = np.broadcast_to(np.array([truth[n] for n in known]) / per_unit, (t.size, len(known)))
            values = np.column_stack([values, flat])
            labels += [f"{n} true [{unit}]" for n in known]
        series(rec, f"plots/states/{method}/{group}", t, values, labels, rate_hz=rate_hz)
        sd = np.column_stack([column(sub, f"sd_{n}") for n in names]) / per_unit
        series(rec, f"plots/sigma/{method}/{group}", t, np.column_stack([sd, -sd]),
               [f"{sign}1 sigma {n} [{unit}]" for sign in "+-" for n in names], rate_hz=rate_hz)


def _log_detectors(rec: rr.RecordingStream, scn: Scenario, method: str, table: pa.Table,
                   thresholds: dict[str, float], rate_hz: float | None) -> None:
    """Each statistic's largest value in each interval of the record rate (an alarm is a peak: it is not decimated
    away), with its thresholds; the isolation as 0/1 in each interval."""
    if table.num_rows == 0:
        return
    t_all = column(table, "t")
    keep = decimate(t_all, rate_hz)
    t = t_all[keep]

    def peaks(name: str) -> np.ndarray:
        return np.fmax.reduceat(np.asarray(column(table, name), float), keep)

    root = f"plots/detectors/{method}"
    for name in ("residual", "dual_state"):
        series(rec, f"{root}/{name}", t, np.column_stack([peaks(name), np.full(t.size, thresholds[name])]),
               [f"{method} {name}", f"{name} threshold"], rate_hz=rate_hz)
    series(rec, f"{root}/fsprt", t, np.column_stack([peaks("fsprt"), np.full(t.size, thresholds["t_on"]),
                                                      np.full(t.size, thresholds["t_off"])]),
           [f"{method} fsprt", "fsprt T1 (fault)", "fsprt T0 (clear)"], rate_hz=rate_hz)
    series(rec, f"{root}/isolated", t, peaks("isolated")[:, None], [f"{method} isolated"], rate_hz=rate_hz,
           band=False)
    site = scn.site
    p_t = earth.lla_to_enu(column(table, "lat"), column(table, "lon"), column(table, "h"), np.radians(site.lat_deg),
                           np.radians(site.lon_deg), site.height_m).astype(np.float32)
    rec.log(f"world/estimates/{method}/rail", rr.Points3D(p_t, radii=0.08, colors=[240, 120, 40]), static=True)


# The supports' canopy attitude (issue 8).
SUPPORT_PLOT_RATE_HZ = 2.0
"""Largest rate of the supports' plots: a canopy moves over seconds (an advance, the shearer's pass), and a face has
many units."""


def _log_support_attitude(rec: rr.RecordingStream, supports: SupportAttitude, rate_hz: float | None) -> None:
    """Each support's angles (with the truth) and errors per method, ours' flags (OR-ed over each plot
    interval) with the shearer's field, the GD objective; decimated to rate_hz, sent column-wise."""
    root = "plots/support_attitude"
    for name, t in supports.t.items():
        keep = decimate(t, rate_hz)
        est = np.degrees(supports.euler[name][:, keep])
        truth = np.degrees(supports.truth_euler[name][:, keep]) if supports.truth_euler else None
        for i, j in enumerate(supports.supports):
            for a, angle in enumerate(ANGLES):
                series(rec, f"{root}/angles/{angle}/{j}/{name}", t[keep], est[i, :, a:a + 1],
                       [f"support {j} {name} [deg]"], rate_hz=rate_hz)
                if truth is not None:
                    series(rec, f"{root}/errors/{angle}/{j}/{name}", t[keep],
                           ((est[i, :, a] - truth[i, :, a] + 180.0) % 360.0 - 180.0)[:, None],
                           [f"support {j} {name} [deg]"], rate_hz=rate_hz)
                    if name == "ours":
                        series(rec, f"{root}/angles/{angle}/{j}/truth", t[keep], truth[i, :, a:a + 1],
                               [f"support {j} truth [deg]"], rate_hz=rate_hz)
    t = supports.t["ours"]
    keep = decimate(t, rate_hz)
    for i, j in enumerate(supports.supports):
        flags = np.bitwise_or.reduceat(supports.flags[i].astype(np.int64), keep)
        values = [(flags & bit) != 0 for _, bit in FLAG_NAMES]
        labels = [f"support {j} ours {label}" for label, _ in FLAG_NAMES]
        if supports.near is not None:
            values.append(np.maximum.reduceat(supports.near[i], keep))
            labels.append(f"support {j} shearer's field / peak")
        series(rec, f"{root}/magnetometer/{j}", t[keep], np.column_stack(values).astype(float), labels,
               rate_hz=rate_hz, band=False)
    if supports.objective:
        rec.log(f"{root}/gd_objective", rr.BarChart(np.degrees(supports.objective)), static=True)



def write_estimate_recording(path: Path, scn: Scenario, truth_shearer, estimates: dict[str, pa.Table],
                             states: dict[str, pa.Table], states_truth: dict[str, float] | None = None,
                             rate_hz: float | None = RECORD_RATE_HZ, fusion: dict[str, pa.Table] | None = None,
                             detectors: dict[str, tuple[pa.Table, dict[str, float]]] | None = None,
                             supports: SupportAttitude | None = None) -> None:
    """Write the estimators' outputs as `path` (normally RUN_DIR/estimates.rrd) with the recording id of
    RUN_DIR/run.rrd.

    `truth_shearer`: the truth_shearer table (or its columns as arrays, or an estimators.io.metrics.TruthTrack);
    `estimates`: method name -> ESTIMATE table; `states`: method name -> ESTIMATE_STATES table (filters with sensor states only); `states_truth`:
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
    run_id = run_recording_id(Path(path).parent)
    with recording_stream(path, run_id or recording_id(scn)) as rec:
        if run_id is None:  # no run.rrd to merge with: this recording is the whole view
            rec.send_recording_name(scn.name)
            rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        for method, table in estimates.items():
            _log_estimate(rec, scn, truth_shearer, method, table, rate_hz, METHOD_RGB.get(method, METHOD_RGB["dr"]))
        for method, table in states.items():
            _log_states(rec, method, table, states_truth, rate_hz)
        for method, table in fusion.items():
            _log_fusion(rec, truth_shearer, method, estimates[method], table, rate_hz)
        for method, (table, thresholds) in detectors.items():
            _log_detectors(rec, scn, method, table, thresholds, rate_hz)
        if supports is not None:
            _log_support_attitude(rec, supports, FULL if rate_hz is FULL else min(rate_hz, SUPPORT_PLOT_RATE_HZ))
