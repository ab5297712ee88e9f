"""`longwall record` (twin.opcua.recorder) against `longwall serve` of the default scenario at full speed on
127.0.0.1: the recorded sensor streams are the served run's row for row, bit for bit, across a dropped connection
too; the estimators on the recording give the batch run's SEP; bad input is one line, exit 2."""

from __future__ import annotations

import asyncio
import json
import shutil
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from twin.cli import main
from twin.config.scenario import load_face_scenario
from twin.view.layout import free_port

pytestmark = pytest.mark.slow  # a served run, recorded twice, and the estimators twice: a minute

HISTORY_S = 3000.0
"""The server's ring buffer: the whole run (at full speed a recorder on a busy machine may fall minutes behind)."""
DROP_AFTER_ROWS = 20_000
"""IMU rows the in-process recorder takes before its connection is cut."""


async def _record_with_a_drop(asyncua, endpoint: str, out):
    """An in-process recorder whose socket is aborted (the connection dropped under it) mid-run; its report and the
    IMU rows it had when the connection was cut."""
    from twin.opcua.recorder import Recorder

    warned = []
    recorder = Recorder(endpoint, out, warn=warned.append)
    task = asyncio.ensure_future(recorder.run())
    while not (recorder.streams and recorder.streams["Imu"].rows >= DROP_AFTER_ROWS):
        assert not task.done(), task.exception() if task.done() else None
        await asyncio.sleep(0.05)
    cut_at = recorder.streams["Imu"].rows
    recorder.client.uaclient.protocol.transport.abort()
    return await asyncio.wait_for(task, 600), cut_at, warned


@pytest.fixture(scope="module")
def served_and_recorded(asyncua, tmp_path_factory):
    """The default scenario served at full speed, recorded by `longwall record` (a process) and by an in-process
    recorder whose connection is dropped mid-run, at once."""
    tmp = tmp_path_factory.mktemp("record")
    port = free_port()
    endpoint = f"opc.tcp://127.0.0.1:{port}"
    server = subprocess.Popen([sys.executable, "-m", "twin.cli", "serve", "--speed", "max", "--endpoint", endpoint,
                               "--history", str(HISTORY_S), "--out", str(tmp / "served")],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert "serving on" in server.stdout.readline()
        cli = subprocess.Popen([sys.executable, "-m", "twin.cli", "record", "--opcua", endpoint, "--out",
                                str(tmp / "recorded")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        dropped = asyncio.run(_record_with_a_drop(asyncua, endpoint, tmp / "dropped"))
        cli_out, cli_err = cli.communicate(timeout=600)
        _, serve_err = server.communicate(timeout=600)
    finally:
        server.kill()
    assert server.returncode == 0, serve_err[-2000:]
    assert cli.returncode == 0, cli_err[-2000:]
    return tmp, cli_out, cli_err, dropped


def _same_rows(recorded, served) -> None:
    """Every sensor stream of `served` is in `recorded` with the same rows, bit for bit (NaN included)."""
    names = {"imu", "odometer", "mag", "survey", "face_survey", "pushram", "pressure"}
    assert {p.stem for p in recorded.glob("*.parquet")} == names
    for name in names:
        got, want = pq.read_table(recorded / f"{name}.parquet"), pq.read_table(served / f"{name}.parquet")
        assert got.schema.equals(want.schema, check_metadata=True), name
        assert got.num_rows == want.num_rows > 0, name
        for column in want.column_names:
            assert got.column(column).to_numpy().tobytes() == want.column(column).to_numpy().tobytes(), (name, column)


def test_the_recording_is_the_served_runs_sensor_streams_row_for_row(served_and_recorded):
    tmp, cli_out, cli_err, _ = served_and_recorded
    _same_rows(tmp / "recorded", tmp / "served")
    assert not list((tmp / "recorded").glob("truth_*")) and not (tmp / "recorded" / "faults.parquet").exists()
    assert (tmp / "recorded" / "scenario.toml").read_text() == (tmp / "served" / "scenario.toml").read_text()
    report = json.loads((tmp / "recorded" / "record_report.json").read_text())
    assert report["finished"] and report["gaps"] == {} and cli_err == ""
    assert "recorded until the run finished" in cli_out and "no gap" in cli_out


def test_a_dropped_connection_loses_no_sample(served_and_recorded):
    tmp, _, _, (report, cut_at, warned) = served_and_recorded
    assert report["reconnects"] >= 1 and report["gaps"] == {} and warned == []
    assert 0 < cut_at < report["rows"]["imu"]  # cut mid-run
    _same_rows(tmp / "dropped", tmp / "served")


def test_the_served_estimate_is_recorded_whole_across_a_drop(served_and_recorded):
    """The server's estimator (kf_cpoem_rts, the default) is recorded as estimates/kf_cpoem_rts.parquet by both
    recorders, the one whose connection dropped included: the same rows, bit for bit, in time order, up to the
    run's end."""
    tmp, cli_out, _, (report, _, _) = served_and_recorded
    got, want = (pq.read_table(tmp / run / "estimates" / "kf_cpoem_rts.parquet") for run in ("dropped", "recorded"))
    assert got.schema.equals(want.schema, check_metadata=True) and got.num_rows == want.num_rows > 0
    for column in want.column_names:
        assert got.column(column).to_numpy().tobytes() == want.column(column).to_numpy().tobytes(), column
    t = want.column("t").to_numpy()
    imu_t = pq.read_table(tmp / "served" / "imu.parquet", columns=["t"]).column("t").to_numpy()
    assert (np.diff(t) > 0).all() and imu_t[-1] - t[-1] < 1.0
    assert report["rows"]["estimates/kf_cpoem_rts"] == t.size and "estimates/kf_cpoem_rts" in cli_out


def test_the_estimators_on_the_recording_give_the_batch_runs_sep(served_and_recorded):
    """kf_cpoem_rts and fkf_rail on the recording (scored against the served run's truth, which the recording does
    not hold) and on the served run itself (the batch run of the scenario and seed): SEP per cycle within 10 %."""
    from twin.pipeline.estimate import run_estimators

    tmp = served_and_recorded[0]
    scn = load_face_scenario(tmp / "served" / "scenario.toml")
    shearer = scn.estimators.shearer.model_copy(update={"methods": ["kf_cpoem_rts", "fkf_rail"]})
    scn = scn.model_copy(update={"estimators": scn.estimators.model_copy(update={"shearer": shearer})})
    scored = tmp / "scored"
    shutil.copytree(tmp / "recorded", scored)
    for name in ("truth_shearer", "truth_cycles"):
        shutil.copy(tmp / "served" / f"{name}.parquet", scored)
    batch = run_estimators(tmp / "served", scn, recording=False)
    live = run_estimators(scored, scn, recording=False)
    for method in ("kf_cpoem_rts", "fkf_rail"):
        for want, got in zip(batch[method]["cycles"], live[method]["cycles"]):
            assert np.isfinite(want["sep"]) and abs(got["sep"] - want["sep"]) <= 0.1 * want["sep"], (method, want, got)


@pytest.mark.parametrize("args, said", [
    (["--opcua", "http://127.0.0.1:4840"], "--opcua http://127.0.0.1:4840: not opc.tcp://HOST:PORT"),
    (["--opcua", "opc.tcp://127.0.0.1:{port}"], "no OPC UA server answers there"),
    (["--opcua", "opc.tcp://127.0.0.1:{port}", "--duration", "-1"], "must be above 0"),
    (["--opcua", "opc.tcp://127.0.0.1:{port}", "--out", "{full}"], "directory exists and is not empty"),
])
def test_bad_input_to_record_is_one_line_and_exit_2(asyncua, args, said, tmp_path, capsys):
    full = tmp_path / "full"
    full.mkdir()
    (full / "mine.txt").write_text("not a run")
    args = [a.format(port=free_port(), full=full) for a in args]
    if "--out" not in args:
        args += ["--out", str(tmp_path / "new")]
    assert main(["record", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and said in err[0], err
    assert not (tmp_path / "new").exists() and (full / "mine.txt").exists()
