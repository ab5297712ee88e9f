"""twin.opcua.blocks.BlockStream: the ring a client reads (ReadBlocks, from asyncua's thread pool) while the publisher
appends to it from the event loop: reads in another thread see whole, ordered blocks and never fail. No server."""

from __future__ import annotations

import threading

import numpy as np

from estimators.io.logformat import ODOMETER
from twin.opcua.blocks import BlockStream


def test_reads_in_another_thread_while_blocks_are_published_see_consecutive_blocks():
    stream = BlockStream(ODOMETER, history=50)
    errors, seen = [], []
    done = threading.Event()

    def reader():
        try:
            while not done.is_set():
                blocks = stream.read(1)
                sequences = [b.sequence for b in blocks]
                assert sequences == list(range(sequences[0], sequences[0] + len(sequences))) if sequences else True
                seen.append(len(blocks))
        except Exception as err:  # noqa: BLE001 - reported below
            errors.append(err)

    thread = threading.Thread(target=reader)
    thread.start()
    for k in range(20_000):
        stream.add({c.name: np.full(1, float(k), c.dtype) for c in ODOMETER.columns}, float(k) + 0.5)
        stream.publish(float(k))
    done.set()
    thread.join()
    assert not errors, errors[0]
    assert seen and stream.sequence == 20_000 and [b.sequence for b in stream.read(0)] == list(range(19_951, 20_001))
