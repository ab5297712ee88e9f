"""Offscreen renders of a model through one of its cameras (mujoco.Renderer), written as PNG.

The OpenGL backend comes from MUJOCO_GL (twin.face.export_target.select_gl chooses EGL where there is no display);
without one, a render is one line (ExportError) saying what to install or set.
"""

from __future__ import annotations

import os
from pathlib import Path

import matplotlib.image
import mujoco
import numpy as np

from twin.face.export_target import ExportError

IMAGE_ASPECT = 16 / 9
"""Width over height of a render."""


def render(model: mujoco.MjModel, data: mujoco.MjData, camera: str, width: int) -> np.ndarray:
    """The scene of `data` through `camera`, `width` pixels wide at IMAGE_ASPECT: (height, width, 3) uint8 RGB.
    The model's offscreen buffer is set to the image's size (MuJoCo's default, 640 x 480, caps a render; a larger one
    than the image costs memory: 0.8 GB at 3840 x 2160 with Mesa's EGL)."""
    height = max(1, round(width / IMAGE_ASPECT))
    model.vis.global_.offwidth, model.vis.global_.offheight = width, height
    try:
        renderer = mujoco.Renderer(model, height, width)
    except Exception as err:  # each backend fails its own way: ImportError, RuntimeError, mujoco.FatalError, ...
        reason = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ExportError(f"no OpenGL context for an offscreen render (MUJOCO_GL={os.environ.get('MUJOCO_GL', '')!r}: "
                          f"{reason}); install EGL or OSMesa (e.g. libegl1, libosmesa6) and set MUJOCO_GL=egl or "
                          f"osmesa before Python starts") from None
    with renderer:
        renderer.update_scene(data, camera=camera)
        return renderer.render()


def write_png(image: np.ndarray, path: Path) -> int:
    """Write an RGB image as PNG; returns the file's size [bytes]."""
    try:
        matplotlib.image.imsave(path, image, format="png")
    except OSError as err:
        raise ExportError(f"{path}: cannot write the image ({err.strerror}); choose a writable path") from None
    return path.stat().st_size
