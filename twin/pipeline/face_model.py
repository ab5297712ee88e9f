"""What `longwall model` writes: the face a scenario's run starts from (simulate.settled_face) assembled with the
shearer mid-face as one MJCF file (twin.face.export) and rendered offscreen (twin.face.render)."""

from __future__ import annotations

from pathlib import Path

from twin.config.scenario import Scenario
from twin.face.export_target import ExportError, check_output, check_width, select_gl


def write_face_model(scn: Scenario, xml: str | Path | None, png: str | Path | None, width: int) -> dict[Path, int]:
    """Write the face of `scn` as the MJCF file `xml` (it opens in `python -m mujoco.viewer --mjcf`) and/or render it
    to the PNG file `png`, `width` pixels wide; at least one. Returns each file written and its size [bytes]. The
    outputs are checked before anything is built (ExportError)."""
    outputs = [Path(p) for p in (xml, png) if p is not None]
    if not outputs:
        raise ExportError("nothing to write: give an MJCF file (xml), a PNG file (png) or both")
    for path in outputs:
        check_output(path)
    check_width(width)
    if png is not None:
        select_gl()
    # Imported after select_gl: MuJoCo reads MUJOCO_GL when it is first imported.
    from twin.face.export import CAMERA, assembled_face_spec, compiled_at_rest, write_mjcf
    from twin.face.render import render, write_png
    from twin.pipeline.simulate import settled_face

    spec = assembled_face_spec(*settled_face(scn))
    written = {}
    if xml is not None:
        written[Path(xml)] = write_mjcf(spec, Path(xml))
    if png is not None:
        written[Path(png)] = write_png(render(*compiled_at_rest(spec), CAMERA, width), Path(png))
    return written
