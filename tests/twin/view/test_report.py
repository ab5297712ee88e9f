"""`longwall report DIR`: the page and its PNG files from a default run (rendered in headless Chromium), the error
plots' sigma bands, the face-frame plan view and profile with their stated exaggeration, the cycle labels as the CLI
prints them, the supports' heat maps, the pan line's straightness, a run without truth, and directories with nothing
to report."""

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
from scipy.spatial import cKDTree

import twin
from estimators.io.logformat import ESTIMATE_DETECTORS, read_estimate, write_estimate
from estimators.io.metrics import column, columns, cycle_label
from twin.cli import default_scenario, main
from twin.pipeline.estimate import format_estimators
from twin.view.report import REPORT_DIR, REPORT_HTML, build_report
from twin.view.report_face import MAX_METHODS, PLAN, PROFILE, cuts, section_plot, sections
from twin.view.report_figures import N_SIGMA, colors_for, error_plot, error_series, pan_line, support_grid
from twin.view.run_data import load_run

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

CHROMIUM = Path("/usr/bin/chromium")
FIGURES = ("top_view.png", "plan_view.png", "profile.png", "errors.png", "cycle_errors.png",
           "detectors_fkf_rail.png", "supports.png", "pressures.png", "face_line.png", "pan_line.png")


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


@pytest.fixture(scope="module")
def run(run_dir):
    return load_run(run_dir)


def _fill_band(ax) -> np.ndarray:
    """(K, 2) the upper edge (t, y) of the first fill_between of an axes (its polygon: start, lower edge forward,
    end, upper edge backward)."""
    fill = next(c for c in ax.collections if type(c).__name__ == "FillBetweenPolyCollection")
    vertices = fill.get_paths()[0].vertices
    k = (vertices.shape[0] - 3) // 2
    return vertices[k + 2:2 * k + 2][::-1]


def test_error_bands_are_each_estimates_own_sigma(run, run_dir):
    series = error_series(run)
    fig = error_plot(series, run.truth["truth_cycles"], colors_for(list(run.estimates)))
    axes = np.reshape(fig.axes, (len(series), 3))
    banded = 0
    for row, (method, one) in zip(axes, series.items()):
        est = read_estimate(run_dir, method)
        at = np.searchsorted(column(est, "t"), one.t)
        np.testing.assert_array_equal(column(est, "t")[at], one.t)
        sd_enu = columns(est, "sd_pos")[at]
        if not np.isfinite(sd_enu).any():  # dead reckoning carries no sigma: no band, said in the panel
            assert not any(c.get_paths() for ax in row for c in ax.collections[:1])
            assert all("no one-sigma" in [t.get_text() for t in ax.texts] for ax in row)
            continue
        banded += 1
        for k, ax in enumerate(row):
            upper = _fill_band(ax)
            np.testing.assert_allclose(upper[:, 0], one.t / 60)
            np.testing.assert_allclose(upper[:, 1], N_SIGMA * sd_enu[:, k])
            err = ax.lines[0].get_ydata()
            inside = np.mean(np.abs(err) <= N_SIGMA * sd_enu[:, k])
            assert f"{inside:.0%} inside" in [t.get_text() for t in ax.texts]
    assert banded >= 4  # the filters and smoothers


def test_error_bands_without_truth_are_the_sigma_alone(run):
    run.truth, truth = {}, run.truth
    try:
        series = error_series(run)
    finally:
        run.truth = truth
    fig = error_plot(series, None, colors_for(list(run.estimates)))
    one = series["kf_cpoem"]
    assert one.err_enu is None
    row = np.reshape(fig.axes, (len(series), 3))[list(series).index("kf_cpoem")]
    for k, ax in enumerate(row):
        assert not ax.lines[1:]  # the zero line only
        np.testing.assert_allclose(_fill_band(ax)[:, 1], N_SIGMA * one.sd_enu[:, k])


def _shown(fig) -> list[str]:
    return [t.get_text() for t in fig.legends[0].get_texts()]


@pytest.mark.parametrize("axis, word, least", [(PLAN, "lateral", 10), (PROFILE, "vertical", 2)])
def test_face_frame_figure_states_its_exaggeration_and_draws_the_best_methods(run, run_dir, page, axis, word, least):
    estimators = json.loads((run_dir / "metrics.json").read_text())["estimators"]
    sep = {m: e["cycles"][-1]["sep"] for m, e in estimators.items()}
    best = sorted(sep, key=sep.get)[:MAX_METHODS]
    drawn = cuts(run)
    assert [c.label.split(":")[0] for c in drawn] == ["A1", "A2"]
    fig, factor = section_plot(drawn, sections(run, best, drawn), colors_for(list(run.estimates)), axis, "target")
    fig.draw_without_rendering()
    assert factor >= least  # across the 70 m face: centimetres of the face line, 2 m of the seam's rise
    width_in, height_in = fig.get_size_inches()
    for ax in fig.axes:
        assert ax.get_aspect() == factor and f"({word} x{factor})" in ax.get_ylabel()
        box = ax.get_position()
        shown = (box.height * height_in) / (box.width * width_in)  # drawn height per drawn width
        np.testing.assert_allclose(shown, factor * np.ptp(ax.get_ylim()) / np.ptp(ax.get_xlim()), rtol=1e-6)
    assert {m for m in _shown(fig) if m in sep} == set(best) and "dr" not in _shown(fig)
    assert "truth" in _shown(fig) and ("target" in _shown(fig)) == (axis == PLAN)
    # the best estimate's line is its own face-frame columns (p_f_*), its band its sd_pos turned into the face frame
    est = read_estimate(run_dir, best[0])
    p_f = columns(est, "p_f", "xyz")
    azimuth = np.radians(run.scenario.face.azimuth_deg)
    sd = (np.hypot(np.cos(azimuth) * column(est, "sd_pos_e"), np.sin(azimuth) * column(est, "sd_pos_n"))
          if axis == PLAN else column(est, "sd_pos_u"))
    line = next(line for line in fig.axes[0].lines if line.get_label() == best[0])
    distance, rows = cKDTree(p_f[:, [1, axis]]).query(np.column_stack([line.get_xdata(), line.get_ydata()]))
    assert distance.max() < 1e-6 and rows.size > 1000
    assert np.all((column(est, "t")[rows] >= drawn[0].t0) & (column(est, "t")[rows] <= drawn[0].t1))
    np.testing.assert_allclose(_fill_band(fig.axes[0])[:, 1], p_f[rows, axis] + sd[rows], atol=1e-6)
    name = "plan_view.png" if axis == PLAN else "profile.png"
    assert f"exaggerated x{factor}" in page.read_text().split(f'href="{name}"')[0].rsplit("<figcaption>", 1)[1]


def test_aligned_run_draws_the_alignment_systems_target(run):
    scn = run.scenario
    run.scenario = scn.model_copy(update={"alignment": scn.alignment.model_copy(update={"mode": "truth"})})
    try:
        drawn = cuts(run)
        parts = sections(run, [], drawn)
    finally:
        run.scenario = scn
    first = parts[0]
    assert first.target_yx.shape[0] == scn.face.pan_count // scn.supports.pans_per_support  # one point per shield
    np.testing.assert_allclose(np.diff(first.target_yx[:, 1], 2), 0, atol=1e-9)  # a straight line
    truth_x = np.interp(first.target_yx[:, 0], first.truth[:, 1], first.truth[:, 0])
    assert np.sqrt(np.mean((truth_x - first.target_yx[:, 1]) ** 2)) < 0.05  # fitted to the true cut


def test_cycle_labels_match_the_cli(page, run_dir):
    printed = format_estimators(json.loads((run_dir / "metrics.json").read_text())["estimators"])
    header = next(line for line in printed.splitlines() if line.startswith("method") and "all" in line)
    labels = header.split()[1:-1]
    assert labels == ["A1", "A2"] == [cycle_label(k) for k in range(2)]
    text = page.read_text()
    assert "".join(f"<th>{label}</th>" for label in labels) + "<th>all</th>" in text
    assert all(f"<td>after {label}</td>" in text for label in labels)  # the pan line table
    assert "cycle 0" not in text and "cycle 1" not in text


def test_support_grid_is_the_mean_of_each_supports_readings_per_bin():
    t = np.array([0.0, 0.0, 1.0, 1.0, 2.0, 3.0, 3.0])
    support = np.array([0, 1, 0, 0, 1, 0, 1])
    value = np.array([1.0, 10.0, 3.0, 5.0, 20.0, 7.0, 30.0])
    edges, grid = support_grid(t, support, value, 2)
    np.testing.assert_allclose(edges, [0.0, 1.5, 3.0])
    np.testing.assert_allclose(grid, [[3.0, 7.0], [10.0, 25.0]])
    _, fine = support_grid(t, support, value, 100)  # no more bins than distinct times
    assert fine.shape == (2, 4) and np.isnan(fine[1, 1]) and fine[0, 1] == 4.0


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
    assert labels == ["installed", "after A1", "after A2"]
    np.testing.assert_allclose(along, np.broadcast_to(u_m, (3, n)), atol=1e-9)
    np.testing.assert_allclose(lateral, np.broadcast_to(lateral_m, (3, n)), atol=1e-9)


def test_run_without_truth_builds_and_says_what_is_left_out(run_dir, tmp_path):
    copy = tmp_path / "imported"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("truth_*", "*.rrd", REPORT_DIR))
    text = build_report(copy).read_text()
    written = {p.name for p in (copy / REPORT_DIR).glob("*.png")}
    assert written == {"top_view.png", "plan_view.png", "profile.png", "sigma.png", "cycle_errors.png",
                       "detectors_fkf_rail.png", "supports.png", "pressures.png"}
    assert "truth_shearer.parquet" in text and "truth_pans.parquet" in text
    assert "left out" in text and "errors against time" in text and "straightness" in text


@pytest.mark.parametrize("make", [lambda d: d / "missing", lambda d: d])
def test_missing_or_empty_directory_is_one_line_exit_2(tmp_path, capsys, make):
    assert main(["report", str(make(tmp_path))]) == 2
    err = capsys.readouterr().err
    assert err.startswith("longwall: error: ") and err.count("\n") == 1
    assert not (tmp_path / REPORT_DIR).exists()
