"""CSV import of sensor logs (the format: estimators.io.csvio): CSV files in, a checked run directory out.

Import policy. Rows are numbered from 1 at the first data row (the header and blank lines are not
counted).

REJECT the whole import with a one-line `LogError` naming the file, the column and the row:

- a file whose name is not a stream (the message lists the valid names);
- a declared column missing from the header, a header without its unit (``t`` instead of ``t[s]``),
  a unit other than the declared one (``t[ms]``, ``dtheta_x[deg]``), a column given twice;
- a row with a different number of fields than the header;
- a value that does not parse as the column's type (text in a number column, ``3.0`` or an
  out-of-range value in an integer column);
- time going backwards (any stream with a time order), or a repeated time in a stream whose time
  must increase strictly (one row per time, e.g. imu); repeated times are fine where several rows
  share a time (one row per support, e.g. pushram).

FLAG and SKIP (the import goes on; `ImportReport` and ``import_report.json`` say what happened):

- a row with an empty value, NaN or +-inf in a column that does not allow NaN is dropped; the report
  counts the dropped rows and lists their row numbers (the first `MAX_LISTED`) and, per column, how
  many rows it caused to be dropped.  An empty value in a column that allows NaN reads as NaN; an
  empty value in a text column is the empty string.
- a gap in time longer than `GAP_FACTOR` times the median interval between distinct sample times is
  recorded as (t_before, t_after), not rejected: the estimators decide what a gap means.
- columns that are not part of the stream are ignored and listed.

The import is atomic: everything is parsed and checked first, then written into a temporary sibling
of the run directory that is renamed into place at the end, so a failed import leaves no run
directory behind. An existing non-empty run directory is refused.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import uuid
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv

from estimators.io.csvio import SCENARIO_FILE, header_name
from estimators.io.logformat import (
    STREAMS,
    Column,
    LogError,
    Stream,
    check_table,
    make_table,
    write_stream,
)

REPORT_FILE = "import_report.json"
GAP_FACTOR = 3.0
"""A time step longer than this many median sample intervals is reported as a gap."""
MAX_LISTED = 1000
"""At most this many skipped row numbers and gaps are listed per stream (all are counted)."""

_ARROW_TYPES = {"f8": pa.float64(), "i8": pa.int64(), "i4": pa.int32(), "i1": pa.int8(), "str": pa.string()}
_TYPE_WORDS = {"f8": "a number", "i8": "an integer", "i4": "a 32-bit integer", "i1": "an 8-bit integer",
               "str": "text"}
_HEADER_RE = re.compile(r"^([^\[\]\s]+)\[([^\[\]]*)\]$")
_CONVERSION_RE = re.compile(r"In CSV column #(\d+)")


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


def import_csv(csv_dir: Path, run_dir: Path) -> ImportReport:
    """Import the stream CSV files of `csv_dir` into a new run directory `run_dir` (see the module policy)."""
    csv_dir, run_dir = Path(csv_dir), Path(run_dir)
    if not csv_dir.is_dir():
        raise LogError(f"{csv_dir}: not a directory")
    if run_dir.exists() and (not run_dir.is_dir() or any(run_dir.iterdir())):
        raise LogError(f"{run_dir}: already exists and is not empty; import into a new run directory")
    files = sorted(p for p in csv_dir.iterdir() if p.is_file() and p.suffix.lower() == ".csv")
    valid = ", ".join(f"{name}.csv" for name in STREAMS)
    for p in files:
        if p.stem not in STREAMS or p.suffix != ".csv":
            raise LogError(f"{p}: not a stream file name; valid names are {valid}")
    if not files:
        raise LogError(f"{csv_dir}: no stream CSV files (valid names are {valid})")

    report = ImportReport(csv_dir=csv_dir, run_dir=run_dir)
    tables = [(STREAMS[p.stem], _import_file(STREAMS[p.stem], p, report)) for p in files]
    scenario = csv_dir / SCENARIO_FILE
    report.scenario = scenario.is_file()

    run_dir.parent.mkdir(parents=True, exist_ok=True)
    tmp = run_dir.parent / f".{run_dir.name}.import-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        for stream, table in tables:
            write_stream(tmp, stream, table)
        if report.scenario:
            shutil.copyfile(scenario, tmp / SCENARIO_FILE)
        (tmp / REPORT_FILE).write_text(json.dumps(report.to_dict(), indent=1) + "\n")
        if run_dir.exists():
            run_dir.rmdir()  # empty (checked above); rename cannot replace it portably
        os.rename(tmp, run_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return report


def _read_header(path: Path) -> list[str]:
    with open(path, newline="", encoding="utf-8-sig") as f:
        try:
            header = next(csv.reader(f))
        except StopIteration:
            raise LogError(f"{path}: empty file, expected a header row of name[unit] columns") from None
        except (csv.Error, UnicodeDecodeError) as err:
            raise LogError(f"{path}: header row unreadable ({err})") from None
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


def _import_file(stream: Stream, path: Path, report: ImportReport) -> pa.Table:
    header = _read_header(path)
    position, extra = _match_header(stream, path, header)
    names = [f"c{i}" for i in range(len(header))]
    by_col = {c.name: names[position[c.name]] for c in stream.columns}
    read_options = pacsv.ReadOptions(skip_rows=1, column_names=names, block_size=1 << 24)
    parse_options = pacsv.ParseOptions(newlines_in_values=any(c.dtype == "str" for c in stream.columns))
    convert_options = pacsv.ConvertOptions(
        include_columns=list(by_col.values()),
        column_types={by_col[c.name]: _ARROW_TYPES[c.dtype] for c in stream.columns},
        null_values=[""], strings_can_be_null=False, quoted_strings_can_be_null=True,
    )
    try:
        raw = pacsv.read_csv(path, read_options=read_options, parse_options=parse_options,
                             convert_options=convert_options)
    except pa.ArrowInvalid as err:
        raise LogError(_locate_read_error(stream, path, header, position, str(err))) from None

    n = raw.num_rows
    drop = np.zeros(n, dtype=bool)
    per_column = {}
    for c in stream.columns:
        col = raw.column(by_col[c.name])
        if c.dtype == "str" or c.nan_ok:
            continue
        bad = np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
        if c.dtype == "f8" and not c.nan_ok:
            bad |= ~np.isfinite(col.to_numpy(zero_copy_only=False))
        per_column[c.name] = int(bad.sum())
        drop |= bad
    kept = np.flatnonzero(~drop)
    dropped = np.flatnonzero(drop)
    table = raw.filter(pa.array(~drop)) if dropped.size else raw

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

    gaps, gap_count, median_dt = [], 0, math.nan
    if stream.time_order != "none" and "t" in data:
        t = data["t"]
        dt = np.diff(t)
        bad = np.flatnonzero(dt <= 0 if stream.time_order == "increasing" else dt < 0)
        if bad.size:
            i = bad[0]
            before, after = float(t[i]), float(t[i + 1])
            what = (f"time goes backwards from {before!r} to {after!r}" if after < before
                    else f"time {before!r} repeats (must increase strictly)")
            raise LogError(f"{path}: column 't' row {kept[i + 1] + 1}: {what}")
        distinct = t[np.concatenate(([True], dt > 0))] if t.size else t
        if distinct.size >= 2:
            steps = np.diff(distinct)
            median_dt = float(np.median(steps))
            at = np.flatnonzero(steps > GAP_FACTOR * median_dt)
            gap_count = int(at.size)
            gaps = [(float(distinct[j]), float(distinct[j + 1])) for j in at[:MAX_LISTED]]
    check_table(stream, out, str(path))  # safety net: what is written is what read_stream accepts

    name = stream.name
    report.rows[name] = out.num_rows
    report.skipped[name] = [int(r) + 1 for r in dropped[:MAX_LISTED]]
    report.skipped_count[name] = int(dropped.size)
    report.skipped_columns[name] = per_column
    report.gaps[name] = gaps
    report.gap_count[name] = gap_count
    report.median_dt[name] = median_dt
    report.extra_columns[name] = extra
    return out


def _locate_read_error(stream: Stream, path: Path, header: list[str], position: dict[str, int],
                       message: str) -> str:
    """Turn an Arrow CSV error into one line naming the column and the row."""
    m = _CONVERSION_RE.search(message)
    if m:
        index = int(m.group(1))
        column = next((stream.column(k) for k, v in position.items() if v == index), None)
        if column is not None:
            row, value = _first_unparsable(path, len(header), index, column)
            if row is not None:
                return (f"{path}: column '{column.name}' row {row}: {value!r} is not "
                        f"{_TYPE_WORDS[column.dtype]} ({_ARROW_TYPES[column.dtype]})")
    if "Expected" in message and "columns" in message:
        row, fields = _first_ragged_row(path, len(header))
        if row is not None:
            return f"{path}: row {row}: {fields} fields, but the header has {len(header)} columns"
    return f"{path}: " + " ".join(message.split())


def _first_unparsable(path: Path, ncols: int, index: int, column: Column) -> tuple[int | None, str]:
    """First row whose value in column `index` does not convert to the column's type (binary search)."""
    names = [f"c{i}" for i in range(ncols)]
    strings = pacsv.read_csv(
        path,
        read_options=pacsv.ReadOptions(skip_rows=1, column_names=names),
        parse_options=pacsv.ParseOptions(newlines_in_values=True),
        convert_options=pacsv.ConvertOptions(include_columns=[names[index]],
                                             column_types={names[index]: pa.string()},
                                             null_values=[""], strings_can_be_null=True),
    ).column(0).combine_chunks()
    strings = pc.utf8_trim_whitespace(strings)
    target = _ARROW_TYPES[column.dtype]

    def fails(lo: int, hi: int) -> bool:
        try:
            pc.cast(strings.slice(lo, hi - lo), target)
            return False
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            return True

    lo, hi = 0, len(strings)
    if not fails(lo, hi):
        return None, ""
    while hi - lo > 1:  # invariant: the first failure is in [lo, hi)
        mid = (lo + hi) // 2
        if fails(lo, mid):
            hi = mid
        else:
            lo = mid
    return lo + 1, strings[lo].as_py()


def _first_ragged_row(path: Path, ncols: int) -> tuple[int | None, int]:
    with open(path, newline="", encoding="utf-8-sig") as f:
        reader = csv.reader(f)
        next(reader, None)
        row = 0
        for fields in reader:
            if not fields:
                continue  # blank lines are not rows
            row += 1
            if len(fields) != ncols:
                return row, len(fields)
    return None, 0
