"""Where a CSV stream file fails to read (estimators.io.csv_import): the row and column behind an Arrow error, found
by reading the file again block by block (memory independent of the file's size), for a one-line message.

Rows are numbered from 1 at the first data row (the header and blank lines are not counted)."""

from __future__ import annotations

import csv
import re
from collections.abc import Callable
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv

from estimators.io.logformat import Column, Stream

ARROW_TYPES = {"f8": pa.float64(), "i8": pa.int64(), "i4": pa.int32(), "i1": pa.int8(), "str": pa.string()}
_TYPE_WORDS = {"f8": "a number", "i8": "an integer", "i4": "a 32-bit integer", "i1": "an 8-bit integer",
               "str": "text"}
_CONVERSION_RE = re.compile(r"In CSV column #(\d+)")
UTF8_FIX = "save the file as UTF-8 text (in a spreadsheet: CSV UTF-8)"


def locate_read_error(stream: Stream, path: Path, header: list[str], position: dict[str, int], message: str,
                      block_bytes: int) -> str:
    """Turn an Arrow CSV error into one line naming the row, the column and the fix."""
    m = _CONVERSION_RE.search(message)
    if m:
        index = int(m.group(1))
        column = next((stream.column(k) for k, v in position.items() if v == index), None)
        if column is not None:
            found = _first_unconvertible(path, len(header), index, column, block_bytes)
            if found is not None:
                return found
    if "Expected" in message and "columns" in message:
        row, fields = _first_ragged_row(path, len(header))
        if row is not None:
            return (f"{path}: row {row}: {fields} fields, but the header has {len(header)} columns; give every row "
                    f"a value for each column (an empty value where there is none)")
    return f"{path}: " + " ".join(message.split())


def _first_unconvertible(path: Path, ncols: int, index: int, column: Column, block_bytes: int) -> str | None:
    """The first row whose value in column `index` is not UTF-8 or does not convert to the column's type."""
    names = [f"c{i}" for i in range(ncols)]
    reader = pacsv.open_csv(
        path,
        read_options=pacsv.ReadOptions(skip_rows=1, column_names=names, block_size=block_bytes),
        parse_options=pacsv.ParseOptions(newlines_in_values=column.dtype == "str"),
        convert_options=pacsv.ConvertOptions(include_columns=[names[index]], column_types={names[index]: pa.binary()},
                                             null_values=[""], strings_can_be_null=True),
    )
    target = ARROW_TYPES[column.dtype]
    rows = 0
    for batch in reader:
        raw = batch.column(0)
        bad = _first_failure(raw, lambda a: pc.cast(a, pa.string()))
        if bad is not None:
            return f"{path}: column '{column.name}' row {rows + bad + 1}: not UTF-8 text; {UTF8_FIX}"
        text = pc.utf8_trim_whitespace(pc.cast(raw, pa.string()))
        bad = _first_failure(text, lambda a: pc.cast(a, target))
        if bad is not None:
            return (f"{path}: column '{column.name}' row {rows + bad + 1}: {text[bad].as_py()!r} is not "
                    f"{_TYPE_WORDS[column.dtype]} ({target}); correct the value or delete the row")
        rows += batch.num_rows
    return None


def _first_failure(values: pa.Array, convert: Callable[[pa.Array], object]) -> int | None:
    """Index of the first value `convert` fails on (binary search), None when all convert."""
    def fails(lo: int, hi: int) -> bool:
        try:
            convert(values.slice(lo, hi - lo))
            return False
        except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
            return True

    lo, hi = 0, len(values)
    if hi == 0 or not fails(lo, hi):
        return None
    while hi - lo > 1:  # invariant: the first failure is in [lo, hi)
        mid = (lo + hi) // 2
        if fails(lo, mid):
            hi = mid
        else:
            lo = mid
    return lo


def _first_ragged_row(path: Path, ncols: int) -> tuple[int | None, int]:
    with open(path, newline="", encoding="utf-8-sig", errors="replace") as f:
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
