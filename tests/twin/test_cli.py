"""`longwall run`: the default scenario end to end, atomic run directories, bad input, reproducibility."""

from __future__ import annotations

import filecmp
import json

import numpy as np
import pytest
from rerun.chunk import RrdReader

from estimators.io.logformat import STREAMS, read_stream
from tests.conftest import SCENARIO_DIR
from twin.cli import main

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")

TRUTH_FILES = ("truth_shearer.parquet", "truth_pans.parquet", "truth_supports.parquet", "truth_cycles.parquet")


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("runs") / "default"
    assert main(["run", "--out", str(out), "--quiet"]) == 0
    return out


def test_default_run_writes_a_complete_run_directory(default_run):
    names = {p.name for p in default_run.iterdir()}
    assert set(TRUTH_FILES) | {"scenario.toml", "metrics.json", "run.rrd"} <= names
    for name in TRUTH_FILES:
        read_stream(default_run, STREAMS[name.removesuffix(".parquet")])  # validates columns and units
    metrics = json.loads((default_run / "metrics.json").read_text())
    assert metrics["twin"]["scenario"] == "default" and len(metrics["twin"]["cycles"]) == 2
    assert not [p for p in default_run.parent.iterdir() if ".partial-" in p.name]


def test_recording_reads_back_with_the_face_entities(default_run):
    reader = RrdReader(str(default_run / "run.rrd"))
    entities = {chunk.entity_path for chunk in reader.stream().to_chunks()}
    for entity in ("/world/floor", "/world/pans/boxes", "/world/supports/boxes", "/world/supports/cylinders",
                   "/world/rams", "/world/shearer", "/world/shearer/boxes", "/world/shearer/cylinders",
                   "/world/shearer_path", "/plots/shearer_speed", "/plots/bend_horizontal_deg",
                   "/plots/ram_length"):
        assert entity in entities or entity.lstrip("/") in entities, entity


def test_existing_directory_is_refused_without_force(default_run, capsys):
    before = sorted(p.name for p in default_run.iterdir())
    assert main(["run", "--out", str(default_run), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--force" in err
    assert sorted(p.name for p in default_run.iterdir()) == before


@pytest.mark.parametrize("content, words", [
    ('name = "x"\n[face]\npan_count = "many"\n', ["face.pan_count"]),
    ('name = "x"\nbogus = 1\n', ["bogus", "unknown key"]),
    ('name = "x"\ncycles = 99\n', ["cycles"]),
    ('name = "x"\n[[supports.push.offsets]]\ncycle = 0\noffsets_m = [0.0]\n', ["supports.push.offsets[0]", "44"]),
])
def test_bad_scenario_is_one_line_exit_2_nothing_written(tmp_path, capsys, content, words):
    scenario = tmp_path / "bad.toml"
    scenario.write_text(content)
    out = tmp_path / "out"
    assert main(["run", str(scenario), "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(scenario) in err
    for word in words:
        assert word in err
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["bad.toml"]


def test_missing_scenario_file(tmp_path, capsys):
    assert main(["run", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert "not found" in capsys.readouterr().err


def short_scenario(tmp_path, seed: int):
    """The default face with one short cycle, for the reproducibility checks."""
    text = (SCENARIO_DIR / "default.toml").read_text().replace("cycles = 2", "cycles = 1")
    path = tmp_path / "short.toml"
    path.write_text(text)
    out = tmp_path / f"seed{seed}-{len(list(tmp_path.iterdir()))}"
    assert main(["run", str(path), "--out", str(out), "--seed", str(seed), "--quiet"]) == 0
    return out


def test_same_seed_gives_bit_identical_truth_and_another_seed_does_not(tmp_path):
    a, b = short_scenario(tmp_path, 7), short_scenario(tmp_path, 7)
    for name in TRUTH_FILES:
        assert filecmp.cmp(a / name, b / name, shallow=False), name
    # Every file of the run directory, the recordings included: the same bytes, but the wall-clock figures
    # (timing.json).
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    assert "wall_s" not in (a / "metrics.json").read_text() and (a / "timing.json").is_file()
    assert any(name.suffix == ".rrd" for name in files)
    for name in files:
        if name.name != "timing.json":
            assert filecmp.cmp(a / name, b / name, shallow=False), name
    c = short_scenario(tmp_path, 8)
    # Rows at t = 0 are the initial pans; their bends come from the seed.
    bends = [read_stream(run, STREAMS["truth_pans"]).column("bend_h").to_numpy()[:43] for run in (a, c)]
    assert np.abs(bends[0] - bends[1]).max() > 1e-4


def test_a_crash_leaves_no_run_directory(tmp_path, monkeypatch):
    import twin.view.recording

    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(twin.view.recording, "write_recording", broken)
    scenario = tmp_path / "short.toml"
    scenario.write_text((SCENARIO_DIR / "default.toml").read_text().replace("cycles = 2", "cycles = 1"))
    with pytest.raises(RuntimeError):
        main(["run", str(scenario), "--out", str(tmp_path / "out"), "--quiet"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.toml"]


def test_export_and_import_give_identical_streams(default_run, tmp_path):
    csv_dir, back = tmp_path / "csv", tmp_path / "back"
    assert main(["export", str(default_run), "--csv", str(csv_dir)]) == 0
    assert main(["import", str(csv_dir), "--out", str(back)]) == 0
    for name in ("imu", "odometer", "pushram", "mag", "faults", "truth_shearer", "truth_pans"):
        a = read_stream(default_run, STREAMS[name])
        b = read_stream(back, STREAMS[name])
        assert a.schema.equals(b.schema, check_metadata=True), name  # names, types and units
        for col in a.column_names:  # values bit for bit, NaN where NaN
            np.testing.assert_array_equal(a.column(col).to_numpy(zero_copy_only=False),
                                          b.column(col).to_numpy(zero_copy_only=False), err_msg=f"{name}.{col}")


def test_monte_carlo_trials_are_written_beside_trial_zero(tmp_path):
    scenario = tmp_path / "short.toml"
    scenario.write_text((SCENARIO_DIR / "default.toml").read_text().replace("cycles = 2", "cycles = 1"))
    out = tmp_path / "mc"
    assert main(["run", str(scenario), "--out", str(out), "--trials", "3", "--quiet"]) == 0
    imus = [read_stream(d, STREAMS["imu"]) for d in (out, out / "trials" / "001", out / "trials" / "002")]
    assert imus[0].column("t").equals(imus[2].column("t"))
    assert not imus[0].column("dtheta_x").equals(imus[1].column("dtheta_x"))
    assert not (out / "trials" / "001" / "truth_shearer.parquet").exists()  # one truth for all trials


def test_run_writes_estimates_and_estimate_reruns_them(default_run, capsys):
    from estimators.io.logformat import read_estimate
    metrics = json.loads((default_run / "metrics.json").read_text())
    assert set(metrics["estimators"]) >= {"dr", "kf", "kf_cpoem", "kf_cpoem_rts"}
    assert len(metrics["estimators"]["kf"]["cycles"]) == 3  # two cycles and "all"
    assert (default_run / "estimates.rrd").is_file()
    # The wall time by stage (timing.json; the summary prints it): every stage that ran, within the total.
    timing = json.loads((default_run / "timing.json").read_text())
    assert {"face", "shearer", "sensors", "recording", "estimators"} <= set(timing["stages_s"])
    assert 0 < sum(timing["stages_s"].values()) <= timing["total_s"] and timing["wall_s"] < timing["total_s"]
    # ... and on the clock: each stage's runs of reports in time order, ending within the run.
    ends = timing["stage_ends_unix_s"]
    assert {stage for _, stage in ends} == set(timing["stages_s"])
    assert [stage for _, stage in ends][-1] == "estimators" and all(a != b for (_, a), (_, b) in zip(ends, ends[1:]))
    times = [t for t, _ in ends]
    assert times == sorted(times) and times[-1] - times[0] <= timing["total_s"]
    before = read_estimate(default_run, "kf_cpoem_rts").column("lat").to_numpy()
    assert main(["estimate", str(default_run)]) == 0
    assert "SEP per cutting cycle" in capsys.readouterr().out
    after = read_estimate(default_run, "kf_cpoem_rts").column("lat").to_numpy()
    assert np.array_equal(before, after)  # same log, same result


def test_estimate_without_a_scenario_is_one_line(tmp_path, capsys):
    assert main(["estimate", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "scenario.toml" in err


def _bytes(paths) -> int:
    return sum(p.stat().st_size for p in paths)


def test_recordings_are_at_most_a_tenth_of_the_parquet(default_run):
    """Issue 24 item 4: run.rrd and estimates.rrd together at most 10 % of the run's Parquet (the streams and
    estimates/), at the default record rate, which metrics.json records."""
    parquet = _bytes([*default_run.glob("*.parquet"), *default_run.glob("estimates/*.parquet")])
    recordings = _bytes([default_run / "run.rrd", default_run / "estimates.rrd"])
    assert recordings <= 0.1 * parquet, f"{recordings / 1e6:.1f} MB of recordings, {parquet / 1e6:.1f} MB of Parquet"
    metrics = json.loads((default_run / "metrics.json").read_text())
    assert metrics["recordings"] == {"run.rrd": 10.0, "estimates.rrd": 10.0}


def _rows(rrd, entity: str) -> int:
    return sum(c.num_rows for c in RrdReader(str(rrd)).stream().to_chunks()
               if c.entity_path == entity and not c.is_static)


def test_record_rate_full_logs_every_estimate_row_and_a_lower_rate_fewer(short_default_run, tmp_path):
    import shutil

    from estimators.io.logformat import read_estimate
    from tests.conftest import SHORT_RUN_S

    run = tmp_path / "run"
    shutil.copytree(short_default_run, run)
    assert main(["estimate", str(run), "--quiet", "--record-rate", "full"]) == 0
    n = read_estimate(run, "kf").num_rows
    assert n > 2 * SHORT_RUN_S + 2
    for entity in ("/world/estimates/kf/position", "/plots/errors/kf/east", "/plots/sigma/kf/gyro_bias"):
        assert _rows(run / "estimates.rrd", entity) == n, entity
    assert json.loads((run / "metrics.json").read_text())["recordings"] == {"estimates.rrd": "full"}
    assert main(["estimate", str(run), "--quiet", "--record-rate", "2"]) == 0
    for entity in ("/world/estimates/kf/position", "/plots/errors/kf/east", "/plots/sigma/kf/gyro_bias"):
        assert 2 <= _rows(run / "estimates.rrd", entity) <= 2 * SHORT_RUN_S + 2, entity  # and the last row
    assert json.loads((run / "metrics.json").read_text())["recordings"] == {"estimates.rrd": 2.0}


@pytest.mark.parametrize("value", ["0", "-5", "fast", "nan", "inf"])
@pytest.mark.parametrize("command", ["run", "estimate"])
def test_a_bad_record_rate_is_one_line_exit_2(tmp_path, capsys, command, value):
    out = tmp_path / "out"
    args = ["run", "--out", str(out)] if command == "run" else ["estimate", str(out)]
    assert main([*args, f"--record-rate={value}"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--record-rate" in err and f"'{value}'" in err and "full" in err
    assert not out.exists()


def test_version_is_the_installed_distributions(capsys):
    """`longwall --version` prints pyproject.toml's version (the installed distribution's) and exits 0."""
    from importlib import metadata

    assert main(["--version"]) == 0
    assert capsys.readouterr().out == f"longwall-twin {metadata.version('longwall-twin')}\n"
