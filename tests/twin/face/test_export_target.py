"""What `longwall model` writes to, checked before MuJoCo loads (twin.face.export_target): one line and exit 2 for bad
input, nothing written; the OpenGL backend chosen where there is no display."""

from __future__ import annotations

import os
import sys

import pytest

from tests.conftest import SCENARIO_DIR
from twin.cli import main
from twin.face.export_target import select_gl

SCENARIO = SCENARIO_DIR / "default.toml"


@pytest.mark.parametrize("argv, words", [
    (["model", str(SCENARIO)], ["--xml", "--png"]),
    (["model", str(SCENARIO), "--xml", "face.xml", "--width", "800"], ["--width", "--png"]),
    (["model", str(SCENARIO), "--png", "face.png", "--width", "20"], ["width 20 px", "64..7680"]),
    (["model", str(SCENARIO), "--png", "face.png", "--width", "wide"], ["'wide'", "width"]),
    (["model", "nowhere.toml", "--xml", "face.xml"], ["nowhere.toml", "not found"]),
    (["model", str(SCENARIO), "--xml", "missing/face.xml"], ["missing", "does not exist"]),
    (["model", str(SCENARIO), "--xml", "."], ["is a folder"]),
    (["model", str(SCENARIO_DIR / "seed000_coning.toml"), "--xml", "face.xml"], ["experiment", "face scenario"]),
])
def test_bad_input_is_one_line_exit_2_nothing_written(tmp_path, monkeypatch, capsys, argv, words):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("longwall: error: ")
    assert all(w in err for w in words), err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="EGL is chosen on Linux only")
@pytest.mark.parametrize("display, preset, mujoco_loaded, chosen", [
    (None, None, False, "egl"),          # headless: EGL
    (":0", None, False, None),           # a display: MuJoCo's own choice (GLFW)
    (None, "osmesa", False, "osmesa"),   # the user's choice stands
    (None, None, True, None),            # MuJoCo already chose
])
def test_egl_is_chosen_where_there_is_no_display(monkeypatch, display, preset, mujoco_loaded, chosen):
    for name, value in (("DISPLAY", display), ("WAYLAND_DISPLAY", None), ("MUJOCO_GL", preset)):
        if value is None:
            monkeypatch.delenv(name, raising=False)
        else:
            monkeypatch.setenv(name, value)
    if not mujoco_loaded:
        monkeypatch.delitem(sys.modules, "mujoco", raising=False)
    select_gl()
    assert os.environ.get("MUJOCO_GL") == chosen
