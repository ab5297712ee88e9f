"""Two Rerun recordings compared by content (what rerun-sdk 0.41 lets a writer fix; twin.view.rrd_stream)."""

from __future__ import annotations

from rerun.chunk import RrdReader


def rrd_content(path):
    """An .rrd's stores: the recording's chunks with their ids (twin.view.rrd_stream numbers them); the blueprint's
    without the store id, chunk and row ids and log_time rerun-sdk 0.41 stamps from the clock there."""
    reader = RrdReader(str(path))
    stores = [[(c.id, c.entity_path, c.to_record_batch()) for c in reader.stream(store=s).to_chunks()]
              for s in reader.recordings()]
    for store in reader.blueprints():
        chunks = [(c.entity_path, c.to_record_batch()) for c in reader.stream(store=store).to_chunks()]
        stores.append(sorted(((entity, batch.drop_columns(["rerun.controls.RowId", "log_time"])
                               .replace_schema_metadata(None)) for entity, batch in chunks), key=lambda x: x[0]))
    return [store.recording_id for store in reader.recordings()], stores


def assert_same_rrd(a, b):
    (ids_a, stores_a), (ids_b, stores_b) = rrd_content(a), rrd_content(b)
    assert ids_a == ids_b and len(stores_a) == len(stores_b)
    for store_a, store_b in zip(stores_a, stores_b):
        assert [x[:-1] for x in store_a] == [x[:-1] for x in store_b]
        for x, y in zip(store_a, store_b):
            assert x[-1].equals(y[-1], check_metadata=True), x[:-1]
