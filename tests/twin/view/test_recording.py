"""twin.view.recording: a synthetic run written to .rrd and read back with rerun.chunk.RrdReader."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
from rerun.chunk import RrdReader

from estimators.io.logformat import (
    STREAMS,
    TRUTH_CYCLES,
    TRUTH_PANS,
    TRUTH_SHEARER,
    TRUTH_SUPPORTS,
    make_table,
)
from twin.config.scenario import Face, Scenario
from twin.view.recording import write_recording
from twin.view.rerun_columns import TIMELINE
from twin.view.row_cuts import MARKER_STEP_M, decimate


def synthetic_truth(n_pans: int = 4, n_supports: int = 4, n_updates: int = 3, shearer_s: float = 5.0,
                    shearer_hz: float = 200.0, pan_length: float = 1.75,
                    seed: int = 0) -> dict[str, pa.Table]:
    """Truth tables shaped like a run: all pans at t = 0, then a changing subset at each later update."""
    rng = np.random.default_rng(seed)
    # Pans: full set at t=0, then every other pan (alternating) at each later time.
    t_list, pan_list = [np.zeros(n_pans)], [np.arange(n_pans)]
    for k in range(1, n_updates):
        pans = np.arange(k % 2, n_pans, 2)
        t_list.append(np.full(pans.size, 10.0 * k))
        pan_list.append(pans)
    t = np.concatenate(t_list)
    pan = np.concatenate(pan_list)
    n = t.size
    yaw = rng.normal(0, 0.005, n)
    pans = make_table(TRUTH_PANS, {
        "t": t, "pan": pan,
        "p_t_e": 0.05 * t, "p_t_n": (pan + 0.5) * pan_length, "p_t_u": np.full(n, 0.35),
        "q_tp_w": np.cos(yaw / 2), "q_tp_x": np.zeros(n), "q_tp_y": np.zeros(n), "q_tp_z": np.sin(yaw / 2),
        "bend_h": np.where(pan == n_pans - 1, np.nan, rng.normal(0, 0.01, n)),
        "bend_v": np.where(pan == n_pans - 1, np.nan, rng.normal(0, 0.01, n)),
        "advance": 0.05 * t,
    })
    # Supports: same pattern.
    st = np.concatenate([np.zeros(n_supports)] + [np.full(n_supports, 10.0 * k + 5.0) for k in range(1, n_updates)])
    sid = np.tile(np.arange(n_supports), n_updates)
    m = st.size
    supports = make_table(TRUTH_SUPPORTS, {
        "t": st, "support": sid,
        "p_t_e": -1.2 + 0.01 * st, "p_t_n": (sid + 0.5) * pan_length, "p_t_u": np.zeros(m),
        "advance": 0.01 * st, "ram": 1.2 + 0.1 * rng.random(m), "ram_pressure": np.full(m, 2.0),
        "canopy": np.full(m, 3.0), "leg_pressure": np.full(m, 31.5),
        "set": (sid % 2).astype(np.int8),
    })
    # Shearer: straight run along the face, one cycle change half way.
    ts = np.arange(int(round(shearer_s * shearer_hz))) / shearer_hz
    k = ts.size
    zeros, ones = np.zeros(k), np.ones(k)
    shearer = make_table(TRUTH_SHEARER, {
        "t": ts, "lat": np.full(k, np.radians(34.27)), "lon": np.full(k, np.radians(117.18)), "h": ones * 36.9,
        "p_t_e": 0.5 * ones, "p_t_n": 5.0 + 0.13 * ts, "p_t_u": 1.25 * ones,
        "v_n_e": zeros, "v_n_n": 0.13 * ones, "v_n_u": zeros,
        "q_nb_w": ones, "q_nb_x": zeros, "q_nb_y": zeros, "q_nb_z": zeros,
        **{f"{p}_{a}": zeros for p in ("w_ib_b", "w_nb_b", "f_b") for a in "xyz"},
        "s": 5.0 + 0.13 * ts, "pan_rear": np.zeros(k, np.int32), "pan_front": np.ones(k, np.int32),
        "cycle": (ts >= shearer_s / 2).astype(np.int32), "phase": np.ones(k, np.int8),
    })
    cycles = make_table(TRUTH_CYCLES, {
        "cycle": np.array([0, 1]), "direction": np.array([1, -1]), "t": np.array([0.0, shearer_s / 2]),
        "t_cut_end": np.array([1.0, 3.5]), "t_sump_end": np.array([1.5, 4.0]),
        "t_push_end": np.array([2.0, 4.5]), "t_end": np.array([shearer_s / 2, shearer_s]),
        "s_sump": np.array([10.0, 10.0]),
    })
    return {"truth_shearer": shearer, "truth_pans": pans, "truth_supports": supports, "truth_cycles": cycles}


def flat_floor(n_pans: int = 4, pan_length: float = 1.75) -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.linspace(-5, 5, 6), np.linspace(0, n_pans * pan_length, 5), indexing="ij")
    vertices = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    ij = np.arange(x.size).reshape(x.shape)
    a, b, c, d = ij[:-1, :-1].ravel(), ij[1:, :-1].ravel(), ij[1:, 1:].ravel(), ij[:-1, 1:].ravel()
    return vertices, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def _sim_times(chunks, entity: str) -> np.ndarray:
    """Distinct sim_time values [s] of an entity's temporal chunks."""
    values = [chunk.to_record_batch().column(TIMELINE).cast(pa.int64()).to_numpy()
              for chunk in chunks if chunk.entity_path == entity and not chunk.is_static]
    return np.unique(np.concatenate(values)) / 1e9 if values else np.zeros(0)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("run") / "run.rrd"
    # model_construct: the geometry fields only, without the whole-run consistency checks.
    scn = Scenario.model_construct(name="test", face=Face(azimuth_deg=30.0))
    write_recording(path, scn, synthetic_truth(), flat_floor())
    return path


def test_entities_and_times(recording):
    reader = RrdReader(recording)
    assert len(reader.recordings()) == 1
    assert reader.recordings()[0].application_id == "longwall-twin"
    assert reader.blueprints() == []  # the layout is handed to the viewer (twin.view.layout), not stored
    chunks = reader.stream().to_chunks()
    entities = {c.entity_path for c in chunks}
    expected = {"/world/floor", "/world/pans/boxes", "/world/pans/spheres", "/world/supports/boxes",
                "/world/supports/cylinders", "/world/rams", "/world/shearer", "/world/shearer/boxes",
                "/world/shearer/cylinders", "/world/shearer_path", "/plots/shearer_speed", "/plots/cycle",
                "/plots/bend_horizontal_deg", "/plots/bend_vertical_deg", "/plots/ram_length", "/plan/axes", "/plan/pans",
                "/plan/truth/path", "/plan/truth/position"}
    assert expected <= entities, expected - entities
    for entity in ("/world/floor", "/world/shearer/boxes", "/world/shearer/cylinders", "/world/shearer_path",
                   "/plan/axes"):
        assert all(c.is_static for c in chunks if c.entity_path == entity)

    for entity in ("/world/pans/boxes", "/world/pans/spheres", "/plan/pans", "/plots/bend_horizontal_deg"):
        np.testing.assert_allclose(_sim_times(chunks, entity), [0.0, 10.0, 20.0])
    np.testing.assert_allclose(_sim_times(chunks, "/world/supports/cylinders"), [0.0, 15.0, 25.0])
    np.testing.assert_allclose(_sim_times(chunks, "/plan/truth/path"), [0.0, 2.5])  # each cycle's path at its start
    np.testing.assert_allclose(_sim_times(chunks, "/plots/ram_length"), [0.0, 15.0, 25.0])
    shearer_t = _sim_times(chunks, "/world/shearer")
    # 5 s at 200 Hz at 0.13 m/s: on the 10 Hz grid, a row as each MARKER_STEP_M (0.05 m) of travel is passed (the
    # drawn shearer at most that and a frame behind), and the last sample 4.995.
    np.testing.assert_allclose(shearer_t[:-1], np.round(shearer_t[:-1] * 10) / 10, atol=1e-9)
    assert np.diff(shearer_t).max() * 0.13 <= MARKER_STEP_M + 0.013 + 1e-9
    assert shearer_t.size <= 0.13 * 5 / MARKER_STEP_M + 2 and shearer_t[-1] == 4.995
    # The constant speed is drawn by its first and last rows.
    np.testing.assert_allclose(_sim_times(chunks, "/plots/shearer_speed"), [0.0, 4.995])


@pytest.mark.parametrize("rate_hz, shearer_rows", [(None, 1000), (2.0, 11)])
def test_record_rate_of_the_run_recording(tmp_path, rate_hz, shearer_rows):
    """At FULL rate (None) every truth sample of the shearer (5 s at 200 Hz) and of its speed; at 2 Hz one row each
    0.5 s and the last (the shearer moves 0.065 m in 0.5 s, more than MARKER_STEP_M)."""
    path = tmp_path / "run.rrd"
    scn = Scenario.model_construct(name="test", face=Face(azimuth_deg=30.0))
    write_recording(path, scn, synthetic_truth(), flat_floor(), rate_hz=rate_hz)
    chunks = RrdReader(path).stream().to_chunks()
    assert _sim_times(chunks, "/world/shearer").size == shearer_rows
    assert _sim_times(chunks, "/plots/shearer_speed").size == (1000 if rate_hz is None else 2)  # a flat line


def _instances(chunks, entity: str, component: str) -> list:
    """Each temporal row's instances of `component` of `entity`, in time order."""
    rows = []
    for chunk in chunks:
        if chunk.entity_path == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            times = batch.column(TIMELINE).cast(pa.int64()).to_numpy()
            rows += [(t, x) for t, x in zip(times, batch.column(component).to_pylist()) if x is not None]
    return [x for _, x in sorted(rows, key=lambda row: row[0])]


def _static(chunks, entity: str, component: str) -> np.ndarray:
    (values,) = [x for c in chunks if c.entity_path == entity and c.is_static
                 for x in c.to_record_batch().column(component).to_pylist() if x is not None]
    return np.asarray(values, float)


def test_the_mjcf_geoms_of_every_body(recording):
    """Pans, supports and the shearer are drawn with every geom of their MJCF piece's bodies, by type (boxes,
    cylinders, spheres): every pan- and support-update time carries all 4 pans' and supports' geoms even though only
    some changed; the shearer's, static in its frame, have the compiled piece's sizes and places."""
    import mujoco

    from twin.face.model import piece_model

    scn = Scenario.model_construct(name="test", face=Face(azimuth_deg=30.0))
    chunks = RrdReader(recording).stream().to_chunks()
    kinds = {"boxes": mujoco.mjtGeom.mjGEOM_BOX, "cylinders": mujoco.mjtGeom.mjGEOM_CYLINDER,
             "spheres": mujoco.mjtGeom.mjGEOM_SPHERE}
    archetype = {"boxes": "Boxes3D", "cylinders": "Cylinders3D", "spheres": "Ellipsoids3D"}
    for piece, bodies, entity in (("pan", ("pan",), "/world/pans"), ("support", ("support", "canopy"), "/world/supports")):
        model = piece_model(scn, piece)
        ids = [model.body(b).id for b in bodies]
        for shape, kind in kinds.items():
            per_body = int(np.isin(model.geom_bodyid[model.geom_type == kind], ids).sum())
            rows = _instances(chunks, f"{entity}/{shape}", f"{archetype[shape]}:centers")
            assert [len(x) for x in rows] == ([4 * per_body] * 3 if per_body else []), (entity, shape)
    # A pan's trough: its body origin (the running line) less the geom's offset, the pans standing level in t.
    pan = piece_model(scn, "pan")
    trough = pan.geom("trough")
    boxes = np.asarray(_instances(chunks, "/world/pans/boxes", "Boxes3D:centers")[0], float)
    assert boxes.shape == (8, 3)
    truth = synthetic_truth()["truth_pans"]
    first = truth.column("p_t_u").to_numpy()[0]
    np.testing.assert_allclose(boxes[0, 2], first + trough.pos[2], atol=1e-3)  # the pans' yaw keeps z

    model = piece_model(scn, "shearer")
    body = model.body("shearer").id
    assert model.body_geomnum[body] == 5  # body, two ranging arms, two drums
    drums = model.geom_type == mujoco.mjtGeom.mjGEOM_CYLINDER
    np.testing.assert_allclose(_static(chunks, "/world/shearer/cylinders", "Cylinders3D:radii"),
                               model.geom_size[drums, 0])
    np.testing.assert_allclose(_static(chunks, "/world/shearer/cylinders", "Cylinders3D:centers"),
                               model.geom_pos[drums], atol=1e-6)
    np.testing.assert_allclose(_static(chunks, "/world/shearer/boxes", "Boxes3D:half_sizes"),
                               model.geom_size[model.geom_type == mujoco.mjtGeom.mjGEOM_BOX], atol=1e-6)
    lengths = []
    for chunk in chunks:
        if chunk.entity_path == "/world/rams" and not chunk.is_static:
            lengths += [len(x) for x in chunk.to_record_batch().column("LineStrips3D:strips").to_pylist()
                        if x is not None]
    assert lengths == [4] * 3
    bars = []
    for chunk in chunks:
        if chunk.entity_path == "/plots/bend_horizontal_deg" and not chunk.is_static:
            for row in chunk.to_record_batch().column("BarChart:values").to_pylist():
                (tensor,) = row
                bars.append(tensor["shape"])
    assert bars == [[3]] * 3


def test_decimate():
    t = np.arange(2000) / 200.0
    idx = decimate(t, 10.0)
    assert idx.size == 101 and idx[0] == 0 and idx[-1] == 1999
    np.testing.assert_allclose(t[idx[:100]], np.arange(100) / 10)


def test_open_viewer_errors(tmp_path, monkeypatch):
    import twin.view.layout as layout

    with pytest.raises(FileNotFoundError, match="run.rrd"):
        layout.open_viewer(tmp_path)
    (tmp_path / "run.rrd").write_bytes(b"")
    monkeypatch.setattr(layout.sys, "executable", str(tmp_path / "bin" / "python"))
    monkeypatch.setattr(layout.shutil, "which", lambda name: None)
    with pytest.raises(FileNotFoundError, match="rerun viewer executable not found"):
        layout.open_viewer(tmp_path)


def test_latest_rows_forward_fill():
    from twin.view.rerun_columns import latest_rows

    # Rows: t=0 pans 0..2; t=5 pan 1; t=9 pans 2, 0 (unsorted); pan 3 first seen at t=5.
    t = np.array([0.0, 0.0, 0.0, 5.0, 9.0, 9.0, 5.0])
    ident = np.array([0, 1, 2, 1, 2, 0, 3])
    times, ids, rows = latest_rows(t, ident)
    np.testing.assert_array_equal(times, [0.0, 5.0, 9.0])
    np.testing.assert_array_equal(ids, [0, 1, 2, 3])
    np.testing.assert_array_equal(rows, [[0, 1, 2, 6], [0, 3, 2, 6], [5, 3, 4, 6]])


def _bars(chunks, entity: str) -> np.ndarray:
    """(times, values) of an entity's BarChart rows, values (T, N) in time order."""
    times, rows = [], []
    for chunk in chunks:
        if chunk.entity_path == entity and not chunk.is_static:
            batch = chunk.to_record_batch()
            times += list(batch.column(TIMELINE).cast(pa.int64()).to_numpy() / 1e9)
            rows += [np.asarray(row[0]["buffer"], float) for row in batch.column("BarChart:values").to_pylist()]
    order = np.argsort(times)
    return np.asarray(times)[order], np.asarray(rows)[order]


def test_the_face_line_at_each_cycle_end(tmp_path):
    """The pan line's deviation from its best-fit straight line per pan [mm] at the start and at each cycle's end,
    against np.polyfit on the latest row of every pan in the face frame (azimuth 30 deg: x = e cos a - n sin a,
    y = e sin a + n cos a); straightness and creep beside it."""
    truth = synthetic_truth(n_pans=6)  # every pan at t = 0, then every other pan at 10 and 20 s
    truth["truth_cycles"] = make_table(TRUTH_CYCLES, {
        "cycle": np.array([0, 1]), "direction": np.array([1, -1]), "t": np.array([0.0, 12.0]),
        "t_cut_end": np.array([5.0, 17.0]), "t_sump_end": np.array([6.0, 18.0]), "t_push_end": np.array([7.0, 19.0]),
        "t_end": np.array([12.0, 22.0]), "s_sump": np.array([10.0, 10.0])})
    path = tmp_path / "run.rrd"
    write_recording(path, Scenario.model_construct(name="test", face=Face(azimuth_deg=30.0)), truth, flat_floor(6))
    chunks = RrdReader(path).stream().to_chunks()
    times, bars = _bars(chunks, "/face/pan_line_mm")
    np.testing.assert_allclose(times, [0.0, 12.0, 22.0])
    pans = {k: truth["truth_pans"].column(k).to_numpy() for k in ("t", "pan", "p_t_e", "p_t_n")}
    a = np.radians(30.0)
    for t_k, row in zip(times, bars):
        latest = [np.flatnonzero((pans["pan"] == i) & (pans["t"] <= t_k))[-1] for i in range(6)]
        e, n = pans["p_t_e"][latest], pans["p_t_n"][latest]
        x, y = e * np.cos(a) - n * np.sin(a), e * np.sin(a) + n * np.cos(a)
        np.testing.assert_allclose(row, (x - np.polyval(np.polyfit(y, x, 1), y)) * 1e3, atol=1e-6)
    assert np.abs(bars[0]).max() < 1e-6 < np.abs(bars[1]).max()  # installed straight, kinked by the pushes
    assert {"/face/straightness_mm", "/face/creep_mm"} <= {c.entity_path for c in chunks}


def _chunk_contents(path) -> list[tuple[str, pa.RecordBatch]]:
    """Each chunk of a recording without its row ids (which number the rows in logging order)."""
    out = []
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        out.append((str(chunk.entity_path), batch.select([n for n in batch.schema.names if "row" not in n.lower()])))
    return out


def _default_run():
    """The default scenario's truth and trial 0's sensors as tables, and a writer of its recording (each stream of
    BLOCK_STREAMS cut in blocks anywhere, inside a record interval and between the rows of one sample time, with
    `split`)."""
    from tests.conftest import simulated
    from twin.sensors.streams import imu_truth, sensor_streams
    from twin.view.recording import BLOCK_STREAMS

    scn, result = simulated("default")
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    tables = {name: make_table(STREAMS[name], cols) for name, cols in {**result.tables, **streams}.items()
              if name in STREAMS}

    def write(path, split):
        def cut(name, table):
            if not split or name not in BLOCK_STREAMS:
                return table
            edges = [0, 7, table.num_rows // 3 + 1, table.num_rows // 2 - 5, table.num_rows]
            return [table.slice(a, b - a) for a, b in zip(edges[:-1], edges[1:])]
        data = {name: cut(name, table) for name, table in tables.items()}
        write_recording(path, scn, {k: v for k, v in data.items() if k.startswith("truth_")},
                        result.floor_grid.mesh_t(result.frame), sensors={k: v for k, v in data.items()
                                                                          if not k.startswith("truth_")})
    return write


def test_the_long_streams_in_blocks_give_the_recording_of_whole_tables(tmp_path):
    """A run's recording reads truth_shearer, truth_supports, imu, pushram and pressure a row group at a time
    (BLOCK_STREAMS): given in blocks cut anywhere, every chunk it writes holds what the whole tables give."""
    write = _default_run()
    write(tmp_path / "whole.rrd", False)
    write(tmp_path / "blocks.rrd", True)
    whole, blocks = _chunk_contents(tmp_path / "whole.rrd"), _chunk_contents(tmp_path / "blocks.rrd")
    assert len(whole) == len(blocks) > 20
    for (entity_a, a), (entity_b, b) in zip(whole, blocks):
        assert entity_a == entity_b and a.equals(b), entity_a


def _rows(path) -> tuple[dict[tuple, pa.Table], dict[str, int]]:
    """A recording's rows as a reader sees them, however they are cut into chunks: per (entity, static, columns) its
    rows in time order, without row ids; and each entity's number of temporal chunks."""
    parts, counts = {}, {}
    for chunk in RrdReader(path).stream().to_chunks():
        batch = chunk.to_record_batch()
        batch = batch.select([n for n in batch.schema.names if "row" not in n.lower()])
        parts.setdefault((str(chunk.entity_path), chunk.is_static, tuple(batch.schema.names)), []).append(batch)
        counts[str(chunk.entity_path)] = counts.get(str(chunk.entity_path), 0) + (not chunk.is_static)
    return {key: pa.Table.from_batches(batches) if key[1] else pa.Table.from_batches(batches).sort_by(TIMELINE)
            for key, batches in parts.items()}, counts


def test_the_pans_and_supports_sent_in_chunks_are_the_rows_of_one_chunk(tmp_path, monkeypatch):
    """The pans' and supports' frames built and sent CHUNK_GEOMS geoms at a time (truth_supports in blocks): every
    entity of the recording holds the rows, at the times, of the recording sent in one chunk; the pans' and supports'
    entities are cut into chunks of as many frames as hold that many geoms."""
    import twin.view.recording as recording

    write = _default_run()
    write(tmp_path / "one.rrd", False)
    one, one_counts = _rows(tmp_path / "one.rrd")
    written = RrdReader(tmp_path / "one.rrd").stream().to_chunks()
    entities = {"supports": ("/world/supports/boxes", "/world/supports/cylinders", "/world/rams", "/plots/ram_length"),
                "pans": ("/world/pans/boxes", "/world/pans/spheres", "/plan/pans", "/plots/bend_horizontal_deg",
                         "/plots/bend_vertical_deg")}
    shapes = {"supports": (("boxes", "Boxes3D"), ("cylinders", "Cylinders3D")),
              "pans": (("boxes", "Boxes3D"), ("spheres", "Ellipsoids3D"))}
    geoms = {body: sum(len(_instances(written, f"/world/{body}/{shape}", f"{archetype}:centers")[0])
                       for shape, archetype in shapes[body]) for body in entities}  # a frame's
    frames = {body: one[(entities[body][-1], False, (TIMELINE, "BarChart:values"))].num_rows for body in entities}
    assert frames["supports"] > 100 and frames["pans"] > 30
    assert all(frames[b] * geoms[b] <= recording.CHUNK_GEOMS for b in entities)  # the default run: one chunk each
    chunk_geoms = 10 * max(geoms.values()) + 5
    monkeypatch.setattr(recording, "CHUNK_GEOMS", chunk_geoms)
    write(tmp_path / "chunks.rrd", True)
    chunks, chunk_counts = _rows(tmp_path / "chunks.rrd")
    assert one.keys() == chunks.keys()
    for key, table in one.items():
        assert table.equals(chunks[key]), key
    for body, names in entities.items():
        per_chunk = chunk_geoms // geoms[body]
        assert [(one_counts[e], chunk_counts[e]) for e in names] == [(1, -(-frames[body] // per_chunk))] * len(names)
    cut = entities["supports"] + entities["pans"]
    assert {e: n for e, n in one_counts.items() if e not in cut} == {e: n for e, n in chunk_counts.items()
                                                                      if e not in cut}


def test_the_plan_view_in_the_face_frame(recording):
    """The plan's true path: along the face (y_F) across, -PLAN_SCALE times the advance (x_F) less one web depth a
    cycle up (a 2-D view's y points down): the synthetic shearer (e 0.5, n 5 + 0.13 t at azimuth 30 deg) by hand."""
    from twin.view.plan import PLAN_SCALE

    chunks = RrdReader(recording).stream().to_chunks()
    strips = _instances(chunks, "/plan/truth/path", "LineStrips2D:strips")
    assert len(strips) == 2  # a strip per cycle
    a, web = np.radians(30.0), Face().web_depth_m
    for k, (strip,) in enumerate(strips):
        t0 = 2.5 * k
        e, n = 0.5, 5.0 + 0.13 * t0
        x_f, y_f = e * np.cos(a) - n * np.sin(a), e * np.sin(a) + n * np.cos(a)
        np.testing.assert_allclose(strip[0], [y_f, -PLAN_SCALE * (x_f - web * k)], rtol=1e-5, atol=1e-4)
    # The pan line at every pan-update time, one point per pan.
    assert [len(s[0]) for s in _instances(chunks, "/plan/pans", "LineStrips2D:strips")] == [4] * 3
