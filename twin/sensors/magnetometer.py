"""The shearer's three-axis magnetometer: the geomagnetic field at the site and the MAG stream.

Earth field
-----------
The World Magnetic Model (pygeomag, the WMM release covering the scenario's `sensors.mag.date`) is evaluated
once per run, at the scenario's reference point (site latitude, longitude, ellipsoidal height). The face and
its panel span well under 1 km, over which the WMM field changes by a few nT (declination by < 0.01 deg),
far below the magnetometer noise, so one evaluation serves every sample; the field vector is the same in the
local-level frame n wherever the shearer is.

Sensor model
------------
At each magnetometer sample time t_k (k / rate, inside the truth's time span)

    b_b = S (C_b^n)^T B_n + h + k(t) d + sum_f [t_start_f <= t < t_end_f] B_f u_f + v,

with S the soft-iron matrix, h the hard-iron offset, d the motor field of `sensors.mag.motor_disturbance_t`,
k(t) = |v_n| / cutting speed while the haulage phase is not "stopped" (0 while stopped, so the ride's
sub-mm/s suspension jitter at standstill leaves no field), B_f u_f the field of a `mag_interference` fault
(magnitude `value` [T], a direction u_f drawn uniformly on the sphere per fault, fixed in b) and v white
noise of standard deviation `noise_t` per axis. The motor and interference fields are external to the
soft-iron distortion of the Earth field and are added after it.

Sampling the truth: the attitude and velocity at t_k are linearly interpolated between the two neighbouring
truth samples (the quaternion by normalised linear interpolation, sign-aligned); the phase is that of the
truth sample at or before t_k. At the default rates (truth 200 Hz, magnetometer 50 Hz, or any rate dividing
the truth rate) the sample times coincide with truth samples and the truth is taken exactly; otherwise the
interpolation error over 5 ms is far below the noise (the shearer turns at < 1 deg/s).

Fault targets: a `mag_interference` fault without a target acts on this magnetometer; one with a target
support acts on that support's canopy unit instead (twin.sensors.support_imu).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from estimators.nav.geomagnetic import (
    GeomagneticReference,
    geomagnetic_reference,
    tilt_compensated_yaw,
)
from estimators.nav.rotations import quat_conj, quat_rotate
from twin.config.scenario import Scenario
from twin.config.sensors import Fault
from twin.face.haulage import STOPPED
from twin.sensors.chunks import TruthChunk, halo_rows, split_truth
from twin.sensors.faults import faults_of, window_mask


class FieldElements(NamedTuple):
    """Geomagnetic field elements at a point (for reports and for the heading's declination)."""

    declination: float
    """Angle of magnetic north from true north [rad], positive east (clockwise seen from above)."""
    inclination: float
    """Dip of the field below the horizontal [rad], positive downwards."""
    intensity: float
    """Total field strength [T]."""


def _reference(lat_deg: float, lon_deg: float, height_m: float, date: str) -> GeomagneticReference:
    """The WMM field at a point through estimators.nav.geomagnetic (one model for the twin and the estimators)."""
    return geomagnetic_reference(np.radians(float(lat_deg)), np.radians(float(lon_deg)), float(height_m), date)


def field_elements(lat_deg: float, lon_deg: float, height_m: float, date: str) -> FieldElements:
    """Declination, inclination [rad] and total intensity [T] of the WMM field at a point and date.

    `height_m` is the ellipsoidal height (WMM altitudes refer to the WGS-84 ellipsoid); `date` is "YYYY-MM-DD".
    """
    ref = _reference(lat_deg, lon_deg, height_m, date)
    return FieldElements(ref.declination, ref.inclination, ref.intensity)


def earth_field_n(lat_deg: float, lon_deg: float, height_m: float, date: str) -> np.ndarray:
    """The WMM geomagnetic field in the local-level frame n (East, North, Up) [T], shape (3,)."""
    return _reference(lat_deg, lon_deg, height_m, date).field_n.copy()


def site_field_n(scn: Scenario) -> np.ndarray:
    """The run's Earth field in n [T]: the WMM at the scenario's reference point on `sensors.mag.date`."""
    return earth_field_n(scn.site.lat_deg, scn.site.lon_deg, scn.site.height_m, scn.sensors.mag.date)


def site_field_elements(scn: Scenario) -> FieldElements:
    """Field elements at the scenario's reference point on `sensors.mag.date` (for reports)."""
    return field_elements(scn.site.lat_deg, scn.site.lon_deg, scn.site.height_m, scn.sensors.mag.date)


def bracket(t_truth: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indices (i0, i1) of the truth samples around each t and the weight w of i1 (0 at coinciding times)."""
    n = t_truth.size
    i0 = np.clip(np.searchsorted(t_truth, t, side="right") - 1, 0, n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    dt = t_truth[i1] - t_truth[i0]
    w = np.divide(t - t_truth[i0], dt, out=np.zeros_like(t), where=dt > 0)
    return i0, i1, np.clip(w, 0.0, 1.0)


def _interp_columns(truth: dict, names: Iterable[str], i0, i1, w) -> np.ndarray:
    """Columns linearly interpolated at the bracketed times, stacked (K, len(names))."""
    out = np.stack([np.asarray(truth[c], float)[i0] for c in names], axis=-1)
    moving = w > 0
    if moving.any():
        nxt = np.stack([np.asarray(truth[c], float)[i1[moving]] for c in names], axis=-1)
        out[moving] += w[moving, None] * (nxt - out[moving])
    return out


def shearer_attitude_at(shearer: dict, t: np.ndarray) -> np.ndarray:
    """q_nb (K, 4) at times t from the truth: exact at truth samples, else normalised lerp of neighbours."""
    t_truth = np.asarray(shearer["t"], float)
    i0, i1, w = bracket(t_truth, t)
    names = ("q_nb_w", "q_nb_x", "q_nb_y", "q_nb_z")
    q = np.stack([np.asarray(shearer[c], float)[i0] for c in names], axis=-1)
    moving = w > 0
    if moving.any():
        q1 = np.stack([np.asarray(shearer[c], float)[i1[moving]] for c in names], axis=-1)
        q0 = q[moving]
        q1 = np.where(np.sum(q0 * q1, axis=-1, keepdims=True) < 0, -q1, q1)
        qm = q0 + w[moving, None] * (q1 - q0)
        q[moving] = qm / np.linalg.norm(qm, axis=-1, keepdims=True)
    return q


def motor_factor(scn: Scenario, shearer: dict, t: np.ndarray) -> np.ndarray:
    """k(t): ground speed / cutting speed while the haulage phase is not stopped, else 0."""
    t_truth = np.asarray(shearer["t"], float)
    i0, i1, w = bracket(t_truth, t)
    v_n = _interp_columns(shearer, ("v_n_e", "v_n_n", "v_n_u"), i0, i1, w)
    v_cut = scn.haulage.cutting_speed_m_min / 60.0
    moving = np.asarray(shearer["phase"])[i0] != STOPPED
    return np.where(moving, np.linalg.norm(v_n, axis=-1) / v_cut, 0.0)


def interference_directions(faults: Iterable[Fault], rng: np.random.Generator,
                            target: int | None = None) -> list[tuple[Fault, np.ndarray]]:
    """The `mag_interference` faults with this target, each (in schedule order) with its field direction u_f (3,)
    in b, drawn uniformly on the sphere from `rng` whether or not its window meets the run."""
    out = []
    for fault in faults_of(faults, "mag_interference"):
        if fault.target == target:
            u = rng.normal(size=3)
            out.append((fault, u / np.linalg.norm(u)))
    return out


def interference_field(t: np.ndarray, directions: list[tuple[Fault, np.ndarray]]) -> np.ndarray:
    """Sum (K, 3) [T] in b of the fault fields B_f u_f whose windows hold the times t (`interference_directions`)."""
    out = np.zeros((t.size, 3))
    for fault, u in directions:
        out[window_mask(t, fault)] += fault.value * u
    return out


def soft_iron_rows(b: np.ndarray, soft_iron: np.ndarray) -> np.ndarray:
    """S b for each row b of (K, 3), i.e. b @ S^T, rounded alike in every row whatever K: NumPy hands a lone row to
    a vector kernel that rounds differently from the matrix kernel, so a lone row is multiplied beside a copy."""
    if len(b) == 1:
        return (np.concatenate([b, b]) @ soft_iron.T)[:1]
    return b @ soft_iron.T


class Magnetometer:
    """The MAG stream (estimators.io.logformat.MAG) of the shearer magnetometer, one TruthChunk at a time
    (twin.sensors.chunks); `faults` defaults to the scenario's schedule.

    Random draws: the white noise from `rng` in sample order (each chunk draws its samples' (n, 3) next, the
    values one draw over the run gives); one direction per untargeted `mag_interference` fault from the child
    generator rng.spawn(1)[0], drawn at construction. Spawning does not advance `rng`, so the faults leave the
    noise as it is and a fault changes the stream only inside its window; `rng` must carry its SeedSequence (as
    default_rng(seed) does). (Before the stream was drawn in chunks the directions came from `rng` after the
    noise: the noise is the same as then, the directions are not.)"""

    def __init__(self, scn: Scenario, rng: np.random.Generator, faults: Iterable[Fault] | None = None):
        self.scn = scn
        self.cfg = scn.sensors.mag
        self.field_n = site_field_n(scn)
        self.rng = rng
        self.interference = interference_directions(scn.faults if faults is None else faults, rng.spawn(1)[0])

    def step(self, chunk: TruthChunk) -> dict[str, np.ndarray]:
        """The readings the chunk owns, b_x, b_y, b_z [T] in b; the truth columns t, q_nb_*, v_n_*, phase are read."""
        cfg = self.cfg
        shearer, _ = chunk.padded()
        t = chunk.clock(cfg.rate_hz)
        q_nb = shearer_attitude_at(shearer, t)
        b_b = soft_iron_rows(quat_rotate(quat_conj(q_nb), self.field_n), np.asarray(cfg.soft_iron, float))
        b_b += np.asarray(cfg.hard_iron_t, float)
        if any(cfg.motor_disturbance_t):
            b_b += motor_factor(self.scn, shearer, t)[:, None] * np.asarray(cfg.motor_disturbance_t, float)
        if cfg.noise_t > 0:
            b_b += self.rng.normal(0.0, cfg.noise_t, b_b.shape)
        b_b += interference_field(t, self.interference)
        return {"t": t, "b_x": b_b[:, 0], "b_y": b_b[:, 1], "b_z": b_b[:, 2]}


def mag_stream(scn: Scenario, shearer: dict, rng: np.random.Generator,
               faults: Iterable[Fault] | None = None) -> dict[str, np.ndarray]:
    """The MAG stream of a whole run: the Magnetometer over the truth_shearer columns in one chunk."""
    return Magnetometer(scn, rng, faults).step(next(split_truth(shearer, [], halo_rows(scn))))


tilt_compensated_heading = tilt_compensated_yaw
"""Yaw from a magnetometer reading and tilt (002 eqs. 3-6): estimators.nav.geomagnetic.tilt_compensated_yaw."""
