"""The Python API (twin.run, twin.load_scenario, Run, twin.estimate) gives what the command line gives."""

from __future__ import annotations

import filecmp
import shutil

import numpy as np
import pyarrow as pa
import pytest

import twin
from estimators.io import metrics
from estimators.io.logformat import LogError
from tests.conftest import SCENARIO_DIR
from twin.cli import main
from twin.config.scenario import ScenarioError

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

STREAM_FILES = ("truth_shearer.parquet", "truth_pans.parquet", "imu.parquet", "odometer.parquet",
                "pushram.parquet", "estimates/kf_cpoem_rts.parquet", "estimates/dr.parquet")


@pytest.fixture(scope="module")
def short_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("scn") / "short.toml"
    path.write_text((SCENARIO_DIR / "default.toml").read_text().replace("cycles = 2", "cycles = 1"))
    return path


@pytest.fixture(scope="module")
def api_run(short_path, tmp_path_factory):
    """A Scenario object, its seed overridden, run from Python."""
    return twin.run(twin.load_scenario(short_path), tmp_path_factory.mktemp("api") / "run", seed=11)


def test_a_scenario_object_runs_as_the_command_line_runs_its_file(api_run, short_path, tmp_path):
    out = tmp_path / "cli"
    assert main(["run", str(short_path), "--out", str(out), "--seed", "11", "--quiet"]) == 0
    for name in STREAM_FILES:
        assert filecmp.cmp(api_run.dir / name, out / name, shallow=False), name
    assert twin.load_scenario(api_run.dir / "scenario.toml").seed == 11


def test_run_reads_its_metrics_streams_and_estimates(api_run):
    assert api_run.metrics["twin"]["scenario"] == "default"
    assert set(api_run.metrics["estimators"]) >= {"kf", "kf_cpoem_rts", "dr"}
    imu = api_run.stream("imu")
    assert isinstance(imu, pa.Table) and {"t", "dtheta_x", "dv_z"} <= set(imu.column_names)
    sol = api_run.estimate("kf_cpoem_rts")
    assert sol.num_rows > 0 and sol.column("t").to_numpy()[-1] <= imu.column("t").to_numpy()[-1]
    with pytest.raises(LogError, match="unknown stream 'imus'"):
        api_run.stream("imus")
    with pytest.raises(LogError, match="not found"):
        api_run.estimate("no_such_method")


def test_estimates_carry_the_tangent_plane_and_face_frame_positions(api_run):
    """An estimate's p_t less the truth's p_t (the twin's ride, interpolated) is its position error as
    metrics.position_errors finds it from latitude, longitude and height (local ENU at the truth point: the two
    frames differ by 1e-5 rad over the 77 m face); p_f is p_t turned into the face frame, y the distance along the
    face from the headgate (within the snake and the shoes' offset of the truth's arc length s)."""
    est, truth = api_run.estimate("kf_cpoem_rts"), api_run.stream("truth_shearer")
    col = lambda table, name: table.column(name).to_numpy()
    t = col(est, "t")
    p_t = np.column_stack([col(est, f"p_t_{a}") for a in "enu"])
    true_t = np.column_stack([np.interp(t, col(truth, "t"), col(truth, f"p_t_{a}")) for a in "enu"])
    _, err = metrics.position_errors(est, truth)
    assert 0.01 < np.abs(err).max() and np.abs(p_t - true_t - err).max() < 1e-4
    a = np.radians(twin.load_scenario(api_run.dir / "scenario.toml").face.azimuth_deg)
    p_f = np.column_stack([col(est, f"p_f_{a}") for a in "xyz"])
    np.testing.assert_allclose(p_f[:, 0], p_t[:, 0] * np.cos(a) - p_t[:, 1] * np.sin(a), atol=1e-9)
    np.testing.assert_allclose(p_f[:, 1], p_t[:, 0] * np.sin(a) + p_t[:, 1] * np.cos(a), atol=1e-9)
    np.testing.assert_allclose(p_f[:, 2], p_t[:, 2], atol=1e-9)
    assert np.abs(p_f[:, 1] - np.interp(t, col(truth, "t"), col(truth, "s"))).max() < 0.5


def test_estimate_again_gives_the_same_estimates(api_run, tmp_path):
    copy = tmp_path / "copy"
    shutil.copytree(api_run.dir, copy)
    for p in (copy / "estimates").glob("*.parquet"):
        p.unlink()
    again = twin.estimate(copy)
    assert again.metrics["estimators"] == api_run.metrics["estimators"]
    assert filecmp.cmp(copy / "estimates/kf_cpoem_rts.parquet", api_run.dir / "estimates/kf_cpoem_rts.parquet",
                       shallow=False)


def test_bad_arguments_are_one_line_errors(short_path, tmp_path):
    with pytest.raises(ScenarioError, match="trials: must be >= 1"):
        twin.run(short_path, tmp_path / "x", trials=0)
    assert not (tmp_path / "x").exists()


def test_the_progress_bar_names_the_stage_under_way_and_a_compilation(short_path, tmp_path, monkeypatch):
    """The bar names the stage that is running (not the one just done), and says so while numba compiles (a first
    run after installing), here a kernel compiled inside the face stage."""
    import numba as nb

    import twin.pipeline.api as api
    import twin.pipeline.twin_stream as twin_stream

    seen = []

    class Bar(api.tqdm):
        def set_description(self, desc=None, refresh=True):
            seen.append(desc)
            super().set_description(desc, refresh)

    real_simulate = twin_stream.simulate_stream

    def simulate_after_a_compile(scn, sink, progress=None, offsets=None, live=None, supports_sink=None):
        nb.njit(lambda x: x + 1)(1)  # not cached: compiled now
        return real_simulate(scn, sink, progress, offsets, live, supports_sink)

    monkeypatch.setattr(api, "tqdm", Bar)
    monkeypatch.setattr(twin_stream, "simulate_stream", simulate_after_a_compile)
    twin.run(short_path, tmp_path / "run", quiet=False)
    stages = [d.split("(")[1].split(")")[0] for d in seen if "(" in d]
    assert stages[0] == "face: compiling numba kernels, first run only", seen
    order = ["face", "shearer", "sensors", "write", "recording", "estimators"]
    named = [s for s in dict.fromkeys(s.split(":")[0] for s in stages) if s in order]
    assert named == order, seen
