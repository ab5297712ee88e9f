"""Estimation on a log without truth (a real face's, imported): every estimate, the recording, the report and
what each estimate says of itself, no errors scored, one line saying so; the estimates the same as with truth."""

from __future__ import annotations

import contextlib
import filecmp
import io
import json
import shutil

import numpy as np
import pytest
from rerun.chunk import RrdReader

import estimators
import twin
from estimators.io.logformat import (
    ESTIMATES_DIR,
    STREAMS,
    SUPPORT_IMU,
    make_table,
    write_stream,
)
from tests.conftest import capped, simulated
from twin.cli import main
from twin.config.scenario import parse_scenario, scenario_to_toml
from twin.pipeline.estimate import format_estimators, positioning_config, run_estimators, solution_columns
from twin.pipeline.support_estimate import SUPPORT_ATTITUDE
from twin.sensors.support_imu import support_imu_stream
from twin.view.recording import ESTIMATES_RRD

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

METHODS = ["dr", "kf", "ckf_mag"]
"""Dead reckoning, a filter with sensor states and a federated one: every kind of estimate file but detectors."""
NO_TRUTH = "no truth in this run"


def short_scenario(methods=METHODS):
    data = capped("default", cycles=1).model_dump()
    data["estimators"]["shearer"]["methods"] = list(methods)
    return parse_scenario(data, "default")


def _estimate_files(run_dir) -> list[str]:
    return sorted(p.name for p in (run_dir / ESTIMATES_DIR).glob("*.parquet"))


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """The short default run (with truth), estimated when it was run."""
    return twin.run(short_scenario(), tmp_path_factory.mktemp("truth") / "run").dir


@pytest.fixture(scope="module")
def imported(run_dir, tmp_path_factory):
    """run_dir exported to CSV, the truth CSV files removed, imported by the command line."""
    base = tmp_path_factory.mktemp("no_truth")
    assert main(["export", str(run_dir), "--csv", str(base / "csv")]) == 0
    for path in (base / "csv").glob("truth_*.csv"):
        path.unlink()
    assert main(["import", str(base / "csv"), "--out", str(base / "imp")]) == 0
    return base / "imp"


@pytest.fixture(scope="module")
def estimated(imported):
    """`longwall estimate` on the imported log: (rc, printed summary)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(["estimate", str(imported)])
    return rc, out.getvalue()


def test_estimate_writes_everything_that_needs_no_truth(imported, estimated):
    rc, printed = estimated
    assert rc == 0
    assert _estimate_files(imported) == ["ckf_mag.parquet", "ckf_mag_fusion.parquet", "ckf_mag_states.parquet",
                                         "dr.parquet", "kf.parquet", "kf_states.parquet"]
    metrics = json.loads((imported / "metrics.json").read_text())["estimators"]
    assert list(metrics) == METHODS
    for name, entry in metrics.items():
        assert entry["truth"] is False and "cycles" not in entry, name
        own = entry["self"]
        assert own["samples"] > 1000 and 50 < own["distance_m"] < 500, name
        assert len(own["survey_residuals"]) >= 1 and all(np.isfinite(r["horizontal"]) for r in own["survey_residuals"])
    assert metrics["kf"]["self"]["flags"]["zupts"] > 0 and metrics["kf"]["self"]["final_sd_horizontal_m"] > 0
    assert metrics["dr"]["self"]["final_sd_horizontal_m"] is None  # dead reckoning carries no covariance
    assert set(metrics["kf"]["odo_scale"]) == {"estimate", "sd"}  # the scenario's scale error is no truth
    assert sum(NO_TRUTH in line for line in printed.splitlines()) == 1
    assert "SEP" not in printed and "maximum error" not in printed

    entities = {c.entity_path for c in RrdReader(imported / ESTIMATES_RRD).stream().to_chunks()}
    for name in METHODS:
        assert {f"/world/estimates/{name}/path", f"/plots/flags/{name}"} <= entities
    assert {"/plots/sigma/kf/position/east", "/plots/sigma/ckf_mag/attitude/u"} <= entities
    assert "/plots/states/kf/odo_scale" in entities and "/plots/fusion/ckf_mag/yaw_innovation" in entities
    assert not any(e.startswith(("/plots/errors", "/plots/attitude_errors")) for e in entities)


def test_truth_does_not_change_an_estimate(run_dir, imported, estimated, tmp_path):
    """The imported log with the run's truth put back: the same estimate files, byte for byte, now scored."""
    with_truth = tmp_path / "with_truth"
    shutil.copytree(imported, with_truth)
    for path in run_dir.glob("truth_*.parquet"):
        shutil.copy(path, with_truth / path.name)
    assert main(["estimate", str(with_truth), "--quiet"]) == 0
    assert _estimate_files(with_truth) == _estimate_files(imported)
    for name in _estimate_files(imported):
        assert filecmp.cmp(with_truth / ESTIMATES_DIR / name, imported / ESTIMATES_DIR / name, shallow=False), name
    scored = json.loads((with_truth / "metrics.json").read_text())["estimators"]
    unscored = json.loads((imported / "metrics.json").read_text())["estimators"]
    for name in METHODS:
        assert scored[name]["truth"] is True and scored[name]["cycles"][-1]["samples"] > 0
        assert scored[name]["self"] == unscored[name]["self"]


def test_report_and_view_on_a_run_without_truth(imported, estimated, viewer_launches):
    from twin.view.report import REPORT_DIR, REPORT_HTML

    assert main(["report", str(imported)]) == 0
    assert {p.name for p in (imported / REPORT_DIR).glob("*.png")} == {
        "top_view.png", "plan_view.png", "profile.png", "sigma.png", "supports.png", "pressures.png"}  # no errors
    page = (imported / REPORT_DIR / REPORT_HTML).read_text()
    assert "no errors scored" in page and "errors against time" in page and "survey [m]" in page
    assert main(["view", str(imported)]) == 0
    [args] = viewer_launches
    assert args[:2] == ["/usr/bin/rerun", str(imported / ESTIMATES_RRD)] and args[2].endswith(".rbl")


def test_python_api_estimates_without_truth(run_dir, tmp_path):
    """twin.estimate and estimators.estimate on the run with its truth and estimates removed: the run's own
    estimate files (made with truth beside them), unscored."""
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("truth_*", ESTIMATES_DIR, "*.rrd"))
    run = twin.estimate(copy)
    for name in _estimate_files(run_dir):
        assert filecmp.cmp(copy / ESTIMATES_DIR / name, run_dir / ESTIMATES_DIR / name, shallow=False), name
    assert all(e["truth"] is False and "cycles" not in e for e in run.metrics["estimators"].values())
    assert run.estimate("kf").num_rows == run.metrics["estimators"]["kf"]["self"]["samples"]
    sol = estimators.estimate(copy, "dr", positioning_config(short_scenario()))
    table = run.estimate("dr")
    for key, values in solution_columns(sol, short_scenario()).items():
        np.testing.assert_array_equal(values, table.column(key).to_numpy(), err_msg=key)


def test_partial_truth_scores_the_whole_run_only(run_dir, tmp_path):
    """truth_shearer without truth_cycles: the errors over the whole run (the "all" row), said so in the table."""
    copy = tmp_path / "partial"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("truth_cycles.parquet", ESTIMATES_DIR, "*.rrd"))
    out = run_estimators(copy, short_scenario(["dr"]), recording=False)
    full = json.loads((run_dir / "metrics.json").read_text())["estimators"]["dr"]["cycles"]
    assert out["dr"]["truth"] is True and [c["cycle"] for c in out["dr"]["cycles"]] == ["all"]
    assert out["dr"]["cycles"][0]["sep"] == full[-1]["sep"]
    assert "over the whole run only" in format_estimators(out)


def test_support_attitude_without_truth(tmp_path):
    """seed002_face's support_imu stream alone (two of its units, to keep it short): kf, ukf and ours (the GD-UKF
    needs the truth to tune), the same files as with truth, unscored, one line saying so."""
    face, result = simulated("seed002_face")
    data = face.model_dump()
    data["sensors"]["support_imu"]["supports"] = face.sensors.support_imu.supports[::5]
    scn = parse_scenario(data, face.name)
    cols = support_imu_stream(scn, result.tables["truth_supports"], result.tables["truth_shearer"],
                              np.random.default_rng(scn.seed))
    dirs = {"none": tmp_path / "none", "truth": tmp_path / "truth"}
    for path in dirs.values():
        path.mkdir()
        (path / "scenario.toml").write_text(scenario_to_toml(scn))
        write_stream(path, SUPPORT_IMU, make_table(SUPPORT_IMU, cols))
    for name in ("truth_supports", "truth_shearer"):
        write_stream(dirs["truth"], STREAMS[name], make_table(STREAMS[name], result.tables[name]))
    out = {key: run_estimators(path, scn)[SUPPORT_ATTITUDE] for key, path in dirs.items()}
    assert out["none"]["truth"] is False and out["truth"]["truth"] is True
    assert out["none"]["methods"] == ["kf", "ukf", "ours"] and "per_support" not in out["none"]
    assert out["none"]["own"]["final_deg"] == {j: {m: out["truth"]["own"]["final_deg"][j][m] for m in
                                                   out["none"]["methods"]} for j in out["none"]["supports"]}
    for name in _estimate_files(dirs["none"]):
        assert filecmp.cmp(dirs["none"] / ESTIMATES_DIR / name, dirs["truth"] / ESTIMATES_DIR / name,
                           shallow=False), name
    printed = format_estimators({SUPPORT_ATTITUDE: out["none"]})
    assert sum("no truth_supports" in line for line in printed.splitlines()) == 1 and "RMSE" not in printed
    assert (dirs["none"] / ESTIMATES_RRD).is_file()
