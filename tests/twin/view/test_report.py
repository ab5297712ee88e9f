"""`longwall report DIR`: the page and its PNG files from a default run (rendered in headless Chromium), the pan line's
straightness, a run without truth, and directories with nothing to report."""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

import twin
from estimators.io.logformat import ESTIMATE_DETECTORS, read_estimate, write_estimate
from estimators.io.metrics import column
from twin.cli import default_scenario, main
from twin.view.report import REPORT_DIR, REPORT_HTML, build_report
from twin.view.report_figures import pan_line

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

CHROMIUM = Path("/usr/bin/chromium")
FIGURES = ("top_view.png", "errors.png", "cycle_errors.png", "detectors_fkf_rail.png", "pan_line.png",
           "pressures.png", "face_line.png")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A default run, with rail-model detector statistics beside kf_cpoem's path (the default scenario runs no
    rail-model filter): chi-square(3) draws, raised while the model is isolated from 10 to 15 min."""
    out = tmp_path_factory.mktemp("report") / "default"
    twin.run(default_scenario(), out)
    est = read_estimate(out, "kf_cpoem")
    rows = np.arange(0, est.num_rows, 100)
    t = column(est, "t")[rows]
    isolated = ((t > 600) & (t < 900)).astype(np.int32)
    chi2 = np.random.default_rng(1).chisquare(3, (2, t.size))
    write_estimate(out, "fkf_rail", {"t": t, **{k: column(est, k)[rows] for k in ("lat", "lon", "h")},
                                     "residual": chi2[0] * (1 + 30 * isolated), "dual_state": chi2[1],
                                     "fsprt": chi2[0] + 20 * isolated, "applied": 1 - isolated,
                                     "isolated": isolated}, ESTIMATE_DETECTORS)
    return out


@pytest.fixture(scope="module")
def page(run_dir) -> Path:
    assert main(["report", str(run_dir)]) == 0
    return run_dir / REPORT_DIR / REPORT_HTML


def _rgb(path: Path) -> np.ndarray:
    """(N, 3) uint8 pixels of a PNG."""
    return (imread(path)[..., :3].reshape(-1, 3) * 255).round().astype(np.uint8)


def _assert_plotted(path: Path, min_colours: int, min_coloured: int) -> None:
    """Many distinct colours, and at least min_coloured pixels of the plots' colours (not grey: text, frames)."""
    rgb = _rgb(path)
    assert len(np.unique(rgb, axis=0)) >= min_colours, path.name
    assert np.sum(np.ptp(rgb.astype(int), axis=1) > 60) >= min_coloured, path.name


def test_every_figure_is_a_non_blank_png_embedded_in_the_page(page):
    text = page.read_text()
    for name in FIGURES:
        png = page.parent / name
        _assert_plotted(png, 50, 2000)
        assert f'href="{name}"' in text
        assert f"data:image/png;base64,{base64.b64encode(png.read_bytes()).decode()}" in text
    links = re.findall(r'(?:src|href)="([^"]*)"', text)
    assert sum(link.startswith("data:image/png;base64,") for link in links) == len(FIGURES)
    assert {link for link in links if not link.startswith("data:")} == set(FIGURES)  # nothing else to fetch


def test_header_table_shows_each_method_and_its_metrics(page, run_dir):
    text = page.read_text()
    metrics = json.loads((run_dir / "metrics.json").read_text())
    assert "default (seed 1)" in text
    for method, entry in metrics["estimators"].items():
        overall = entry["cycles"][-1]
        assert f"<td>{method}</td>" in text
        for key in ("rmse_e", "rmse_n", "rmse_u", "max_horizontal"):
            assert f"<td>{overall[key]:.3f}</td>" in text
    assert "max |lateral deviation| [mm]" in text


def test_page_renders_in_headless_chromium(page, tmp_path):
    if not CHROMIUM.is_file():
        if os.environ.get("CI"):
            pytest.fail(f"{CHROMIUM} missing; .ci/run installs Debian's chromium")
        pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium)")
    shot = tmp_path / "page.png"
    subprocess.run([str(CHROMIUM), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                    "--disable-background-networking", "--disable-component-update", "--disable-sync",
                    f"--user-data-dir={tmp_path / 'profile'}", f"--screenshot={shot}", "--window-size=1400,3000",
                    page.as_uri()], check=True, capture_output=True, timeout=120)
    _assert_plotted(shot, 200, 20000)


def test_pan_line_recovers_lateral_offsets_from_a_straight_line():
    azimuth = np.radians(30.0)  # face direction, headgate to tailgate, counter-clockwise from east
    along_en = np.array([np.cos(azimuth), np.sin(azimuth)])
    wall_en = np.array([along_en[1], -along_en[0]])  # face x: the along direction turned -90 deg about up
    lateral_m = 0.05 * np.array([1, -1, -1, 1, 1, -1, -1, 1])  # no mean, no slope against the along distance
    u_m = 1.8 * np.arange(lateral_m.size)
    p_en = np.array([3.0, -2.0]) + u_m[:, None] * along_en + lateral_m[:, None] * wall_en
    n = lateral_m.size
    pans = {"t": np.r_[np.zeros(n), np.full(n, 50.0)], "pan": np.r_[np.arange(n), np.arange(n)],
            "p_t_e": np.r_[p_en[:, 0], p_en[:, 0] + wall_en[0]], "p_t_n": np.r_[p_en[:, 1], p_en[:, 1] + wall_en[1]]}
    cycles = {"t_end": np.array([40.0, 60.0]), "cycle": np.array([0, 1])}
    labels, along, lateral = pan_line(pans, cycles)
    assert labels == ["installed", "cycle 0", "cycle 1"]
    np.testing.assert_allclose(along, np.broadcast_to(u_m, (3, n)), atol=1e-9)
    np.testing.assert_allclose(lateral, np.broadcast_to(lateral_m, (3, n)), atol=1e-9)


def test_run_without_truth_builds_and_says_what_is_left_out(run_dir, tmp_path):
    copy = tmp_path / "imported"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("truth_*", "*.rrd", REPORT_DIR))
    text = build_report(copy).read_text()
    written = {p.name for p in (copy / REPORT_DIR).glob("*.png")}
    assert written == {"top_view.png", "cycle_errors.png", "detectors_fkf_rail.png", "pressures.png"}
    assert "truth_shearer.parquet" in text and "truth_pans.parquet" in text
    assert "left out" in text and "errors against time" in text and "straightness" in text


@pytest.mark.parametrize("make", [lambda d: d / "missing", lambda d: d])
def test_missing_or_empty_directory_is_one_line_exit_2(tmp_path, capsys, make):
    assert main(["report", str(make(tmp_path))]) == 2
    err = capsys.readouterr().err
    assert err.startswith("longwall: error: ") and err.count("\n") == 1
    assert not (tmp_path / REPORT_DIR).exists()
