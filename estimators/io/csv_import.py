"""CSV import of sensor logs (the format: estimators.io.csvio): CSV files in, a checked run directory out.

Import policy. Rows are numbered from 1 at the first data row (the header and blank lines are not
counted). Each file is read in blocks of `BLOCK_BYTES` and written as it goes, so memory does not grow
with the size of the file.

REJECT the whole import with a one-line `LogError` naming the file, the column and the row, and the fix:

- an entry named like a stream file that is not a regular file (a directory, a FIFO, a device), or one
  that cannot be read (permissions);
- a file whose name is not a stream (the message lists the valid names);
- an empty file; a header that is not UTF-8; a declared column missing from the header, a header
  without its unit (``t`` instead of ``t[s]``), a unit other than the declared one (``t[ms]``,
  ``dtheta_x[deg]``), a column given twice;
- a file with no data rows left (header only, or every row skipped below), except ``faults.csv``
  (a log without faults);
- a row with a different number of fields than the header;
- a last row without a line break at its end: the file was cut off while written or copied, and the
  row may be a cut-off number (``0.0123`` read as ``0.01``);
- a value that is not UTF-8 text or does not parse as the column's type (text in a number column,
  ``3.0`` or an out-of-range value in an integer column);
- a value outside the physical limits of its column (estimators.io.plausible: a 1e300 increment, an
  angular rate over 100 rad/s, an odometer jump faster than 20 m/s, a latitude over 90 degrees);
- time going backwards (any stream with a time order), or a repeated time in a stream whose time
  must increase strictly (one row per time, e.g. imu); repeated times are fine where several rows
  share a time (one row per support, e.g. pushram).

FLAG and SKIP (the import goes on; `ImportReport`, the printed summary and ``import_report.json`` say
what happened):

- a row with an empty value, NaN or +-inf in a column that does not allow NaN is dropped; the report
  counts the dropped rows and lists their row numbers (the first `MAX_LISTED`) and, per column, how
  many rows it caused to be dropped.  An empty value in a column that allows NaN reads as NaN; an
  empty value in a text column is the empty string.
- a gap in time longer than `GAP_FACTOR` times the median interval between distinct sample times is
  recorded as (t_before, t_after), not rejected: the estimators decide what a gap means.
- columns that are not part of the stream are ignored and listed.

The import is atomic: each stream is written into a temporary sibling of the run directory that is
renamed into place only when every file is complete, so a failed import leaves no run directory
behind. An existing non-empty run directory is refused.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import stat
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from estimators.io.csv_locate import ARROW_TYPES, UTF8_FIX, locate_read_error
from estimators.io.csvio import SCENARIO_FILE, header_name
from estimators.io.logformat import (
    MARKER,
    MARKER_TEXT,
    STREAMS,
    LogError,
    Stream,
    check_table,
    make_table,
    stream_writer,
)
from estimators.io.plausible import first_implausible
from estimators.io.time_steps import TimeSteps, time_steps

REPORT_FILE = "import_report.json"
GAP_FACTOR = 3.0
"""A time step longer than this many median sample intervals is reported as a gap."""
MAX_LISTED = 1000
"""At most this many skipped row numbers and gaps are listed per stream (all are counted)."""

BLOCK_BYTES = 1 << 20
"""CSV bytes parsed at a time: the import's memory scales with this (Arrow reads up to about 36 blocks ahead), not
with the file's size."""
ROW_GROUP_BLOCKS = 16
"""Blocks written as one Parquet row group (the file's footer grows with the number of row groups)."""
MAY_BE_EMPTY = ("faults",)
"""Streams whose file may hold the header only (a log without faults)."""
_HEADER_RE = re.compile(r"^([^\[\]\s]+)\[([^\[\]]*)\]$")
_MAX_HEADER_BYTES = 1 << 20


# ----------------------------------------------------------------------------------------------- import


@dataclass
class ImportReport:
    """What `import_csv` did, per stream name. Row numbers are 1-based data rows of the CSV file."""

    csv_dir: Path
    run_dir: Path
    rows: dict[str, int] = field(default_factory=dict)
    """Rows written."""
    skipped: dict[str, list[int]] = field(default_factory=dict)
    """Row numbers dropped for an empty/NaN value (the first MAX_LISTED)."""
    skipped_count: dict[str, int] = field(default_factory=dict)
    skipped_columns: dict[str, dict[str, int]] = field(default_factory=dict)
    """For each column, the number of rows with an empty/NaN value there."""
    gaps: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    """(t_before, t_after) of each gap (the first MAX_LISTED)."""
    gap_count: dict[str, int] = field(default_factory=dict)
    median_dt: dict[str, float] = field(default_factory=dict)
    """Median interval between distinct sample times (NaN for fewer than two)."""
    extra_columns: dict[str, list[str]] = field(default_factory=dict)
    """Header entries that are not columns of the stream; they were not imported."""
    scenario: bool = False
    """Whether scenario.toml was copied."""

    def to_dict(self) -> dict:
        d = asdict(self)
        d["csv_dir"], d["run_dir"] = str(self.csv_dir), str(self.run_dir)
        d["gaps"] = {k: [[float(a), float(b)] for a, b in v] for k, v in self.gaps.items()}
        d["median_dt"] = {k: (None if math.isnan(v) else v) for k, v in self.median_dt.items()}
        return d

    def summary(self) -> str:
        lines = []
        for name, n in self.rows.items():
            line = f"{name}: {n} rows"
            if self.skipped_count.get(name):
                cols = ", ".join(f"{c} {k}" for c, k in self.skipped_columns[name].items() if k)
                line += f", {self.skipped_count[name]} skipped (empty/NaN: {cols})"
            if self.gap_count.get(name):
                line += (f", {self.gap_count[name]} gaps > {GAP_FACTOR:g} x median dt "
                         f"{self.median_dt[name]:.6g} s")
            if self.extra_columns.get(name):
                line += f", ignored columns {', '.join(self.extra_columns[name])}"
            lines.append(line)
        return "\n".join(lines)


def import_csv(csv_dir: Path, run_dir: Path, block_bytes: int = BLOCK_BYTES) -> ImportReport:
    """Import the stream CSV files of `csv_dir` into a new run directory `run_dir` (see the module policy)."""
    csv_dir, run_dir = Path(csv_dir), Path(run_dir)
    if not csv_dir.is_dir():
        raise LogError(f"{csv_dir}: not a directory")
    if run_dir.exists() and (not run_dir.is_dir() or any(run_dir.iterdir())):
        raise LogError(f"{run_dir}: already exists and is not empty; import into a new run directory")
    entries = sorted(p for p in csv_dir.iterdir() if p.suffix.lower() == ".csv")
    valid = ", ".join(f"{name}.csv" for name in STREAMS)
    for p in entries:
        if p.stem not in STREAMS or p.suffix != ".csv":
            raise LogError(f"{p}: not a stream file name; valid names are {valid}")
        _check_regular_file(p)
    if not entries:
        raise LogError(f"{csv_dir}: no stream CSV files (valid names are {valid})")
    scenario = csv_dir / SCENARIO_FILE
    report = ImportReport(csv_dir=csv_dir, run_dir=run_dir, scenario=scenario.exists())
    if report.scenario:
        _check_regular_file(scenario)

    run_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = run_dir.parent / f".{run_dir.name}.import-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        for p in entries:
            _import_file(STREAMS[p.stem], p, tmp, report, block_bytes)
        if report.scenario:
            shutil.copyfile(scenario, tmp / SCENARIO_FILE)
        (tmp / REPORT_FILE).write_text(json.dumps(report.to_dict(), indent=1) + "\n")
        (tmp / MARKER).write_text(MARKER_TEXT)
        if run_dir.exists():
            run_dir.rmdir()  # empty (checked above); rename cannot replace it portably
        os.rename(tmp, run_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return report


def _check_regular_file(path: Path) -> None:
    """LogError unless `path` is a regular file this process can read."""
    try:
        mode = path.stat().st_mode
    except OSError as err:
        raise LogError(f"{path}: cannot be read ({err.strerror}); check the file") from None
    if not stat.S_ISREG(mode):
        kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file (a FIFO, socket or device)"
        raise LogError(f"{path}: {kind}; a stream CSV must be a regular file, move it out of the CSV directory")
    if not os.access(path, os.R_OK):
        raise LogError(f"{path}: no permission to read it; give read permission (chmod u+r) or copy the file")


def _read_header(path: Path) -> list[str]:
    try:
        with open(path, "rb") as f:
            line = f.readline(_MAX_HEADER_BYTES)
            if len(line) == _MAX_HEADER_BYTES and not line.endswith(b"\n"):
                raise LogError(f"{path}: header row longer than {_MAX_HEADER_BYTES} bytes; is this a CSV file of "
                               f"name[unit] columns?")
    except OSError as err:
        raise LogError(f"{path}: cannot be read ({err.strerror}); check the file") from None
    if not line.strip():
        raise LogError(f"{path}: empty file, expected a header row of name[unit] columns")
    try:
        text = line.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise LogError(f"{path}: header row byte {err.start + 1} ({line[err.start]:#04x}) is not UTF-8 text; "
                       f"{UTF8_FIX}") from None
    try:
        header = next(csv.reader([text.rstrip("\r\n")]))
    except (csv.Error, StopIteration) as err:
        raise LogError(f"{path}: header row unreadable ({err}); write one name[unit] per column") from None
    return [h.strip() for h in header]


def _match_header(stream: Stream, path: Path, header: list[str]) -> tuple[dict[str, int], list[str]]:
    """Map each declared column to its position in the header; return that and the extra header entries."""
    declared = {c.name: c for c in stream.columns}
    position: dict[str, int] = {}
    extra = []
    for i, h in enumerate(header):
        m = _HEADER_RE.match(h)
        name, unit = (m.group(1), m.group(2)) if m else (h, None)
        c = declared.get(name)
        if c is None:
            extra.append(h if h else f"(column {i + 1}, no name)")
            continue
        if unit is None:
            raise LogError(f"{path}: column '{name}' header row: no unit, the header must read "
                           f"'{header_name(c)}'")
        if unit != c.unit:
            raise LogError(f"{path}: column '{name}' header row: unit '{unit}', expected '{c.unit}' "
                           f"(header '{header_name(c)}')")
        if name in position:
            raise LogError(f"{path}: column '{name}' header row: given twice (columns {position[name] + 1} "
                           f"and {i + 1})")
        position[name] = i
    for c in stream.columns:
        if c.name not in position:
            raise LogError(f"{path}: column '{c.name}' header row: missing; expected '{header_name(c)}' "
                           f"({c.doc})")
    return position, extra


def _import_file(stream: Stream, path: Path, out_dir: Path, report: ImportReport, block_bytes: int) -> None:
    """Read `path` block by block, check and write each block to out_dir's stream file, then report on it."""
    header = _read_header(path)
    position, extra = _match_header(stream, path, header)
    names = [f"c{i}" for i in range(len(header))]
    by_col = {c.name: names[position[c.name]] for c in stream.columns}
    read_options = pacsv.ReadOptions(skip_rows=1, column_names=names, block_size=block_bytes)
    parse_options = pacsv.ParseOptions(newlines_in_values=any(c.dtype == "str" for c in stream.columns))
    convert_options = pacsv.ConvertOptions(
        include_columns=list(by_col.values()),
        column_types={by_col[c.name]: ARROW_TYPES[c.dtype] for c in stream.columns},
        null_values=[""], strings_can_be_null=False, quoted_strings_can_be_null=True,
    )
    rows = written = skipped = 0
    before: dict[str, float] = {}
    dropped: list[int] = []
    per_column = {c.name: 0 for c in stream.columns if c.dtype != "str" and not c.nan_ok}
    out_path = out_dir / stream.filename
    pending: list[pa.Table] = []
    try:
        with stream_writer(out_path, make_table(stream, {c.name: [] for c in stream.columns}).schema) as writer:
            for batch in pacsv.open_csv(path, read_options=read_options, parse_options=parse_options,
                                        convert_options=convert_options):
                out, drop = _block(stream, path, batch, by_col, rows, before, per_column)
                dropped += [rows + int(i) + 1 for i in drop[: max(0, MAX_LISTED - len(dropped))]]
                skipped += int(drop.size)
                if out.num_rows:
                    pending.append(out)
                    before = {k: out.column(k)[-1].as_py() for k in ("t", "distance") if k in out.column_names}
                if len(pending) == ROW_GROUP_BLOCKS:
                    writer.write_table(pa.concat_tables(pending))
                    pending.clear()
                rows += batch.num_rows
                written += out.num_rows
            if pending:
                writer.write_table(pa.concat_tables(pending))
    except pa.ArrowException as err:
        raise LogError(locate_read_error(stream, path, header, position, str(err), block_bytes)) from None
    except OSError as err:
        raise LogError(f"{path}: cannot be read ({err}); check the file") from None
    if written == 0 and stream.name not in MAY_BE_EMPTY:
        what = f"all {rows} rows have empty or NaN values" if rows else "the header only, no data rows"
        raise LogError(f"{path}: {what}; a stream file needs its samples (or leave the file out)")
    if rows and not _ends_with_line_break(path):
        raise LogError(f"{path}: row {rows}: no line break after the last row, the file looks cut off (the row may "
                       f"be cut short); end the row with a line break if it is complete, else delete it")

    name = stream.name
    steps = time_steps(out_path, GAP_FACTOR, MAX_LISTED) if stream.time_order != "none" else TimeSteps(math.nan)
    report.rows[name] = written
    report.skipped[name] = dropped
    report.skipped_count[name] = skipped
    report.skipped_columns[name] = per_column
    report.gaps[name] = steps.gaps
    report.gap_count[name] = steps.gap_count
    report.median_dt[name] = steps.median
    report.extra_columns[name] = extra


def _block(stream: Stream, path: Path, raw: pa.RecordBatch, by_col: dict[str, str], rows: int,
           before: dict[str, float], per_column: dict[str, int]) -> tuple[pa.Table, np.ndarray]:
    """One block of CSV rows: the stream table of its kept rows and the indices of the dropped ones in the block.

    `rows` counts the rows of the blocks before, `before` holds their last kept row; `per_column` is updated."""
    drop = np.zeros(raw.num_rows, dtype=bool)
    for c in stream.columns:
        if c.name in per_column:
            col = raw.column(by_col[c.name])
            bad = np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
            if c.dtype == "f8":
                bad |= ~np.isfinite(col.to_numpy(zero_copy_only=False))
            per_column[c.name] += int(bad.sum())
            drop |= bad
    kept, dropped = np.flatnonzero(~drop), np.flatnonzero(drop)
    table = pa.Table.from_batches([raw]).filter(pa.array(~drop)) if dropped.size else pa.Table.from_batches([raw])
    data = {}
    for c in stream.columns:
        col = table.column(by_col[c.name])
        if c.dtype == "str":
            data[c.name] = col.to_pylist()
        elif c.nan_ok:
            data[c.name] = col.fill_null(math.nan).to_numpy(zero_copy_only=False)
        else:
            data[c.name] = col.to_numpy(zero_copy_only=False)
    out = make_table(stream, data)

    if stream.time_order != "none" and out.num_rows:
        offset = 1 if "t" in before else 0  # the block's first time is checked against the block before
        t = np.concatenate(([before["t"]], data["t"])) if offset else data["t"]
        dt = np.diff(t)
        bad = np.flatnonzero(dt <= 0 if stream.time_order == "increasing" else dt < 0)
        if bad.size:
            i = bad[0]
            was, now = float(t[i]), float(t[i + 1])
            what = (f"time goes backwards from {was!r} to {now!r}" if now < was
                    else f"time {was!r} repeats (must increase strictly)")
            row = rows + kept[i + 1 - offset] + 1
            raise LogError(f"{path}: column 't' row {row}: {what}; sort the rows by time or delete the row")
    found = first_implausible(stream.name, out, before)
    if found is not None:
        i, column, what = found
        raise LogError(f"{path}: column '{column}' row {rows + kept[i] + 1}: {what}; check the column's unit "
                       f"and the row")
    check_table(stream, out, str(path), before)  # safety net: what is written is what read_stream accepts
    return out, dropped


def _ends_with_line_break(path: Path) -> bool:
    with open(path, "rb") as f:
        f.seek(-1, os.SEEK_END)
        return f.read(1) in (b"\n", b"\r")
