"""The speed table of benchmarks/bench_speed.py on synthetic timings: ratios, targets, a skipped peer, the files."""

from __future__ import annotations

import csv

import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def bench():
    return benchmark_module("bench_speed")


@pytest.fixture
def rows(bench):
    row = bench.Row
    return [
        row("twin real-time factor", "x", 450.0, target=">= 400x (issue 2)", target_min=400.0),
        row("strapdown mechanization, IMU samples/s", "/s", 2_000_000.0, "pyins 1.0.1", 100_000.0,
            target=">= 1,000,000/s (issue 4)", target_min=1e6),
        row("filter + smoother, IMU samples/s", "/s", 50_000.0, "pyins (python-ins)", None,
            "not installed (pip install -e \".[bench]\")", ">= 100,000/s (issue 5)", 1e5, note="a | note"),
        row("peak memory, twin stage", "GB", 1.234, target="<= 4 GB (issue 2)", target_max=4.0),
    ]


def test_ratio_and_targets(rows):
    twin, strap, filt, mem = rows
    assert twin.ratio is None and twin.met is True
    assert strap.ratio == pytest.approx(20.0) and strap.met is True
    assert filt.ratio is None and filt.met is False
    assert mem.met is True
    assert rows[0].__class__("x", "/s", None).met is None


def test_cells_format_and_skipped_peer(bench, rows):
    cells = bench.table_cells(rows)
    assert cells[0][:5] == ["figure", "ours", "peer", "ratio (ours/peer)", "target"]
    twin, strap, filt, mem = cells[1:]
    assert twin[1] == "450x" and twin[2] == "-" and twin[3] == "-" and twin[4].endswith("(met)")
    assert strap[1] == "2,000,000 /s" and strap[2] == "pyins 1.0.1: 100,000 /s" and strap[3] == "20.0x"
    assert filt[2].startswith("skipped: pyins (python-ins) not installed") and filt[3] == "skipped"
    assert filt[4].endswith("(NOT met)")
    assert mem[1] == "1.23 GB"
    text = bench.format_text(rows)
    assert "skipped" in text and "20.0x" in text and "a | note" in text


def test_markdown_and_csv_written(bench, rows, tmp_path):
    md, csv_path = bench.write_table(rows, tmp_path / "bench" / "speed.md", "Speed table, synthetic")
    assert md.exists() and csv_path == tmp_path / "bench" / "speed.csv"
    lines = md.read_text().splitlines()
    assert lines[0] == "# Speed table, synthetic"
    table = [line for line in lines if line.startswith("|")]
    assert len(table) == 2 + len(rows)  # header, rule, rows
    assert all(line.count(" | ") == 5 for line in table if not line.startswith("|---"))  # "|" in a note escaped
    with csv_path.open() as fh:
        recs = list(csv.DictReader(fh))
    assert [r["figure"] for r in recs] == [r.figure for r in rows]
    assert float(recs[1]["ratio"]) == pytest.approx(20.0) and recs[1]["peer_status"] == "measured"
    assert recs[2]["ratio"] == "" and recs[2]["peer_status"].startswith("skipped: not installed")
    assert recs[2]["target_met"] == "false" and recs[0]["target_met"] == "true"
    assert recs[0]["peer_status"] == "none"


def test_missing_peer_is_named(bench):
    assert bench.peer_version("python-ins", "no_such_module_for_bench_speed") is None
    assert "python-ins" in bench.missing("python-ins")
