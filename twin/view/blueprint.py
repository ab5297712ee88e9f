"""The Rerun layout (blueprint) of a face run's recordings, one tab per subject, for each kind of run:

* with truth (`longwall run`): "Face" (the 3-D face framed on the face, the plan view in the face frame, speed and
  pan line), "Face line" ("Face alignment" when the alignment loop ran: offsets and sequence beside it), "Sensors" (one
  plot per quantity and unit), then the estimates, one tab per quantity with every method overlaid;
* without truth (an imported log, estimates.rrd alone): "Face" with the estimated paths, and the estimates' one-sigma
  and states.

HIDDEN_METHODS, and with truth every method whose error over the run is more than OFF_FACE_SEP times the best's
(`hidden_methods`), are hidden in every view (their entities' visibility off, so a user turns them on in the
blueprint panel): dead reckoning drifts tens of metres off the face, and a filter without fixes metres across it at
the plan's x20, where they would set the plots' scales and cross the plan. The 3-D eye and the
plan's bounds are set from the run's face, so no estimate off it moves them. Entities as twin.view.recording,
twin.view.sensor_recording, twin.view.estimate_recording and twin.view.plan log them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import rerun.blueprint as rrb

from twin.pipeline.support_estimate import ANGLES
from twin.view import plan
from twin.view.estimate_recording import ATTITUDE_AXES, POSITION_AXES, STATE_GROUPS

HIDDEN_METHODS = ("dr",)
"""Methods hidden by default (dead reckoning: no aiding, tens of metres off by the end of a run)."""
OFF_FACE_SEP = 3.0
"""With truth, a method whose SEP over the run exceeds this many times the best method's is hidden by default."""
WHOLE_RUN = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                  end=rrb.TimeRangeBoundary.infinite()))
"""A plot's time axis over the whole run (not a window about the time cursor)."""
LEGEND = rrb.PlotLegend(corner=rrb.Corner2D.LeftTop)
"""Legends at the top left: errors start near zero and the plots' first seconds are the gyrocompassing stand."""


@dataclass(frozen=True)
class RunContents:
    """What a run directory holds, as far as its layout goes."""

    truth: bool = False
    """The twin's truth and sensors (run.rrd, truth_*.parquet): twin tabs, errors rather than one-sigma."""
    alignment: bool = False
    """The face alignment loop ran (the scenario's alignment mode is not "none")."""
    methods: list[str] = field(default_factory=list)
    state_methods: list[str] = field(default_factory=list)
    fusion_methods: list[str] = field(default_factory=list)
    detector_methods: list[str] = field(default_factory=list)
    support_attitude: bool = False
    eye: rrb.EyeControls3D | None = None
    """The 3-D view's eye, framed on the face (face_eye)."""
    plan_bounds: tuple[list[float], list[float]] | None = None
    """The plan view's x and y ranges (twin.view.plan.plan_bounds); None: no plan view (no scenario)."""
    streams: frozenset[str] | None = None
    """The sensor streams with rows (run_dir/STREAM.parquet): the Sensors tab plots these (None: every one)."""
    hidden: frozenset[str] = frozenset(HIDDEN_METHODS)
    """Methods hidden by default (hidden_methods)."""


def hidden_methods(methods: list[str], sep_m: dict[str, float]) -> frozenset[str]:
    """HIDDEN_METHODS and the methods whose SEP over the run (`sep_m`, metrics.json's; none without truth) is over
    OFF_FACE_SEP times the best's."""
    scored = {m: v for m, v in sep_m.items() if m in methods and m not in HIDDEN_METHODS and np.isfinite(v)}
    best = min(scored.values(), default=np.inf)
    return frozenset(HIDDEN_METHODS) | {m for m, v in scored.items() if v > OFF_FACE_SEP * best}


def face_eye(p_t: np.ndarray, azimuth_rad: float) -> rrb.EyeControls3D:
    """An orbital eye over the face whose points in t (K, 3) are given (the pans' positions): from the coal wall's side
    (the shearer and its drums in front of the pans and supports) towards the headgate and above, looking at the
    face's middle, the whole face in sight."""
    lo, hi = np.nanmin(p_t, axis=0), np.nanmax(p_t, axis=0)
    centre = 0.5 * (lo + hi)
    length = max(float(np.hypot(*(hi - lo)[:2])), 10.0)
    x_t = np.array([np.cos(azimuth_rad), -np.sin(azimuth_rad), 0.0])  # F's x: towards the coal wall
    y_t = np.array([np.sin(azimuth_rad), np.cos(azimuth_rad), 0.0])  # F's y: along the face
    eye = centre + 0.45 * length * x_t - 0.45 * length * y_t + np.array([0.0, 0.0, 0.25 * length])
    return rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=eye, look_target=centre, eye_up=[0.0, 0.0, 1.0])


def _hidden(paths: list[str], hidden: frozenset[str]) -> dict[str, rrb.EntityBehavior]:
    """Visibility off for the entities of the `hidden` methods among `paths` (and their parents up to the method)."""
    out = {}
    for path in paths:
        parts = path.rstrip("/*").split("/")
        for k, part in enumerate(parts):
            if part in hidden:
                out["/".join(parts[:k + 1])] = rrb.EntityBehavior(visible=False)
                out["/".join(parts)] = rrb.EntityBehavior(visible=False)
    return out


def _plot(name: str, contents: list[str] | str, legend: bool = True,
          hidden: frozenset[str] = frozenset()) -> rrb.TimeSeriesView:
    """A time-series view of `contents` over the whole run, the `hidden` methods hidden, legend at LEGEND (or none)."""
    paths = [contents] if isinstance(contents, str) else contents
    return rrb.TimeSeriesView(name=name, origin="/", contents=contents, overrides=_hidden(paths, hidden),
                              axis_x=WHOLE_RUN,
                              plot_legend=LEGEND if legend else rrb.PlotLegend(visible=False))


def face_views(c: RunContents) -> tuple[rrb.Spatial3DView, rrb.Spatial2DView | None]:
    """The 3-D face view and the plan view, the hidden methods hidden."""
    world = [f"world/estimates/{m}/{part}" for m in c.methods for part in ("path", "position", "rail")]
    face = rrb.Spatial3DView(name="Face", origin="world", contents="world/**", overrides=_hidden(world, c.hidden),
                             eye_controls=c.eye)
    if c.plan_bounds is None:
        return face, None
    flat = [f"{plan.PLAN_ROOT}/estimates/{m}/{part}" for m in c.methods for part in ("path", "position")]
    x_range, y_range = c.plan_bounds
    return face, rrb.Spatial2DView(name=plan.PLAN_NAME, origin=plan.PLAN_ROOT, overrides=_hidden(flat, c.hidden),
                                   visual_bounds=rrb.VisualBounds2D(x_range=x_range, y_range=y_range))


def _face_tab(c: RunContents) -> rrb.Container:
    face, plan_view = face_views(c)
    left = rrb.Vertical(face, plan_view, row_shares=[3, 2]) if plan_view is not None else face
    if not c.truth:
        return rrb.Horizontal(left, name="Face")
    right = rrb.Vertical(
        _plot("Shearer speed [m/s]", "plots/shearer_speed", legend=False),
        _plot("Cycle", "plots/cycle", legend=False),
        rrb.BarChartView(name="Pan line from its best-fit line per pan [mm], at cycle ends", origin="face/pan_line_mm"),
        rrb.BarChartView(name="Horizontal bend per chute [deg]", origin="plots/bend_horizontal_deg"),
    )
    return rrb.Horizontal(left, right, column_shares=[3, 1], name="Face")


def _face_line_tab(c: RunContents) -> rrb.Container:
    views = [
        rrb.BarChartView(name="Pan line from its best-fit line per pan [mm], at cycle ends", origin="face/pan_line_mm"),
        _plot("Straightness and creep [mm]", ["face/straightness_mm", "face/creep_mm"]),
        rrb.BarChartView(name="Horizontal bend per chute [deg]", origin="plots/bend_horizontal_deg"),
        rrb.BarChartView(name="Vertical bend per chute [deg]", origin="plots/bend_vertical_deg"),
        rrb.BarChartView(name="Ram length per support [m]", origin="plots/ram_length"),
    ]
    if c.alignment:
        views += [rrb.BarChartView(name="Push offsets per support [mm]", origin="alignment/offsets_mm"),
                  _plot("Offsets' sequence number applied", "alignment/sequence", legend=False)]
        _, plan_view = face_views(c)
        if plan_view is not None:
            return rrb.Vertical(plan_view, rrb.Grid(*views), row_shares=[2, 3], name="Face alignment")
    return rrb.Grid(*views, name="Face line")


SENSOR_VIEWS = (
    ("Accelerometer, shearer [m/s^2]", ["sensors/imu/accel"], "imu"),
    ("Gyroscope, shearer [rad/s]", ["sensors/imu/gyro"], "imu"),
    ("Magnetometer, shearer [uT]", ["sensors/mag"], "mag"),
    ("Odometer distance [m]", ["sensors/odometer/**"], "odometer"),
    ("Accelerometers, supports [m/s^2]", ["sensors/support_imu/*/accel"], "support_imu"),
    ("Gyroscopes, supports [rad/s]", ["sensors/support_imu/*/gyro"], "support_imu"),
    ("Lowest leg and highest ram pressure [MPa]", ["sensors/pressure/extremes"], "pressure"),
    ("Fault windows (active = 1)", ["faults/**"], "faults"),
)
"""The Sensors tab's time-series views, one quantity and unit each: (name, contents, the stream they come from)."""
SENSOR_BARS = (("Push-ram extension per support [m]", "sensors/pushram", "pushram"),
               ("Leg pressure per support [MPa]", "sensors/pressure/leg_bars", "pressure"),
               ("Ram pressure per support [MPa]", "sensors/pressure/ram_bars", "pressure"))


def _sensors_tab(c: RunContents) -> rrb.Container:
    """The plots of the streams the run holds (all without `c.streams`)."""
    def held(stream: str) -> bool:
        return c.streams is None or stream in c.streams

    return rrb.Grid(*(_plot(name, contents) for name, contents, stream in SENSOR_VIEWS if held(stream)),
                    *(rrb.BarChartView(name=name, origin=origin) for name, origin, stream in SENSOR_BARS
                      if held(stream)), grid_columns=4, name="Sensors")


def estimate_tabs(c: RunContents) -> list[rrb.Container]:
    """The estimates, one tab per quantity with every method overlaid: with truth the horizontal, east/north/up and
    attitude errors, without their one-sigma; the sensor states, the flags, fusion, detectors, the supports."""
    m, tabs = c.methods, []

    def plot(name: str, contents: list[str]) -> rrb.TimeSeriesView:
        return _plot(name, contents, hidden=c.hidden)

    if not m:
        return tabs
    if c.truth:
        tabs.append(rrb.Vertical(plot("Horizontal position error [m]", [f"plots/errors/{k}/horizontal" for k in m]),
                                 name="Horizontal error"))
        tabs.append(rrb.Vertical(*(plot(f"Position error {a} [m]", [f"plots/errors/{k}/{a}" for k in m])
                                   for a in POSITION_AXES), name="Position error"))
        tabs.append(rrb.Vertical(*(plot(f"Attitude error phi_{a} [deg]", [f"plots/attitude_errors/{k}/{a}"
                                                                             for k in m])
                                   for a in ATTITUDE_AXES), name="Attitude error"))
    tabs.append(rrb.Vertical(*(plot(f"Position one-sigma {a} [m]", [f"plots/sigma/{k}/position/{a}" for k in m])
                               for a in POSITION_AXES), name="Position one-sigma"))
    tabs.append(rrb.Vertical(*(plot(f"Attitude one-sigma phi_{a} [deg]", [f"plots/sigma/{k}/attitude/{a}"
                                                                              for k in m])
                               for a in ATTITUDE_AXES), name="Attitude one-sigma"))
    if c.state_methods:
        tabs.append(rrb.Grid(*(plot(f"{group} [{unit}]", [f"plots/{kind}/{k}/{group}" for k in c.state_methods
                                                             for kind in ("states", "sigma")])
                               for group, (_, _, unit) in STATE_GROUPS.items()), name="Sensor states"))
    tabs.append(rrb.Vertical(plot("Position fixes, ZUPTs, skipped", [f"plots/flags/{k}" for k in m]),
                             name="Flags"))
    if c.fusion_methods:
        tabs.append(rrb.Grid(*(plot(title, [f"plots/fusion/{k}/{part}/**" for k in c.fusion_methods])
                               for part, title in (
                                   ("beta", "Information sharing"), ("r_yaw", "Magnetometer yaw noise sd [deg]"),
                                   ("yaw_innovation", "Yaw innovation [deg]"),
                                   ("magnetometer", "Magnetometer readings"),
                                   ("subfilter_errors", "Sub-filter position errors [m]" if c.truth else
                                    "Sub-filter offsets from the global estimate [m]"))), name="Fusion"))
    if c.detector_methods:
        tabs.append(rrb.Grid(*(plot(title, [f"plots/detectors/{k}/{part}/**" for k in c.detector_methods])
                               for part, title in (("residual", "Residual chi-square"),
                                                   ("dual_state", "Dual-state chi-square"), ("fsprt", "Fading SPRT"),
                                                   ("isolated", "Rail model isolated"))), name="Detectors"))
    if c.support_attitude:
        root = "plots/support_attitude"
        tabs.append(rrb.Grid(
            *(_plot(f"Support {a} [deg]", f"{root}/angles/{a}/**") for a in ANGLES),
            *(_plot(f"Support {a} error [deg]", f"{root}/errors/{a}/**") for a in ANGLES),
            _plot("Support magnetometer: ours' flags, shearer's field / peak", f"{root}/magnetometer/**"),
            rrb.BarChartView(name="GD-UKF objective per iteration [deg]", origin=f"{root}/gd_objective"),
            name="Supports"))
    return tabs


def face_blueprint(c: RunContents) -> rrb.Blueprint:
    """The layout of a face run's recordings (module docstring)."""
    tabs = [_face_tab(c)]
    if c.truth:
        tabs += [_face_line_tab(c), _sensors_tab(c)]
    tabs += estimate_tabs(c)
    return rrb.Blueprint(rrb.Tabs(*tabs, active_tab=0), collapse_panels=True)
