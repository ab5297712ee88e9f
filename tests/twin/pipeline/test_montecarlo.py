"""Monte Carlo at scale: the default scenario's trials (two methods) sequentially, on 2 processes and on a local Ray instance
give the same trials table; bad flags are one line and exit 2; a failing trial is counted and named."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

import twin.pipeline.montecarlo
from twin.cli import default_scenario, main
from twin.view.layout import free_port

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

TRIALS = 2
METHODS = ["kf", "kf_cpoem"]
"""Two methods are enough to compare the runners; the default scenario's six would triple the time."""


def assert_same_table(a: pa.Table, b: pa.Table) -> None:
    """Exact equality of every cell (NaN equal to NaN, null to null)."""
    assert a.schema.equals(b.schema) and a.num_rows == b.num_rows
    for name in a.column_names:
        x, y = a[name].to_numpy(zero_copy_only=False), b[name].to_numpy(zero_copy_only=False)
        if x.dtype.kind == "f":
            assert np.array_equal(x, y, equal_nan=True), name
        else:
            assert x.tolist() == y.tolist(), name


@pytest.fixture(scope="module")
def scenario(tmp_path_factory) -> str:
    """The default scenario with METHODS only."""
    path = tmp_path_factory.mktemp("scenario") / "mc.toml"
    text = (default_scenario()).read_text()
    assert "[estimators.shearer]" not in text
    path.write_text(text + f"\n[estimators.shearer]\nmethods = {json.dumps(METHODS)}\n")
    return str(path)


@pytest.fixture(scope="module")
def sequential_run(tmp_path_factory, scenario):
    out = tmp_path_factory.mktemp("mc") / "sequential"
    assert main(["run", scenario, "--out", str(out), "--trials", str(TRIALS), "--quiet"]) == 0
    return out


@pytest.fixture(scope="module")
def ray_address():
    """A local Ray instance (2 CPUs, no dashboard) started here and stopped at the end. Skipped only when Ray is
    not installed outside CI."""
    try:
        import ray
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip('ray is not installed (pip install -e ".[ray]")')
    import logging

    temp_dir = tempfile.mkdtemp(prefix="ray-")  # short: Ray's socket paths must fit 107 characters
    context = ray.init(num_cpus=2, include_dashboard=False, logging_level=logging.ERROR, log_to_driver=False,
                       _temp_dir=temp_dir)
    yield context.address_info["gcs_address"]
    ray.shutdown()
    shutil.rmtree(temp_dir, ignore_errors=True)


def test_sequential_trials_table_and_summary(sequential_run):
    table = pq.read_table(sequential_run / "trials.parquet")
    assert table["trial"].to_pylist() == [t for t in range(TRIALS) for _ in METHODS]
    assert table["method"].to_pylist() == METHODS * TRIALS
    assert set(table["status"].to_pylist()) == {"ok"} and set(table["error"].to_pylist()) == {None}
    assert (sequential_run / "trials.csv").read_text().startswith('"trial","method","status","error","cycle0.')
    metrics = json.loads((sequential_run / "metrics.json").read_text())
    kf0 = table.filter(pc.and_(pc.equal(table["trial"], 0), pc.equal(table["method"], "kf")))
    assert kf0["all.sep"].to_pylist() == [metrics["estimators"]["kf"]["cycles"][-1]["sep"]]  # trial 0 is the run
    mc = metrics["monte_carlo"]
    assert (mc["trials"], mc["failed"], mc["failures"], mc["runner"]) == (TRIALS, 0, [], "sequential")
    sep = table.filter(pc.equal(table["method"], "kf"))["all.sep"].to_numpy()
    stats = mc["methods"]["kf"]["all.sep"]
    assert stats["n"] == TRIALS and stats["mean"] == pytest.approx(sep.mean())
    assert stats["sd"] == pytest.approx(sep.std(ddof=1)) and (stats["min"], stats["max"]) == (sep.min(), sep.max())
    assert np.unique(sep).size == TRIALS  # the trials draw different sensor errors
    for trial in range(1, TRIALS):
        assert (sequential_run / "trials" / f"{trial:03d}" / "estimates" / "kf.parquet").is_file()
        assert not (sequential_run / "trials" / f"{trial:03d}" / "truth_shearer.parquet").exists()
    assert not (sequential_run / "trials" / "001" / "estimates.rrd").exists()


def test_two_workers_give_the_sequential_table(sequential_run, scenario, tmp_path):
    out = tmp_path / "workers"
    assert main(["run", scenario, "--out", str(out), "--trials", str(TRIALS), "--workers", "2", "--quiet"]) == 0
    assert_same_table(pq.read_table(out / "trials.parquet"), pq.read_table(sequential_run / "trials.parquet"))
    assert json.loads((out / "metrics.json").read_text())["monte_carlo"]["runner"] == "2 processes"


def test_ray_gives_the_sequential_table(sequential_run, scenario, ray_address, tmp_path):
    out = tmp_path / "ray"
    done = subprocess.run([sys.executable, "-m", "twin.cli", "run", scenario, "--out", str(out), "--trials", str(TRIALS),
                           "--ray", ray_address, "--quiet"], check=False, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr
    assert_same_table(pq.read_table(out / "trials.parquet"), pq.read_table(sequential_run / "trials.parquet"))
    for trial in range(1, TRIALS):  # the tasks' files came back into the run directory
        assert (out / "trials" / f"{trial:03d}" / "imu.parquet").is_file()
        assert (out / "trials" / f"{trial:03d}" / "estimates" / "kf.parquet").is_file()


@pytest.mark.parametrize("flags, words", [
    (["--workers", "0"], ["--workers", ">= 1"]),
    (["--trials", "2", "--workers", "3"], ["--workers", "<= --trials"]),
    (["--trials", "2", "--workers", "2", "--ray", "auto"], ["--workers and --ray"]),
])
def test_bad_worker_flags_are_one_line_exit_2(tmp_path, capsys, flags, words):
    out = tmp_path / "out"
    assert main(["run", "--out", str(out), "--quiet", *flags]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("longwall: error: ")
    assert all(word in err for word in words) and not out.exists()


def test_ray_not_installed_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray raises ImportError
    assert main(["run", "--out", str(tmp_path / "out"), "--trials", "2", "--ray", "auto", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and 'pip install -e ".[ray]"' in err
    assert list(tmp_path.iterdir()) == []  # not even a partial run directory


def test_unreachable_ray_cluster_is_one_line_exit_2(tmp_path, capsys):
    pytest.importorskip("ray")
    address = f"127.0.0.1:{free_port()}"
    assert main(["run", "--out", str(tmp_path / "out"), "--trials", "2", "--ray", address, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and address in err and "no Ray cluster" in err
    assert list(tmp_path.iterdir()) == []


def test_a_failing_trial_is_counted_and_named(scenario, tmp_path, capsys, monkeypatch):
    estimate = twin.pipeline.montecarlo.run_estimators

    def fail_trial_1(run_dir, scn, recording=True):
        if run_dir.name == "001":
            raise RuntimeError("injected failure\nsecond line")
        return estimate(run_dir, scn, recording)

    monkeypatch.setattr(twin.pipeline.montecarlo, "run_estimators", fail_trial_1)
    out = tmp_path / "out"
    assert main(["run", scenario, "--out", str(out), "--trials", "2", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "1 of 2 Monte Carlo trials failed" in err
    assert "trial 1: RuntimeError: injected failure" in err
    table = pq.read_table(out / "trials.parquet")
    failed = table.filter(pc.equal(table["trial"], 1))
    assert failed["method"].to_pylist() == METHODS and set(failed["status"].to_pylist()) == {"failed"}
    assert set(failed["error"].to_pylist()) == {"RuntimeError: injected failure"}
    assert failed["all.sep"].null_count == len(METHODS)
    mc = json.loads((out / "metrics.json").read_text())["monte_carlo"]
    assert (mc["trials"], mc["failed"]) == (2, 1)
    assert mc["failures"] == [{"trial": 1, "error": "RuntimeError: injected failure"}]
    assert mc["methods"]["kf"]["all.sep"]["n"] == 1 and mc["methods"]["kf"]["all.sep"]["sd"] is None
