"""twin.view.blueprint and twin.view.layout: the layout of each kind of run, walked as a blueprint object and read back
from the .rbl the viewer gets; the Sensors tab's plots against the units the sensor recording writes."""

from __future__ import annotations

import fnmatch
import re

import numpy as np
import pyarrow as pa
import pytest
import rerun.blueprint as rrb
from rerun.chunk import RrdReader

from twin.view.blueprint import (
    HIDDEN_METHODS,
    OFF_FACE_SEP,
    SENSOR_VIEWS,
    RunContents,
    face_blueprint,
    face_eye,
    hidden_methods,
)
from twin.view.plan import PLAN_NAME, PLAN_SCALE

pytestmark = pytest.mark.slow  # the sensor units' fixture simulates the default run (about 50 s alone)

METHODS = ["dr", "dr_compensated", "kf", "kf_cpoem_rts"]


def _tabs(bp: rrb.Blueprint) -> dict[str, object]:
    return {str(tab.name): tab for tab in bp.root_container.contents}


def _views(node) -> list:
    """The views under a container, depth first."""
    if isinstance(node, rrb.Container):
        return [v for child in node.contents for v in _views(child)]
    return [node]


def _contents(view) -> list[str]:
    return [view.contents] if isinstance(view.contents, str) else list(view.contents)


def _hidden(view) -> set[str]:
    return {str(path) for path, behavior in view.visualizer_overrides.items()
            if isinstance(behavior, rrb.EntityBehavior) and not behavior.visible.as_arrow_array()[0].as_py()}


def _default(**kw) -> RunContents:
    pans = np.array([[0.0, 0.0, 30.0], [38.5, 66.7, 32.0]])  # the default face: 77 m at azimuth 30 deg
    return RunContents(truth=True, methods=METHODS, state_methods=["kf"], eye=face_eye(pans, np.radians(30.0)),
                       plan_bounds=([-2.0, 79.0], [-24.0, 8.0]), **kw)


def test_a_run_with_truth_has_the_face_the_sensors_and_a_tab_per_estimated_quantity():
    tabs = _tabs(face_blueprint(_default()))
    assert list(tabs)[:3] == ["Face", "Face line", "Sensors"]
    held = _tabs(face_blueprint(_default(streams=frozenset({"imu", "mag", "odometer", "pressure", "pushram"}))))
    sensors = [str(v.name) for v in _views(held["Sensors"])]  # no support units, no faults: no empty plots for them
    assert len(sensors) == 8 and not any("supports" in n or "Fault" in n for n in sensors)
    assert {"Horizontal error", "Position error", "Attitude error", "Position one-sigma", "Sensor states",
            "Flags"} <= set(tabs)
    names = [str(v.name) for v in _views(tabs["Face"])]
    assert names[:2] == ["Face", PLAN_NAME] and f"x{PLAN_SCALE:g}" in PLAN_NAME
    # One plot per tab quantity, every method overlaid in it; the one the tab is named for first.
    (horizontal,) = _views(tabs["Horizontal error"])
    assert _contents(horizontal) == [f"plots/errors/{m}/horizontal" for m in METHODS]
    assert [str(v.name) for v in _views(tabs["Position error"])] == [f"Position error {a} [m]"
                                                                     for a in ("east", "north", "up")]


def test_dead_reckoning_is_hidden_and_the_eye_is_on_the_face():
    """dr's entities are hidden (visible off, so a user can turn them on) in the 3-D view, the plan and every plot
    that holds them; the eye looks at the face's middle from the coal wall's side, above, the plan's bounds are the
    run's."""
    tabs = _tabs(face_blueprint(_default()))
    face, plan_view = _views(tabs["Face"])[:2]
    assert {"world/estimates/dr/path", "world/estimates/dr/position"} <= _hidden(face)
    assert {"plan/estimates/dr/path", "plan/estimates/dr/position"} <= _hidden(plan_view)
    assert not any("kf" in path for view in (face, plan_view) for path in _hidden(view))
    eye = face.properties["EyeControls3D"]
    target = np.asarray(eye.look_target.as_arrow_array().to_pylist()[0])
    position = np.asarray(eye.position.as_arrow_array().to_pylist()[0])
    np.testing.assert_allclose(target, [19.25, 33.35, 31.0])
    x_f = np.array([np.cos(np.radians(30.0)), -np.sin(np.radians(30.0)), 0.0])  # towards the coal wall
    assert (position - target) @ x_f > 20.0 and position[2] > target[2] + 5.0  # beyond the coal wall, above
    bounds = plan_view.properties["VisualBounds2D"]
    assert bounds.range.as_arrow_array().to_pylist()[0] == {"x_range": [-2.0, 79.0], "y_range": [-24.0, 8.0]}
    for view in _views(tabs["Horizontal error"]) + _views(tabs["Position error"]):
        dr = {p for p in _contents(view) if "/dr/" in p}
        assert dr and dr <= _hidden(view), view.name
    assert HIDDEN_METHODS == ("dr",)


def test_a_method_far_off_the_best_is_hidden_too():
    """With truth, a method whose SEP over the run is over OFF_FACE_SEP times the best's is hidden like dr (in the 3-D
    view, the plan and the error plots), one just under it is not; without scores only dr is."""
    sep = {"dr": 40.0, "dr_compensated": 0.2 * OFF_FACE_SEP * 1.01, "kf": 0.2 * OFF_FACE_SEP * 0.99,
           "kf_cpoem_rts": 0.2}
    hidden = hidden_methods(METHODS, sep)
    assert hidden == {"dr", "dr_compensated"} and hidden_methods(METHODS, {}) == set(HIDDEN_METHODS)
    tabs = _tabs(face_blueprint(_default(hidden=hidden)))
    face, plan_view = _views(tabs["Face"])[:2]
    (horizontal,) = _views(tabs["Horizontal error"])
    for view in (face, plan_view, horizontal):
        assert any("/dr_compensated" in p for p in _hidden(view)), view.name
        assert not any("/kf" in p for p in _hidden(view)), view.name


def test_each_kind_of_run():
    """Without truth (an imported log): the face and the estimates' one-sigma, no twin tabs and no errors; a face
    alignment run: the "Face alignment" tab with the plan, the offsets and their sequence."""
    bare = _tabs(face_blueprint(RunContents(methods=METHODS, plan_bounds=([0.0, 1.0], [0.0, 1.0]))))
    assert list(bare)[0] == "Face" and "Sensors" not in bare and "Horizontal error" not in bare
    assert "Position one-sigma" in bare
    aligned = _tabs(face_blueprint(_default(alignment=True)))
    assert "Face line" not in aligned
    names = [str(v.name) for v in _views(aligned["Face alignment"])]
    assert names[0] == PLAN_NAME and "Push offsets per support [mm]" in names
    assert any("sequence" in n for n in names)


def test_the_layout_saved_for_the_viewer(tmp_path):
    """run_blueprint of a default run directory (scenario and truth_pans only), saved as the .rbl the viewer opens:
    one blueprint whose store holds the named views and dr's hidden entities."""
    import pyarrow.parquet as pq

    from tests.conftest import capped
    from twin.config.scenario import scenario_to_toml
    from twin.view.layout import run_blueprint
    from twin.view.rerun_columns import APPLICATION_ID

    (tmp_path / "scenario.toml").write_text(scenario_to_toml(capped("default")))
    pq.write_table(pa.table({"p_t_e": [0.0, 38.5], "p_t_n": [0.0, 66.7], "p_t_u": [30.0, 32.0]}),
                   tmp_path / "truth_pans.parquet")
    for stream in ("truth_shearer", "imu"):
        pq.write_table(pa.table({"t": [0.0]}), tmp_path / f"{stream}.parquet")
    (tmp_path / "estimates").mkdir()
    for m in METHODS:
        pq.write_table(pa.table({"t": [0.0]}), tmp_path / "estimates" / f"{m}.parquet")
    bp = run_blueprint(tmp_path)
    assert "Sensors" in _tabs(bp) and "Horizontal error" in _tabs(bp)
    path = tmp_path / "layout.rbl"
    bp.save(APPLICATION_ID, path)
    reader = RrdReader(path)
    [store] = reader.blueprints()
    dumped = " ".join(f"{c.entity_path} " + " ".join(str(column) for column in c.to_record_batch().columns)
                      for c in reader.stream(store=store).to_chunks())
    for name in ("Face", PLAN_NAME, "Horizontal position error [m]", "Accelerometer, shearer [m/s^2]"):
        assert name in dumped, name
    assert "overrides/world/estimates/dr/path" in dumped  # its visibility, off


@pytest.fixture(scope="module")
def sensor_units(short_default_run, tmp_path_factory) -> dict[str, set[str]]:
    """The units ('[...]' in the series names) of each sensor entity the recording writes for the default run."""
    from estimators.io.logformat import STREAMS, read_stream
    from twin.view.record_rate import RECORD_RATE_HZ
    from twin.view.rrd_stream import recording_stream
    from twin.view.sensor_recording import log_sensors

    streams = {name: read_stream(short_default_run, STREAMS[name])
               for name in ("imu", "odometer", "mag", "support_imu", "pushram", "pressure", "faults")
               if (short_default_run / STREAMS[name].filename).is_file()}
    path = tmp_path_factory.mktemp("sensors") / "run.rrd"
    with recording_stream(path, "sensor-units") as rec:
        log_sensors(rec, streams, RECORD_RATE_HZ)
    units: dict[str, set[str]] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        if "SeriesLines:names" in batch.schema.names:
            for names in batch.column("SeriesLines:names").to_pylist():
                for name in names or ():
                    found = re.findall(r"\[([^\]]+)\]", name)
                    units.setdefault(str(chunk.entity_path).lstrip("/"), set()).update(found or ["1"])
    return units


def _matches(pattern: str, entity: str) -> bool:
    """A blueprint content pattern (`*` one path part, `/**` the path and everything under it) against an entity."""
    if pattern.endswith("/**"):
        return entity == pattern[:-3] or entity.startswith(pattern[:-2])
    return len(pattern.split("/")) == len(entity.split("/")) and fnmatch.fnmatchcase(entity, pattern)


def test_each_sensor_plot_holds_one_unit(sensor_units):
    """Every time-series view of the Sensors tab matches sensor entities of one unit, named in its title; the
    accelerometer, gyroscope and magnetometer of the shearer each have a plot."""
    assert {"sensors/imu/accel", "sensors/imu/gyro", "sensors/mag"} <= set(sensor_units)
    shown = 0
    for name, contents, _ in SENSOR_VIEWS:
        entities = [e for e in sensor_units if any(_matches(p, e) for p in contents)]
        units = set().union(*(sensor_units[e] for e in entities)) if entities else set()
        assert len(units) <= 1, (name, units)
        if entities and units != {"1"}:
            assert f"[{units.pop()}]" in name, name
        shown += bool(entities)
    assert shown >= 4
    covered = {e for e in sensor_units if any(_matches(p, e) for _, c, _ in SENSOR_VIEWS for p in c)}
    assert covered == set(sensor_units) - {e for e in sensor_units if not e.startswith(("sensors/", "faults/"))}
