"""`longwall view`: the web viewer for a machine without a display, and the one-line refusals."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import urllib.request

import pytest

from tests.twin.view.test_recording import flat_floor, synthetic_truth
from twin.cli import main
from twin.config.scenario import Face, Scenario
from twin.view.layout import free_port
from twin.view.recording import RUN_RRD, write_recording

pytestmark = pytest.mark.slow  # over 3 s of the full suite: not in the quick subset (pytest -m "not slow")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A directory holding a small run.rrd (the synthetic truth of test_recording)."""
    path = tmp_path_factory.mktemp("run")
    write_recording(path / RUN_RRD, Scenario.model_construct(name="test", face=Face(azimuth_deg=30.0)),
                    synthetic_truth(), flat_floor())
    return path


def test_the_web_viewer_answers_on_localhost_and_stops_on_ctrl_c(run_dir):
    port = free_port()
    view = subprocess.Popen([sys.executable, "-c", "import sys; from twin.cli import main; sys.exit(main(sys.argv[1:]))",
                             "view", str(run_dir), "--web", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as in a terminal:
    # a suite started in the background (nohup, &) hands its children SIGINT ignored, and Python keeps it so
    try:
        line = view.stdout.readline()  # printed once the viewer answers
        assert f"http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A" in line, (line, view.stderr.read())
        url = line.split(": ", 1)[1].split()[0]
        with urllib.request.urlopen(url, timeout=10) as answer:
            assert answer.status == 200
    finally:
        view.send_signal(signal.SIGINT)
        rc = view.wait(timeout=30)
    assert rc == 130 and view.stderr.read().count("\n") == 1
    with pytest.raises(OSError):  # the viewer went with it
        urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2)


def test_without_a_display_view_says_to_use_the_web_viewer(run_dir, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    assert main(["view", str(run_dir)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no display" in err and "--web" in err


@pytest.mark.parametrize("args, words", [(["--port", "9090"], "add --web"), (["--web", "--port", "0"], "1..65535"),
                                         (["--web", "--port", "http"], "not a port")])
def test_bad_view_options_are_one_line(run_dir, capsys, args, words):
    assert main(["view", str(run_dir), *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err


def test_a_port_in_use_is_one_line_and_leaves_no_server(run_dir, capsys):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert main(["view", str(run_dir), "--web", "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"127.0.0.1:{port}" in err and "--port" in err
