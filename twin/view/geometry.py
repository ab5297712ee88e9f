"""The MJCF pieces' geoms drawn in Rerun: every geom of a body of the compiled piece (twin.face.model.piece_model),
in its body frame, as one Rerun shape per geom: boxes as Boxes3D, cylinders as Cylinders3D, spheres as Ellipsoids3D,
one entity per geom type under the body's entity (`ENTITY/boxes`, `ENTITY/cylinders`, `ENTITY/spheres`).

A body drawn once in its own frame (the shearer, under its Transform3D) is logged static (`log_body`); a set of bodies
that move (pans, supports) is sent column-wise (`send_bodies`): each geom's centre and attitude in the world at every
time, its size static, its colour the MJCF's unless the caller colours it (a pan's bend, a support's state).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import rerun as rr

from estimators.nav.rotations import quat_mul, quat_rotate
from twin.view.rerun_columns import time_column, xyzw

SHAPES = {int(mujoco.mjtGeom.mjGEOM_BOX): "boxes", int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinders",
          int(mujoco.mjtGeom.mjGEOM_SPHERE): "spheres"}
"""The geom types the pieces use, by the entity they are drawn in."""


@dataclass(frozen=True)
class BodyGeoms:
    """The geoms of one body of a compiled MJCF piece, in the body frame."""

    names: tuple[str, ...]
    kind: np.ndarray  # (G,) mjtGeom
    size: np.ndarray  # (G, 3) MuJoCo's sizes: box half sizes; cylinder radius, half length; sphere radius
    pos: np.ndarray  # (G, 3)
    quat: np.ndarray  # (G, 4) w, x, y, z
    rgba: np.ndarray  # (G, 4) uint8
    body_pos: np.ndarray  # (3,) the body's origin in its parent's frame

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """The geom `name`'s row (its name in the piece, without a prefix)."""
        return self.names.index(name)


def body_geoms(model: mujoco.MjModel, body: str) -> BodyGeoms:
    """Geoms of `body` in a compiled model; ValueError for a geom type Rerun is not given here (SHAPES)."""
    b = model.body(body).id
    rows = np.flatnonzero(model.geom_bodyid == b)
    kind = model.geom_type[rows].astype(int)
    unknown = sorted({mujoco.mjtGeom(k).name for k in kind if k not in SHAPES})
    if unknown:
        raise ValueError(f"body_geoms: {body} has geoms of type {', '.join(unknown)}; twin.view.geometry draws "
                         f"{', '.join(mujoco.mjtGeom(k).name for k in SHAPES)}")
    return BodyGeoms(tuple(model.geom(int(g)).name for g in rows), kind, model.geom_size[rows].copy(),
                     model.geom_pos[rows].copy(), model.geom_quat[rows].copy(),
                     np.round(255 * model.geom_rgba[rows]).astype(np.uint8), model.body_pos[b].copy())


def _sizes(kind: int, size: np.ndarray) -> dict[str, np.ndarray]:
    """An archetype's size fields of geoms of one type (size (..., 3))."""
    if kind == mujoco.mjtGeom.mjGEOM_BOX:
        return {"half_sizes": size.reshape(-1, 3).astype(np.float32)}
    if kind == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return {"radii": size[..., 0].ravel().astype(np.float32), "lengths": 2 * size[..., 1].ravel().astype(np.float32)}
    return {"half_sizes": np.repeat(size[..., :1], 3, axis=-1).reshape(-1, 3).astype(np.float32)}


def _archetype(kind: int) -> type:
    return {"boxes": rr.Boxes3D, "cylinders": rr.Cylinders3D, "spheres": rr.Ellipsoids3D}[SHAPES[kind]]


def log_body(rec: rr.RecordingStream, entity: str, geoms: BodyGeoms) -> None:
    """A body's geoms, static, in the frame of `entity` (the body's)."""
    for kind in np.unique(geoms.kind):
        rows = geoms.kind == kind
        rec.log(f"{entity}/{SHAPES[kind]}", _archetype(kind)(
            **_sizes(kind, geoms.size[rows]), centers=geoms.pos[rows].astype(np.float32),
            quaternions=xyzw(geoms.quat[rows]), colors=geoms.rgba[rows], fill_mode="solid"), static=True)


def send_bodies(rec: rr.RecordingStream, entity: str, times: np.ndarray,
                bodies: list[tuple[BodyGeoms, np.ndarray, np.ndarray]], colors: np.ndarray | None = None,
                static: bool = True) -> None:
    """N bodies at T times, each drawn with the geoms of its kind: `bodies` holds (geoms, origins (T, N, 3), attitudes
    (T, N, 4) w, x, y, z) per body of the piece (a support and its canopy), all in the world; `colors` (T, N, G, 4)
    uint8 over the geoms of all of them in that order (the MJCF's, static, without). `static` False for the later
    chunks of a history sent in several: the sizes (and the MJCF's colours) were logged with the first."""
    centres, quats = [], []
    for geoms, p, q in bodies:
        q_g = q[:, :, None, :]
        centres.append(p[:, :, None, :] + quat_rotate(q_g, geoms.pos))
        quats.append(quat_mul(q_g, geoms.quat))
    centres, quats = np.concatenate(centres, axis=2), np.concatenate(quats, axis=2)
    kind = np.concatenate([g.kind for g, _, _ in bodies])
    size = np.concatenate([g.size for g, _, _ in bodies])
    rgba = np.concatenate([g.rgba for g, _, _ in bodies])
    n_t, n = centres.shape[:2]
    for k in np.unique(kind):
        rows = kind == k
        count = n * int(rows.sum())
        archetype, path = _archetype(k), f"{entity}/{SHAPES[k]}"
        if static:
            fields = _sizes(k, np.broadcast_to(size[rows], (n, int(rows.sum()), 3)))
            if colors is None:
                fields["colors"] = np.broadcast_to(rgba[rows], (n, int(rows.sum()), 4)).reshape(-1, 4)
            rec.log(path, archetype.from_fields(**fields, fill_mode="solid"), static=True)
        moving = {"centers": centres[:, :, rows].reshape(-1, 3).astype(np.float32),
                  "quaternions": xyzw(quats[:, :, rows]).reshape(-1, 4)}
        if colors is not None:
            moving["colors"] = colors[:, :, rows].reshape(-1, 4)
        rec.send_columns(path, indexes=[time_column(times)],
                         columns=archetype.columns(**moving).partition(np.full(n_t, count)))
