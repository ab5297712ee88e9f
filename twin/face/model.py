"""MuJoCo models assembled with MjSpec from the MJCF pieces in `models/`.

Two models come from one scenario:

* the face model (`build_face_spec`): a contiguous range of pans, each its own body with six scalar joints
  (flat layout), neighbours tied by connectors (twin.face.connectors): a pin at their running-line ends on a coupler with
  axial play, the relative horizontal bend, vertical bend and roll limited by fixed tendons (yaw, pitch and roll
  differences); one hydraulic support
  per `pans_per_support` pans with its push ram, a spatial tendon driven by an integrated-velocity actuator
  (the metered stroke; the tendon length is the ram reading) limited to the cylinder's force each way
  (twin.face.hydraulics) and a canopy leg actuator of the same kind (the oil column, set against the roof limit
  of its slide and limited to the yield load); the floor a height field under the window
  only (FloorBand), on a mocap body, placed at each event (place_floor). A range
  that does not reach a face end is closed by mocap anchors standing in for the neighbouring pans, so a
  window of the face can be simulated alone while the rest stays put.
* the ride model (`build_ride_spec`): the shearer as a free body held by a soft weld (its suspension) to a
  mocap target placed from its two shoes on the pan line.

Pan joints are relative to the face frame F (bodies sit at the world origin turned into F), so a pan's
qpos is its state (x, y, z, yaw, pitch, roll) in F; see twin.face.layout.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path

import mujoco
import numpy as np

from estimators.nav.rotations import mat_to_quat
from twin.config.scenario import PAN_FLOOR_FRICTION, Scenario
from twin.face.connectors import CONNECTOR_KINDS, add_connectors, connector_limits_rad
from twin.face.hydraulics import SupportHydraulics
from twin.face.layout import (
    MESH_MAX_CELLS,
    PAN_WIDTH_M,
    SUPPORT_BASE_LENGTH_M,
    FaceFrame,
    Floor,
    support_stations,
)
from twin.face.suspension import weld_solref

PAN_JOINTS = ("x", "y", "z", "yaw", "pitch", "roll")
HFIELD_RESOLUTION_M = 0.25
FLOOR_MARGIN_M = 6.0
BAND_MARGIN_M = 12.0
"""Floor of a window's band beyond its pans and supports on every side [m]. With 6 m, seed004's largest bend went
1.12 deg against its 1 deg limit (0.05 deg tolerated; 1.016 deg on the whole-panel floor); from 12 m it is back to
1.015 deg. The bend limit is a soft tendon limit whose overshoot follows such small changes (issue 25 item 4)."""
RAM_GAIN_N_M = 5.0e7
"""Stiffness of a ram's servo on its metered stroke (the oil column; 5 mm under a 250 kN load)."""
RAM_DAMPING_N_S_M = 1.0e6
LEG_DAMPING_N_S_M = 3.0e6
"""Damping of the legs' servo (near critical with the leg's armature): a canopy free of the roof follows its oil column
within 0.024 s (simulated)."""
LEG_RETRACT_FRACTION = 0.2
"""The legs pull the canopy down (on their annuli) with at most this fraction of their set load."""
SUPPORT_FRICTION_LOWERED_N = 1.0e4
"""Base sliding resistance of a lowered support (base lift on) [N]."""
SUPPORT_GRIP = 0.25
"""Sliding resistance of a set support per newton of leg load (canopy on the roof and base on the floor): 2 MN at
the default set load."""


def models_dir() -> Path:
    """The MJCF pieces: the repository's `models/` (installed as the package data `twin.models`)."""
    return Path(str(resources.files("twin.models")))


@cache
def _piece(name: str) -> mujoco.MjSpec:
    return mujoco.MjSpec.from_file(str(models_dir() / f"{name}.xml"))


def _piece_copy(name: str) -> mujoco.MjSpec:
    return _piece(name).copy()


def _floor_x0(scn: Scenario) -> float:
    """The rear edge of the floor behind the supports at the face's start."""
    return -(scn.supports.ram_length_set_m + PAN_WIDTH_M + SUPPORT_BASE_LENGTH_M + FLOOR_MARGIN_M)


@dataclass(frozen=True)
class FloorGrid:
    """The floor sampled on a regular grid in F (for the height field and the Rerun mesh)."""

    x: np.ndarray  # (ncol,)
    y: np.ndarray  # (nrow,)
    z: np.ndarray  # (nrow, ncol)

    @classmethod
    def sample(cls, floor: Floor, x0: float, y0: float, ncol: int, nrow: int,
               resolution_m: float = HFIELD_RESOLUTION_M) -> "FloorGrid":
        """ncol x nrow points from (x0, y0) at `resolution_m`."""
        x = x0 + resolution_m * np.arange(ncol)
        y = y0 + resolution_m * np.arange(nrow)
        return cls(x, y, floor.height(x[None, :], y[:, None]))

    @classmethod
    def from_scenario(cls, scn: Scenario, floor: Floor) -> "FloorGrid":
        """The floor the run's face covers, from behind the supports at the start to beyond the last web (not the
        whole panel), at HFIELD_RESOLUTION_M or coarser so that it has at most MESH_MAX_CELLS cells."""
        length = scn.face.pan_count * scn.face.pan_length_m
        x0 = _floor_x0(scn)
        x1 = min(scn.face.panel_length_m, scn.cycles * scn.face.web_depth_m) + PAN_WIDTH_M + FLOOR_MARGIN_M
        y0, y1 = -FLOOR_MARGIN_M, length + FLOOR_MARGIN_M
        res = max(HFIELD_RESOLUTION_M, float(np.sqrt((x1 - x0) * (y1 - y0) / MESH_MAX_CELLS)))
        return cls.sample(floor, x0, y0, int(np.ceil((x1 - x0) / res)) + 1, int(np.ceil((y1 - y0) / res)) + 1, res)

    def mesh_t(self, frame: FaceFrame) -> tuple[np.ndarray, np.ndarray]:
        """Triangle mesh of the floor in t: vertices (V, 3) and triangles (T, 3)."""
        xx, yy = np.meshgrid(self.x, self.y)
        verts_f = np.column_stack([xx.ravel(), yy.ravel(), self.z.ravel()])
        ny, nx = self.z.shape
        idx = np.arange(ny * nx).reshape(ny, nx)
        a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
        tris = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
        return verts_f @ frame.mat_tf.T, tris


@dataclass(frozen=True)
class FloorBand:
    """The height field of a window model: the floor under a window's pans and supports only, a band of fixed size
    moved with the window and the face's advance (FaceSimulator fills it at each event), so that a window model's
    memory does not grow with the panel or the face. Its samples lie on one lattice of HFIELD_RESOLUTION_M in F
    whatever the window's place, so every window stands on the same floor surface.

    back_m: how far behind the window's rearmost pan the band starts (its supports at their longest rams, their
    bases, a margin); ncol, nrow: its samples across and along the face; elevation_m: the largest height range of
    the floor over a band (the hfield's elevation scale)."""

    back_m: float
    ncol: int
    nrow: int
    elevation_m: float
    origin_f: tuple[float, float]
    """A point of the lattice: the rear corner of the floor behind the face's start (FloorGrid.from_scenario's)."""

    @classmethod
    def for_window(cls, scn: Scenario, floor: Floor, count: int) -> "FloorBand":
        f, res = scn.face, HFIELD_RESOLUTION_M
        back = scn.supports.ram_length_set_m + 2 * f.web_depth_m + PAN_WIDTH_M + SUPPORT_BASE_LENGTH_M + BAND_MARGIN_M
        front = 2 * f.web_depth_m + PAN_WIDTH_M + BAND_MARGIN_M  # the snake's offset and the push in the event
        ncol = int(np.ceil((back + front) / res)) + 2
        nrow = int(np.ceil((count * f.pan_length_m + 2 * BAND_MARGIN_M) / res)) + 2
        elevation = (abs(floor.dip_x) * ncol * res + abs(floor.dip_y) * nrow * res + 2 * floor.amplitude + 0.05)
        return cls(back, ncol, nrow, elevation, (_floor_x0(scn), -FLOOR_MARGIN_M))

    def place(self, floor: Floor, x_rear: float, y_first: float) -> tuple[FloorGrid, float]:
        """The band's samples for a window whose rearmost pan is at x_rear and whose first pan starts at y_first,
        and the height its zero elevation stands at."""
        res, (ox, oy) = HFIELD_RESOLUTION_M, self.origin_f
        x0 = ox + np.floor((x_rear - self.back_m - ox) / res) * res
        y0 = oy + np.floor((y_first - BAND_MARGIN_M - oy) / res) * res
        grid = FloorGrid.sample(floor, x0, y0, self.ncol, self.nrow)
        return grid, float(grid.z.min()) - 0.01


def _add_floor(spec: mujoco.MjSpec, band: FloorBand, quat_tf: np.ndarray) -> None:
    """The floor height field on a mocap body of its own (a moving floor: MuJoCo bounds a static body's geoms once,
    at compile), without a shape until FaceSimulator places it under a window (place_floor)."""
    res = HFIELD_RESOLUTION_M
    hf = spec.add_hfield(name="floor", nrow=band.nrow, ncol=band.ncol,
                         size=[(band.ncol - 1) * res / 2, (band.nrow - 1) * res / 2, band.elevation_m, 1.0],
                         userdata=[0.0] * (band.nrow * band.ncol))
    body = spec.worldbody.add_body(name="floor", mocap=True, quat=quat_tf)
    # MuJoCo takes the larger friction of two geoms in contact: the floor's is the pans' feet's, so that theirs holds.
    body.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_HFIELD, hfieldname=hf.name, contype=0, conaffinity=1,
                  friction=[PAN_FLOOR_FRICTION, 0.005, 0.0001], rgba=[0.35, 0.3, 0.25, 1])


def place_floor(model: mujoco.MjModel, data: mujoco.MjData, grid: FloorGrid, z0: float, mat_tf: np.ndarray) -> None:
    """Put the floor samples `grid` (a FloorBand's, heights from z0 up) into a face model's height field."""
    hf = model.hfield("floor")
    n = grid.z.size
    adr = int(model.hfield_adr[hf.id])
    model.hfield_data[adr:adr + n] = ((grid.z - z0) / model.hfield_size[hf.id, 2]).ravel()
    centre_f = np.array([(grid.x[0] + grid.x[-1]) / 2, (grid.y[0] + grid.y[-1]) / 2, z0])
    data.mocap_pos[model.body_mocapid[model.body("floor").id]] = mat_tf @ centre_f


def _scale_pan(body: mujoco.MjsBody, prefix: str, length: float) -> None:
    half = length / 2
    for geom in body.geoms:
        if geom.name in (f"{prefix}trough", f"{prefix}rack"):
            geom.size = [geom.size[0], half, geom.size[2]]
        elif "foot" in geom.name:
            sign = 1.0 if geom.pos[1] > 0 else -1.0
            geom.pos = [geom.pos[0], sign * (half - 0.075), geom.pos[2]]
    for site in body.sites:
        if site.name.endswith("rail_start"):
            site.pos = [0, -half, 0]
        elif site.name.endswith("rail_end"):
            site.pos = [0, half, 0]


def _scale_support(body: mujoco.MjsBody, prefix: str, pan_length: float) -> None:
    """A support's base and canopy 0.9 of a pan length wide (the gap between neighbours)."""
    half = 0.45 * pan_length
    _geom(body, f"{prefix}base").size = [1.5, half, 0.25]
    _geom(body.first_body(), f"{prefix}canopy").size = [2.0, half, 0.1]


def _geom(body: mujoco.MjsBody, name: str) -> mujoco.MjsGeom:
    return next(geom for geom in body.geoms if geom.name == name)


def _add_pans(spec: mujoco.MjSpec, scn: Scenario, quat_tf: np.ndarray, first: int, count: int, anchors: bool) -> None:
    """Pans first..first+count-1 and their connectors (twin.face.connectors); with `anchors`, the connectors to the
    mocap anchors standing in for the pans beyond a window."""
    bodies = {}
    for i in range(first, first + count):
        bodies[i] = spec.worldbody.add_frame(quat=quat_tf).attach_body(_piece_copy("pan").body("pan"), f"pan{i}_", "")
        _scale_pan(bodies[i], f"pan{i}_", scn.face.pan_length_m)
    add_connectors(spec, scn, bodies, anchors)


@dataclass(frozen=True)
class FaceIndex:
    """Addresses of a compiled face model's state, by pan and support (window-local order)."""

    pans: np.ndarray  # global pan indices in this model
    supports: np.ndarray  # global support indices in this model
    pan_qpos: np.ndarray  # (npan, 6) qpos addresses of x, y, z, yaw, pitch, roll
    pan_dof: np.ndarray  # (npan, 6)
    sup_qpos: np.ndarray  # (nsup, 2) qpos of x, leg
    sup_dof: np.ndarray  # (nsup, 2)
    ram_act: np.ndarray  # (nsup,) actuator ids of rams (integrated velocity; act = target length)
    leg_act: np.ndarray  # (nsup,) actuator ids of the legs (integrated velocity; act = the oil column's length)
    ram_tendon: np.ndarray  # (nsup,) tendon ids
    anchor_eq: np.ndarray  # (2,) equality ids of the head and tail anchors (-1 when at a face end)
    anchor_mocap: np.ndarray  # (2,) mocap ids of the anchors (-1 when at a face end)
    anchor_tendon: np.ndarray  # (2, 3) tendon ids of the anchor connectors' limits (CONNECTOR_KINDS; -1: none)
    connector_limit: np.ndarray  # (3,) a connector's half ranges [rad] (CONNECTOR_KINDS)
    coupler_jnt: np.ndarray  # (ncoupler,) slide joints of the connectors' couplers (none without axial play)
    coupler_qpos: np.ndarray  # (ncoupler,)
    coupler_pan: np.ndarray  # (ncoupler,) window pan whose tail end each sits at; count: the head coupler


def build_face_spec(scn: Scenario, band: FloorBand, first: int, count: int, anchors: bool) -> mujoco.MjSpec:
    """Spec of pans first..first+count-1 with their supports, rams, bend limits and a floor height field of the
    band's size (flat until placed: place_floor).

    With `anchors`, both ends are tied to mocap anchors (standing in for the neighbouring pans) whose
    equalities the caller deactivates at a face end; a window model is compiled once and moved along the
    face by setting its state and its supports' body positions.
    """
    f, sup = scn.face, scn.supports
    hyd = SupportHydraulics.from_scenario(sup, scn.roof)
    frame = FaceFrame(np.radians(f.azimuth_deg))
    mat_tf = frame.mat_tf
    quat_tf = mat_to_quat(mat_tf)
    spec = mujoco.MjSpec()
    spec.modelname = f"face_{first}_{first + count - 1}"
    spec.option.timestep = scn.rates.face_timestep_s
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.noslip_iterations = 0
    # Elliptic friction cones: MuJoCo's default pyramidal cone has its edges along the contact frame's tangents, which
    # follow the world axes, so a pan pushed along x_F at an azimuth off those axes slid sideways. On the default face
    # (azimuth 30 deg, flat seam, 4 mm axial play) the pans crept 28-52 mm a cycle towards the headgate whatever the
    # cutting direction (4 mm at azimuth 0 or 90); with elliptic cones, 3 mm, at the same speed.
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.compiler.degree = False
    _add_floor(spec, band, quat_tf)
    _add_pans(spec, scn, quat_tf, first, count, anchors)
    stations = support_stations(scn)
    for j in np.flatnonzero((stations >= first) & (stations < first + count)):
        i = stations[j]
        y_station = (i + 0.5) * f.pan_length_m
        _scale_support(spec.worldbody.add_frame(pos=mat_tf @ [0.0, y_station, 0.0], quat=quat_tf).attach_body(
            _piece_copy("support").body("support"), f"sup{j}_", ""), f"sup{j}_", f.pan_length_m)
        ram = spec.add_tendon(name=f"ram{j}")
        ram.wrap_site(f"sup{j}_ram")
        ram.wrap_site(f"pan{i}_ram")
        spec.add_actuator(name=f"ram{j}", target=f"ram{j}", trntype=mujoco.mjtTrn.mjTRN_TENDON,
                          dyntype=mujoco.mjtDyn.mjDYN_INTEGRATOR, gaintype=mujoco.mjtGain.mjGAIN_FIXED,
                          biastype=mujoco.mjtBias.mjBIAS_AFFINE, gainprm=[RAM_GAIN_N_M] + [0] * 9,
                          biasprm=[0, -RAM_GAIN_N_M, -RAM_DAMPING_N_S_M] + [0] * 7, actlimited=True,
                          actrange=[0.3, sup.ram_length_set_m + 2.0 * f.web_depth_m],
                          forcelimited=True, forcerange=[-hyd.ram.force_pull_n, hyd.ram.force_push_n],
                          ctrllimited=True, ctrlrange=[-20.0, 20.0])
        k_leg = hyd.legs.stiffness_n_m
        spec.add_actuator(name=f"leg{j}", target=f"sup{j}_leg", trntype=mujoco.mjtTrn.mjTRN_JOINT,
                          dyntype=mujoco.mjtDyn.mjDYN_INTEGRATOR, gaintype=mujoco.mjtGain.mjGAIN_FIXED,
                          biastype=mujoco.mjtBias.mjBIAS_AFFINE, gainprm=[k_leg] + [0] * 9,
                          biasprm=[0, -k_leg, -LEG_DAMPING_N_S_M] + [0] * 7, actlimited=True, actrange=[0.3, 7.5],
                          forcelimited=True,
                          forcerange=[-LEG_RETRACT_FRACTION * hyd.legs.force_set_n, hyd.legs.force_yield_n],
                          ctrllimited=True, ctrlrange=[-20.0, 20.0])
    return spec


def index_face_model(model: mujoco.MjModel, scn: Scenario, first: int, count: int) -> FaceIndex:
    pans = np.arange(first, first + count)
    stations = support_stations(scn)
    sups = np.flatnonzero((stations >= first) & (stations < first + count))

    def jnt(name: str) -> int:
        return model.joint(name).id

    pan_j = np.array([[jnt(f"pan{i}_{n}") for n in PAN_JOINTS] for i in pans])
    sup_j = np.array([[jnt(f"sup{j}_{n}") for n in ("x", "leg")] for j in sups]).reshape(-1, 2)
    anchor_eq, anchor_mocap = [], []
    coupler_jnt, coupler_pan = [], []
    for k, name in [*((k, f"pan{i}_play_end") for k, i in enumerate(pans)), (count, f"pan{first}_play_start")]:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if jid >= 0:
            coupler_jnt.append(jid)
            coupler_pan.append(k)
    for side in (0, 1):
        eq = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, f"anchor{side}")
        anchor_eq.append(eq)
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"anchor{side}")
        anchor_mocap.append(model.body_mocapid[body] if body >= 0 else -1)
    return FaceIndex(
        pans=pans, supports=sups,
        pan_qpos=model.jnt_qposadr[pan_j], pan_dof=model.jnt_dofadr[pan_j],
        sup_qpos=model.jnt_qposadr[sup_j], sup_dof=model.jnt_dofadr[sup_j],
        ram_act=np.array([model.actuator(f"ram{j}").id for j in sups], int),
        leg_act=np.array([model.actuator(f"leg{j}").id for j in sups], int),
        ram_tendon=np.array([model.tendon(f"ram{j}").id for j in sups], int),
        anchor_eq=np.array(anchor_eq), anchor_mocap=np.array(anchor_mocap),
        anchor_tendon=np.array([[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_TENDON, f"anchor{side}_{kind}")
                                 for kind in CONNECTOR_KINDS] for side in (0, 1)]),
        connector_limit=connector_limits_rad(scn),
        coupler_jnt=np.array(coupler_jnt, int), coupler_qpos=model.jnt_qposadr[np.array(coupler_jnt, int)],
        coupler_pan=np.array(coupler_pan, int),
    )


def build_ride_spec(scn: Scenario) -> mujoco.MjSpec:
    """The shearer on its suspension: free body welded softly to the mocap target `ride`.

    The weld's solref makes the ride's steps sample the scenario's suspension (twin.face.suspension).
    """
    sh = scn.shearer
    spec = _piece_copy("shearer")
    spec.modelname = "shearer_ride"
    dt = 1.0 / scn.rates.ride_hz
    spec.option.timestep = dt
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.equality("suspension").solref = weld_solref(sh.suspension_frequency_hz, sh.suspension_damping_ratio, dt)
    body = spec.body("shearer")
    half = sh.length_m / 2
    _geom(body, "body").size = [0.6, half - 1.0, 0.5]
    for geom in body.geoms:  # the drums' hubs 0.4 m in from the machine's ends, the arms reaching to them
        inset = {"drum": 0.4, "arm_": 0.9}.get(geom.name[:4])
        if inset is not None:
            geom.pos = [geom.pos[0], np.sign(geom.pos[1]) * (half - inset), geom.pos[2]]
    for site in body.sites:
        if site.name.startswith("shoe"):
            site.pos = [0.0, np.sign(site.pos[1]) * sh.shoe_spacing_m / 2, -sh.body_height_m]
    return spec


def piece_model(scn: Scenario, name: str) -> mujoco.MjModel:
    """The MJCF piece `name` ("pan", "support" or "shearer") alone, sized for the scenario as the face and ride models
    use it, compiled: its bodies' geoms in their body frames (for drawing: twin.view.geometry)."""
    if name == "shearer":
        return build_ride_spec(scn).compile()
    spec = _piece_copy(name)
    if name == "pan":
        _scale_pan(spec.body("pan"), "", scn.face.pan_length_m)
    elif name == "support":
        _scale_support(spec.body("support"), "", scn.face.pan_length_m)
    else:
        raise ValueError(f"piece_model: no MJCF piece '{name}' (pan, support, shearer)")
    return spec.compile()
