"""Face layout: the face frame, the floor and the roof, pan geometry and the initial chain of pans.

Face frame F: origin at the headgate end of the first pan's running line at the start (the scenario's
reference point, so F and the MuJoCo world t share their origin), x towards the coal wall (advance), y along
the face towards the tailgate, z up. F is the world ENU tangent plane t turned about z so that y points along
the scenario's face azimuth. A pan's state is (x, y, z, yaw, pitch, roll) in F: the centre of its running
line and the Euler angles yaw about z, pitch about x (vertical bend), roll about y (cross slope), applied in
that order (C = Rz Rx Ry, as DESIGN's body convention).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from estimators.nav.rotations import euler_to_mat

if TYPE_CHECKING:
    from twin.config.scenario import Scenario

# Pan state columns (face frame F).
PX, PY, PZ, YAW, PITCH, ROLL = range(6)

PAN_WIDTH_M = 1.0
"""Width of a pan across the face (x), including the coal-side rack; the running line is its centre."""
PAN_HEIGHT_M = 0.35
"""Height of the running line above the floor (pan feet to rail top)."""
INITIAL_BEND_FRACTION = 0.25
"""Share of the horizontal bend limit the random initial face may use (the snake has the rest)."""
MESH_MAX_CELLS = 250_000
"""Most cells of the floor mesh a recording draws (coarser than the height field on a long run's face)."""
SUPPORT_BASE_LENGTH_M = 3.0
"""Length of a support base from its ram connection (front) to its rear; x extent in F."""


@dataclass(frozen=True)
class FaceFrame:
    """Rotation between the face frame F and the tangent plane t (same origin)."""

    azimuth_rad: float

    @property
    def mat_tf(self) -> np.ndarray:
        """C_f^t: F components to t (ENU) components. F's y axis points along the azimuth."""
        a = self.azimuth_rad
        x_t = np.array([np.cos(a), -np.sin(a), 0.0])  # azimuth + 90 deg clockwise from north
        y_t = np.array([np.sin(a), np.cos(a), 0.0])
        return np.column_stack([x_t, y_t, [0.0, 0.0, 1.0]])

    @property
    def yaw_tf(self) -> float:
        """Yaw (about z, counter-clockwise) of F in t."""
        return -self.azimuth_rad


UNDULATION_SHARES = (0.6, 0.3, 0.1)
"""Amplitude shares of the three along-face undulation sinusoids."""
UNDULATION_WAVELENGTHS = (1.0, 0.62, 0.38)
"""Their wavelengths relative to the scenario's undulation wavelength."""


def floor_pitch_change(amplitude_m: float, wavelength_m: float, pan_length_m: float) -> float:
    """Upper bound of the floor's slope change over one pan [rad]: amplitude x curvature bound x pan length."""
    curvature = amplitude_m * sum(w * (2 * np.pi / (r * wavelength_m)) ** 2
                                  for w, r in zip(UNDULATION_SHARES, UNDULATION_WAVELENGTHS))
    return curvature * pan_length_m


@dataclass(frozen=True)
class Floor:
    """Floor height z(x, y) in F: seam dip along the face, dip in the advance direction, and undulation.

    The undulation is a sum of three along-face sinusoids (wavelengths 1, 0.62 and 0.38 times the nominal,
    seeded phases) whose amplitudes add to `amplitude`, modulated slowly in the advance direction.
    """

    dip_y: float
    dip_x: float
    amplitude: float
    wavelengths: tuple[float, float, float]
    weights: tuple[float, float, float]
    phases: tuple[float, float, float]
    advance_wavelength: float
    advance_phase: float

    @classmethod
    def from_scenario(cls, scn: Scenario, rng: np.random.Generator) -> "Floor":
        f = scn.face
        lam = f.undulation_wavelength_m
        phases = tuple(float(p) for p in rng.uniform(0, 2 * np.pi, 3))
        return cls(
            dip_y=float(np.tan(np.radians(f.seam_dip_deg))),
            dip_x=float(np.tan(np.radians(f.advance_dip_deg))),
            amplitude=f.undulation_amplitude_m,
            wavelengths=tuple(r * lam for r in UNDULATION_WAVELENGTHS),
            weights=UNDULATION_SHARES,
            phases=phases,
            advance_wavelength=4.0 * lam,
            advance_phase=float(rng.uniform(0, 2 * np.pi)),
        )

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x, y = np.asarray(x, float), np.asarray(y, float)
        und = sum(w * np.sin(2 * np.pi * y / lam + ph)
                  for w, lam, ph in zip(self.weights, self.wavelengths, self.phases))
        modulation = 1.0 + 0.3 * np.sin(2 * np.pi * x / self.advance_wavelength + self.advance_phase)
        return self.dip_y * y + self.dip_x * x + self.amplitude * und * modulation / 1.3



ROOF_SEED_STREAM = 26
"""The roof's random phase comes from its own stream of the scenario's seed (twin.face.drift's stop errors have 25),
so that adding the roof left every other draw of a run unchanged."""


@dataclass(frozen=True)
class Roof:
    """Roof height z(x, y) in F, before convergence: the floor's height plus the mining height, with an undulation of
    its own (the seam's thickness varying) along the face and, slower, in the advance direction."""

    floor: Floor
    mining_height: float
    amplitude: float
    wavelength: float
    phase: float

    @classmethod
    def from_scenario(cls, scn: Scenario, floor: Floor) -> "Roof":
        r = scn.roof
        phase = float(np.random.default_rng([scn.seed, ROOF_SEED_STREAM]).uniform(0, 2 * np.pi))
        return cls(floor, r.mining_height_m, r.undulation_amplitude_m, r.undulation_wavelength_m, phase)

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        x, y = np.asarray(x, float), np.asarray(y, float)
        return (self.floor.height(x, y) + self.mining_height
                + self.amplitude * np.sin(2 * np.pi * (y + 0.3 * x) / self.wavelength + self.phase))


def pan_axes(states: np.ndarray) -> np.ndarray:
    """Rotation matrices C_p^F (..., 3, 3) of pans from their states (..., 6)."""
    return euler_to_mat(states[..., PITCH], states[..., ROLL], states[..., YAW])



def joint_ends(states: np.ndarray, pan_length: float) -> tuple[np.ndarray, np.ndarray]:
    """Headgate-side and tailgate-side end points of every pan's running line in F, each (N, 3)."""
    axis_y = pan_axes(states)[:, :, 1]
    half = 0.5 * pan_length * axis_y
    return states[:, :3] - half, states[:, :3] + half


def bend_angles(states: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal and vertical bend from each pan to the next (N-1,), rad: yaw and pitch differences."""
    return np.diff(states[:, YAW]), np.diff(states[:, PITCH])


def initial_yaws(scn: Scenario, rng: np.random.Generator) -> np.ndarray:
    """Pan yaws from the scenario's bend list, or a smooth seeded random line within the bend limit."""
    f = scn.face
    limit = np.radians(f.bend_limit_horizontal_deg)
    if isinstance(f.initial_bend_horizontal_deg, list):
        bends = np.radians(np.asarray(f.initial_bend_horizontal_deg, float))
    else:
        # AR(1) yaw along the face (correlation 0.9 per pan), bends clipped to their share of the limit.
        sigma = np.radians(f.initial_straightness_deg)
        eps = rng.normal(0.0, sigma * np.sqrt(1 - 0.9 ** 2), f.pan_count)
        yaw = np.empty(f.pan_count)
        yaw[0] = rng.normal(0.0, sigma)
        for i in range(1, f.pan_count):
            yaw[i] = 0.9 * yaw[i - 1] + eps[i]
        bends = np.clip(np.diff(yaw), -INITIAL_BEND_FRACTION * limit, INITIAL_BEND_FRACTION * limit)
    yaw = np.concatenate([[0.0], np.cumsum(bends)])
    return yaw - yaw.mean()


def running_line_height(floor: Floor, x: float, y: float, eps: float = 0.05) -> float:
    """Height of a pan's running line above the floor at (x, y): PAN_HEIGHT_M along the floor's normal (a pan stands
    square on its floor), so 1 / cos(tilt) times it vertically: 22 mm more on a 20 deg dip than on the flat. Laid
    PAN_HEIGHT_M plumb above a steep floor, the chain stood in it, and the mocap anchors of the first windows, at the
    unsettled neighbours, held the edge pans down into it and buckled them up (a 3 deg vertical bend at 10 deg)."""
    sx = (floor.height(x + eps, y) - floor.height(x - eps, y)) / (2 * eps)
    sy = (floor.height(x, y + eps) - floor.height(x, y - eps)) / (2 * eps)
    return PAN_HEIGHT_M * float(np.sqrt(1.0 + sx * sx + sy * sy))


def initial_pans(scn: Scenario, floor: Floor, rng: np.random.Generator) -> np.ndarray:
    """Initial pan states (N, 6) in F: a chain from the origin laid on the floor.

    Each pan's pitch puts its tailgate end on the floor (three fixed-point passes; the running line
    running_line_height above it); roll follows the floor's cross slope at the pan centre. MuJoCo settles the chain further before the first cut.
    """
    f = scn.face
    n, length = f.pan_count, f.pan_length_m
    yaw = initial_yaws(scn, rng)
    states = np.zeros((n, 6))
    states[:, YAW] = yaw
    joint = np.array([0.0, 0.0, floor.height(0.0, 0.0) + running_line_height(floor, 0.0, 0.0)])
    for i in range(n):
        pitch = 0.0
        for _ in range(3):
            d = np.array([-np.sin(yaw[i]) * np.cos(pitch), np.cos(yaw[i]) * np.cos(pitch), np.sin(pitch)])
            end = joint + length * d
            rise = floor.height(end[0], end[1]) + running_line_height(floor, end[0], end[1]) - joint[2]
            pitch = np.arcsin(np.clip(rise / length, -1, 1))
        d = np.array([-np.sin(yaw[i]) * np.cos(pitch), np.cos(yaw[i]) * np.cos(pitch), np.sin(pitch)])
        centre = joint + 0.5 * length * d
        eps = 0.05
        slope_x = (floor.height(centre[0] + eps, centre[1]) - floor.height(centre[0] - eps, centre[1])) / (2 * eps)
        states[i] = [*centre, yaw[i], pitch, -np.arctan(slope_x)]
        joint = joint + length * d
    return states


def support_stations(scn: Scenario) -> np.ndarray:
    """Pan index each support pushes: one support per `pans_per_support` pans, centred in its group."""
    k = scn.supports.pans_per_support
    return np.arange(k // 2, scn.face.pan_count, k)
