"""CSV exchange of sensor logs: export a run directory to CSV, import CSV logs as a run directory.

A CSV log is a directory with one file per stream, named after the stream (``imu.csv``,
``odometer.csv``, ..., the names of `logformat.STREAMS`), plus ``scenario.toml`` if there is one.
Each file is comma-separated UTF-8 with one header row giving every column as ``name[unit]``
(``t[s],dtheta_x[rad],...``, units exactly as declared in `logformat`), then one row per sample.
Export writes floats in the shortest form that reads back to the same float64 (NaN as ``nan``),
integers as integers and strings quoted, so a run directory exported and imported back gives
identical streams. Columns may come in any order.

Import (the policy for what is rejected, flagged and skipped): estimators.io.csv_import.
"""

from __future__ import annotations

import os
import shutil
import uuid
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pacsv

from estimators.io.logformat import (
    STREAMS,
    Column,
    LogError,
    Stream,
    read_stream,
)

SCENARIO_FILE = "scenario.toml"
_CHUNK_ROWS = 1 << 18



def header_name(column: Column) -> str:
    """The CSV header of a column: ``name[unit]``."""
    return f"{column.name}[{column.unit}]"


# ----------------------------------------------------------------------------------------------- export


def export_csv(run_dir: Path, out_dir: Path) -> list[Path]:
    """Write every stream of `run_dir` as ``out_dir/<stream>.csv`` and copy the scenario file.

    Each stream is read with `read_stream` (so it is checked first) and written with its declared
    columns in declared order under a ``name[unit]`` header. Returns the files written.
    """
    run_dir, out_dir = Path(run_dir), Path(out_dir)
    if not run_dir.is_dir():
        raise LogError(f"{run_dir}: not a run directory")
    present = [s for s in STREAMS.values() if (run_dir / s.filename).is_file()]
    if not present:
        expected = ", ".join(s.filename for s in STREAMS.values())
        raise LogError(f"{run_dir}: no stream files (expected any of {expected})")
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for stream in present:
        table = read_stream(run_dir, stream).select([c.name for c in stream.columns])
        written.append(_write_csv(stream, table, out_dir / f"{stream.name}.csv"))
    scenario = run_dir / SCENARIO_FILE
    if scenario.is_file():
        written.append(Path(shutil.copyfile(scenario, out_dir / SCENARIO_FILE)))
    return written


def _write_csv(stream: Stream, table: pa.Table, path: Path) -> Path:
    """Header line, then the rows formatted by Arrow in parallel chunks (Arrow releases the GIL) and
    written in order. Arrow formats float64 as the shortest string that parses back to the same value."""
    workers = max(1, min(8, os.cpu_count() or 1))
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        with pa.OSFile(str(tmp), "wb") as sink, ThreadPoolExecutor(workers) as pool:
            sink.write((",".join(header_name(c) for c in stream.columns) + "\n").encode())
            pending: deque = deque()
            for start in range(0, table.num_rows, _CHUNK_ROWS):
                pending.append(pool.submit(_csv_rows, table.slice(start, _CHUNK_ROWS)))
                if len(pending) > 2 * workers:  # bounded memory: write as the chunks come in order
                    sink.write(pending.popleft().result())
            while pending:
                sink.write(pending.popleft().result())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def _csv_rows(table: pa.Table) -> pa.Buffer:
    out = pa.BufferOutputStream()
    pacsv.write_csv(table, out, pacsv.WriteOptions(include_header=False))
    return out.getvalue()
