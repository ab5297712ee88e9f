"""What a model export (twin.face.export, twin.face.render) writes to, checked before MuJoCo loads: the output files,
the image's width, and the OpenGL backend of a render. MuJoCo reads MUJOCO_GL once, when it is first imported, so
the backend is chosen before that: on Linux without a display, EGL (headless, on a GPU or Mesa's software renderer).
This module does not import MuJoCo."""

from __future__ import annotations

import os
import sys
from pathlib import Path

DEFAULT_WIDTH_PX = 1600
WIDTH_RANGE_PX = (64, 7680)


class ExportError(Exception):
    """A model that cannot be written or rendered; its message is one line (what, where, how to fix)."""


def check_output(path: Path) -> None:
    """ExportError unless a file can be written at `path`: not a folder, in a folder that exists."""
    if path.is_dir():
        raise ExportError(f"{path}: is a folder; give a file name in it")
    if not path.parent.is_dir():
        raise ExportError(f"{path}: the folder {path.parent} does not exist; create it or choose another path")


def check_width(width: int) -> None:
    """ExportError unless `width` [px] is within WIDTH_RANGE_PX."""
    lo, hi = WIDTH_RANGE_PX
    if not lo <= width <= hi:
        raise ExportError(f"width {width} px is outside {lo}..{hi}; give a width in that range")


def select_gl() -> None:
    """Set MUJOCO_GL to egl on a Linux machine without a display, unless the user has set it (osmesa, glfw, ...) or
    MuJoCo is already imported (then it has chosen)."""
    if "mujoco" in sys.modules or not sys.platform.startswith("linux"):
        return
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("MUJOCO_GL", "egl")
