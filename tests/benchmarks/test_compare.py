"""The comparison table of benchmarks/compare.py on synthetic figures (no simulation): mean +- sd, the met
column, failed rows, the Markdown and CSV files, every paper present."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from tests.conftest import benchmark_module


@pytest.fixture(scope="module")
def cmp():
    return benchmark_module("compare")


@pytest.fixture
def specs(cmp):
    rs = cmp.RowSpec
    return [
        rs("001", "Table 3", "SEP A1 [m]", "0.50", "mc", lambda f: f["sep"][:, 0], "<= paper", cmp.at_most(0.5)),
        rs("001", "Table 3", "SEP A2 [m]", "0.32", "mc", lambda f: f["sep"][:, 1], "<= paper", cmp.at_most(0.32)),
        rs("000", "7.2 coning", "reduction [%]", "64.3", "exp", lambda f: f["coning"], ">= 99 %",
           cmp.at_least(99.0), ".2f"),
        rs("000", "7.4 sculling", "reduction [%]", "70.0", "exp", lambda f: f["sculling"], fmt=".1f"),
        rs("000", "7.4 sculling", "missing key", "-", "exp", lambda f: f["nope"]),
        rs("004", "Table 2", "RMSE E [m]", "0.420", "rail", lambda f: f["rmse"], "<= paper", cmp.at_most(0.42)),
        rs("003", "Table 2", "not selected", "-", "absent", lambda f: 1.0),
    ]


@pytest.fixture
def figures(cmp):
    return {"mc": {"sep": np.array([[0.1, 0.4], [0.3, 0.2], [0.2, 0.6]])},
            "exp": {"coning": 99.51234, "sculling": 98.0},
            "rail": cmp.Failed("RuntimeError: out of memory")}


def test_mean_sd_met_and_failed_rows(cmp, specs, figures):
    rows = cmp.build_table(specs, figures)
    assert len(rows) == 6  # the unselected source gives no row
    a1, a2, coning, sculling, missing, rail = rows
    assert a1.ours == "0.200 ± 0.082" and a1.met == "yes" and a1.n == 3
    assert a1.mean == pytest.approx(0.2) and a1.sd == pytest.approx(np.std([0.1, 0.3, 0.2]))
    assert a2.ours == "0.400 ± 0.163" and a2.met == "no"
    assert coning.ours == "99.51" and coning.met == "yes" and coning.sd is None  # a single value: no spread
    assert sculling.ours == "98.0" and sculling.met == "-" and sculling.target == "-"
    assert missing.ours.startswith("failed: KeyError") and missing.met == "-"
    assert rail.ours == "failed: RuntimeError: out of memory" and rail.met == "-"
    assert rail.paper_value == "0.420"  # the paper's figure stays beside the failure


def test_nan_values_are_counted(cmp):
    assert cmp.fmt_ours(np.array([1.0, np.nan, 3.0]), ".1f") == "2.0 ± 1.0 (2/3 finite)"
    assert cmp.fmt_ours(np.array([np.nan, np.nan]), ".1f") == "nan"
    assert cmp.one_line(ValueError("first\nsecond")) == "ValueError: first"


def test_markdown_and_csv_written(cmp, specs, figures, tmp_path):
    rows = cmp.build_table(specs, figures)
    md, csv_path = cmp.write_table(rows, tmp_path / "bench", "Synthetic", ["a note | with a bar"])
    assert md == tmp_path / "bench" / "compare.md" and csv_path.name == "compare.csv"
    text = md.read_text(encoding="utf-8")
    assert text.startswith("# Synthetic") and "a note | with a bar" in text
    assert "| paper | table/section | figure | paper's value | ours | target | met |" in text
    assert "| 001 | Table 3 | SEP A1 [m] | 0.50 | 0.200 ± 0.082 | <= paper | yes |" in text
    assert "failed: RuntimeError: out of memory" in text
    with csv_path.open(encoding="utf-8") as fh:
        table = list(csv.reader(fh))
    assert table[0] == [*cmp.COLUMNS, "ours_mean", "ours_sd", "ours_n"]
    assert len(table) == 1 + len(rows)
    assert table[1][4] == "0.200 ± 0.082" and float(table[1][7]) == pytest.approx(0.2) and table[1][9] == "3"
    assert table[6][4].startswith("failed:") and table[6][7] == ""
    assert "0.200 ± 0.082" in cmp.format_text(rows)


def test_every_paper_has_rows_even_when_every_benchmark_fails(cmp):
    specs = cmp.row_specs()
    failed = {name: cmp.Failed("boom") for name in cmp.SOURCES}
    rows = cmp.build_table(specs, failed)
    assert {r.paper for r in rows} == set(cmp.PAPERS)
    assert all(r.ours == "failed: boom" and r.paper_value for r in rows)
    assert {s.source for s in specs} == set(cmp.SOURCES)
    for paper in cmp.PAPERS:  # each paper's headline rows carry a target from its issue
        assert any(r.target != "-" for r in rows if r.paper == paper)


def test_real_specs_read_synthetic_figures(cmp):
    """Every row of the real table reads figures shaped like the benchmarks' (no row fails on its getter)."""
    n = 2
    lever = {f"table{t}": {"reduction_pct": [80.0, 70.0, 90.0]} for t in (2, 3)}
    align_one = {"phi_deg": [0.1, -0.1, 1.0], "level_dev": 0.12, "heading_ok": False}
    align = [{g: {m: dict(align_one) for m in ("ekf", "ukf", "optimized_ukf")} for g in ("mti-g-700", "nav-004")}
             for _ in range(n)]
    seg = {"pitch": 0.05, "roll": 0.06, "yaw": 0.5}
    turn = {"metrics": [{f: {"dynamic": seg, "static": seg, "max": seg} for f in ("kf", "ukf", "gd_ukf", "ours")}] * n}
    err = np.full((n, 3), 0.2)
    fed = {"results": {s: ({m: err for m in ("kf", "ckf_mag", "afkf")}, {}) for s in ("seed003",
                                                                                       "seed003_interference")},
           "summary": {"gain": np.full((n, 2), 0.8), "ratio": np.full(n, 4.0)}}
    det = {"delay": 10.0, "clear": 20.0, "missed": 0, "fixes": 10, "false_per_h": 0.0, "error_in_fault": 0.3}
    rail = {"rmse": {"kf": np.ones((5, 2)), "fkf_rail": np.ones((5, 2))},
            "detectors": {d: det for d in ("residual", "dual_state", "fsprt")}, "clean_error_in_fault": 0.28,
            "none_error_in_fault": 2.0, "alarms": [0] * n, "mc_rmse": np.full((n, 5, 2), 0.05)}
    figures = {"000 experiments": {"seed000_coning": {"reduction_pct": 99.9, "drift_reduction_pct": 99.99},
                                   "seed000_sculling": {"reduction_pct": 99.5}, "seed000_lever_arm": lever},
               "000 alignment": align, "000 schuler": {"north_pct": 1.0, "east_pct": 2.0, "attitude_pct": 6.0},
               "001 monte carlo": {"sep": {"kf_cpoem_rts": np.full((n, 4), 0.08)}},
               "001 sweep": {"sweep": {k: [0.1, 0.2, 0.3, 0.4] for k in range(1, 13)}},
               "002 turntable": turn, "003 federated": fed, "004 rail": rail}
    rows = cmp.build_table(cmp.row_specs(), figures)
    assert not [r for r in rows if r.ours.startswith("failed")]
    assert {r.paper for r in rows} == set(cmp.PAPERS)
    by = {(r.paper, r.figure): r for r in rows}
    assert by[("001", "worst cycle SEP over Par 1-12 [m], KF + CPOEM + RTS, trial 0")].ours == "0.400"
    assert by[("001", "SEP cycle A1 [m], KF + CPOEM + RTS")].met == "yes"
    assert by[("000", "EKF phi_U [deg], nav-004 1800 s")].met == "no"
    assert by[("000", "EKF phi_E [deg], nav-004 1800 s")].met == "-"  # the level's target is on its deviation
    level = by[("000", "EKF level deviation from the draw's floor [%], nav-004 1800 s")]
    assert (level.ours, level.met) == ("12.0 ± 0.0", "no")
    assert by[("000", "attitude error vs linear error model, largest deviation [%]")].met == "no"
    assert by[("004", "fading SPRT: max horizontal error in the fault [m]")].met == "yes"
    assert by[("004", "fading SPRT false alarms per trial")].met == "yes"


def test_a_paper_whose_rows_cannot_be_built_says_so(cmp, monkeypatch):
    def broken():
        raise ImportError("No module named 'bench_rail'")

    monkeypatch.setattr(cmp, "_rows_004", broken)
    rows = cmp.build_table(cmp.row_specs(), {"004 rail": {}, "003 federated": cmp.Failed("x")})
    rail = [r for r in rows if r.paper == "004"]
    assert len(rail) == 1 and "rows not built: ImportError: No module named 'bench_rail'" in rail[0].ours
    assert any(r.paper == "003" for r in rows)
