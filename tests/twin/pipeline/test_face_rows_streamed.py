"""The supports' truth as a streaming run hands it on: rows recorded in blocks (out of order across them) come out
final in the whole table's order (FinalRows), and each support's advance at each cycle's end gathered block by block
is the whole table's (LatestAt)."""

from __future__ import annotations

import numpy as np

from twin.pipeline.face_recorder import FinalRows, concat_rows
from twin.view.summary import LatestAt, latest_per_id


def recorded_blocks(rng: np.random.Generator, n_blocks: int = 12, n_sup: int = 9):
    """Blocks of support rows as a recorder makes them: each block's rows from its event's start on, some before the
    previous block's last row (an event's trace against the legs' rows), equal times and supports repeated; with
    each block the time before which no later row comes."""
    blocks, finals, t0 = [], [], 0.0
    for k in range(n_blocks):
        n = int(rng.integers(0, 40))
        t = np.round(t0 + rng.uniform(0.0, 30.0, n), 1)  # repeated times
        blocks.append({"t": t, "support": rng.integers(0, n_sup, n), "advance": rng.normal(size=n),
                       "row": np.arange(n) + 1000 * k})
        t0 += 20.0
        finals.append(t0)
    finals[-1] = np.inf
    return blocks, finals


def test_final_rows_joined_are_the_whole_table_in_order():
    rng = np.random.default_rng(7)
    for _ in range(20):
        blocks, finals = recorded_blocks(rng)
        out = FinalRows()
        parts = [out.split(concat_rows([b]) if b["t"].size else b, t) for b, t in zip(blocks, finals)]
        whole = concat_rows(blocks)
        for key in whole:
            np.testing.assert_array_equal(np.concatenate([p[key] for p in parts]), whole[key], err_msg=key)
        for part, t_final in zip(parts, finals):
            assert np.all(part["t"] < t_final)


def test_latest_at_cycle_ends_block_by_block_is_latest_per_id():
    rng = np.random.default_rng(8)
    n_sup = 9
    for _ in range(20):
        blocks, finals = recorded_blocks(rng, n_sup=n_sup)
        whole = concat_rows(blocks)
        first = {"t": np.zeros(n_sup), "support": np.arange(n_sup), "advance": np.zeros(n_sup), "row": -np.ones(n_sup)}
        whole = concat_rows([first, whole])  # every support has a row at t = 0, as a run records
        # cycle ends (increasing), one exactly at a row's time
        t_end = np.sort(np.append(rng.uniform(0.0, whole["t"][-1] + 10.0, 5), whole["t"][whole["t"].size // 2]))
        cuts = np.sort(rng.integers(0, whole["t"].size, 5))
        latest = LatestAt(t_end, n_sup)
        for a, b in zip([0, *cuts], [*cuts, whole["t"].size]):
            latest.add(whole["t"][a:b], whole["support"][a:b], whole["advance"][a:b])
        got = latest.finish()
        want = np.stack([whole["advance"][latest_per_id(whole["t"], whole["support"], n_sup, te)] for te in t_end])
        np.testing.assert_array_equal(got, want)
