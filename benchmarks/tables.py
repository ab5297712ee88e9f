"""Text and Markdown rendering of the benchmarks' tables (benchmarks/compare.py, bench_speed.py): a table is a
list of rows of text cells, the first row the header."""

from __future__ import annotations

from collections.abc import Sequence


def text_table(cells: Sequence[Sequence[str]]) -> str:
    """Columns padded to their widest cell, a dashed rule under the header."""
    widths = [max(len(line[i]) for line in cells) for i in range(len(cells[0]))]
    out = ["  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in cells]
    out.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(out)


def markdown_table(title: str, cells: Sequence[Sequence[str]], notes: Sequence[str] = ()) -> str:
    """`# title`, the notes as paragraphs, then the table ('|' in cells escaped)."""
    esc = [[c.replace("|", "\\|") for c in line] for line in cells]
    lines = [f"# {title}", "", *notes, *([""] if notes else []),
             "| " + " | ".join(esc[0]) + " |", "|" + "---|" * len(esc[0])]
    lines += ["| " + " | ".join(line) + " |" for line in esc[1:]]
    return "\n".join(lines) + "\n"
