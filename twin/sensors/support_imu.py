"""9-axis MEMS units on support canopies (002 section 2): the SUPPORT_IMU stream from the support truth.

The truth of a support is a row whenever its state changes (estimators.io.logformat.TRUTH_SUPPORTS). The canopy
motion these units feel is derived from those rows as follows.

Canopy attitude (frame c: x towards the coal wall, y along the face towards the tailgate, z up)
    C_c^t = Rz(yaw_face) Rx(slope) Ry(tilt): the canopy is aligned with the face (yaw of the face frame, from
    `face.azimuth_deg`), inclined along the face as the floor at its initial station (slope = atan(dz / dy)
    between the initial bases of its neighbours in the face frame, positive rising towards the tailgate as
    `face.seam_dip_deg`; zero without neighbours), and tilted fore-aft by the floor under its base. The fore-aft
    tilt (the paper's canopy "pitch"; a rotation about the canopy y axis, i.e. the project's roll angle) at a
    row is -atan(du / dx): du the rise of the base p_t_u and dx the advance since the last row at least
    TILT_CHORD_M further back; negative when the floor rises towards the coal wall (as the pans' roll in
    twin.face.layout). Rows before the first such chord take the first chord's tilt (the support stood on that
    floor); a support that never advances that far stays level.

Motion between rows
    Every quantity (base position p_t, canopy height, tilt) moves from one row's value to the next row's over
    the interval between the rows with the quintic smooth step S(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 (zero
    rate and acceleration at both ends). A support is static while set: its values do not change between set
    rows. An advance is a set = 0 row (old position, the legs' valves opening with the canopy still at the roof;
    later set = 0 rows of the same advance are left out) followed by the next set row (new position): the unit moves
    forward by the advance over that interval, and the canopy drops by `supports.lower_m` and rises again with the
    bump 64 tau^3 (1 - tau)^3.
    The unit sits on the canopy at the canopy height above the base reference point, so its position is
    p = p_base + C_c^t [0, 0, h].

Sensor outputs (all in c, at `sensors.support_imu.rate_hz` over the shearer truth's time span)
    gyro  = [0, d tilt/dt, 0] + C_t^c w_ie^t                                 (w_ib^c)
    accel = C_t^c (a_t + 2 w_ie^t x v_t) - C_n^c g^n                          (specific force, as twin.face.truth)
    mag   = C_n^c B^n + disturbance + noise
with w_ie^t the Earth rate in the tangent plane t (earth.earth_rate_n at the reference latitude, t being
Earth-fixed and level there), n and g^n (earth.gravity_n) taken at the support's initial station, and B^n
the run's WMM field (twin.sensors.magnetometer.site_field_n). The shearer disturbs the canopy magnetometer while it
passes: a field of peak `shearer_disturbance_t` in a fixed random direction per unit (drawn once, in c),
scaled by (1 - (d / R)^2)^3 for |d| < R = DISTURBANCE_RANGE_PANS pan lengths (zero beyond), d the along-face
distance between the shearer's arc length s and the support's station centre. A `mag_interference` fault
whose target is an instrumented support adds its field (magnitude `value`, random fixed direction) to that
unit inside its window; untargeted ones act on the shearer magnetometer (twin.sensors.magnetometer).

Inertial errors: the preset of `sensors.support_imu.grade` (twin.config.imu_grades) applied by the same error model
as the shearer IMU (twin.sensors.imu_errors.apply_imu_errors: turn-on bias, Gauss-Markov in-run bias, scale and
non-orthogonality, white noise, range), on the increments rate * dt of each sample interval, divided back by
dt; so the white noise has the per-sample standard deviation ARW sqrt(rate) [rad/s] and VRW sqrt(rate)
[m/s^2]. The grade presets carry no magnetometer figures, so the canopy magnetometer's white noise is
`sensors.mag.noise_t` (as the shearer's).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from estimators.nav import earth
from estimators.nav.rotations import quat_conj, quat_mul, quat_rotate
from twin.config.imu_grades import grade
from twin.config.scenario import Scenario
from twin.config.sensors import Fault
from twin.face.layout import FaceFrame, support_stations
from twin.sensors.clock import sample_times
from twin.sensors.faults import faults_of, window_mask
from twin.sensors.imu_errors import apply_imu_errors
from twin.sensors.magnetometer import site_field_n

TILT_CHORD_M = 0.3
"""Shortest advance over which the base's rise gives the fore-aft tilt of the floor [m]."""
DISTURBANCE_RANGE_PANS = 3.0
"""The shearer's field at a canopy unit falls to zero this many pan lengths away along the face."""

COLUMNS = ("t", "support", "gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z", "mag_x", "mag_y",
           "mag_z")


def smooth_step(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """S, dS/dtau, d2S/dtau2 of the quintic smooth step 10 tau^3 - 15 tau^4 + 6 tau^5."""
    return (tau ** 3 * (10 - 15 * tau + 6 * tau ** 2), 30 * tau ** 2 * (1 - tau) ** 2,
            60 * tau * (1 - tau) * (1 - 2 * tau))


def lowering_bump(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """B, dB/dtau, d2B/dtau2 of the bump 64 tau^3 (1 - tau)^3 (1 at tau = 1/2, flat to 2nd order at 0, 1)."""
    u = 1 - tau
    return (64 * tau ** 3 * u ** 3, 192 * tau ** 2 * u ** 2 * (1 - 2 * tau),
            384 * tau * u * ((1 - 2 * tau) ** 2 - tau * u))


@dataclass(frozen=True)
class CanopyRows:
    """One support's truth rows, with the derived canopy set height and fore-aft tilt per row."""

    t: np.ndarray  # (m,)
    p_t: np.ndarray  # (m, 3) base reference point in t
    height: np.ndarray  # (m,) canopy height when set [m]
    tilt: np.ndarray  # (m,) fore-aft tilt about the canopy y axis [rad]
    lowered: np.ndarray  # (m,) bool: the row starts an advance (set = 0)
    slope: float  # along-face inclination about the canopy x axis [rad]


def along_face_slope(scn: Scenario, supports: dict, support: int) -> float:
    """Inclination [rad] of the floor along the face at a support's initial station: atan(dz / dy) in the face
    frame from the first row of its headgate-side neighbour to that of its tailgate-side one (itself where one
    is missing); 0 without neighbours."""
    ids, t = np.asarray(supports["support"]), np.asarray(supports["t"], float)
    p_t = np.column_stack([np.asarray(supports[f"p_t_{a}"], float) for a in "enu"])

    def first_base(j: int) -> np.ndarray | None:
        sel = np.flatnonzero(ids == j)
        return p_t[sel[np.argmin(t[sel])]] if sel.size else None

    lo, hi = first_base(support - 1), first_base(support + 1)
    if lo is None and hi is None:
        return 0.0
    own = first_base(support)
    d_f = FaceFrame(np.radians(scn.face.azimuth_deg)).mat_tf.T @ ((own if hi is None else hi) - (own if lo is None else lo))
    return float(np.arctan2(d_f[2], d_f[1]))


def canopy_rows(scn: Scenario, supports: dict, support: int) -> CanopyRows:
    """The rows of one support from the truth_supports columns, with height and tilt per row and its slope."""
    sel = np.flatnonzero(np.asarray(supports["support"]) == support)
    if sel.size == 0:
        raise ValueError(f"truth_supports has no rows for support {support}")
    sel = sel[np.argsort(np.asarray(supports["t"], float)[sel], kind="stable")]
    # One advance is one lowered row: the later rows of a run of lowered ones (the ram moving) are dropped.
    lowered = np.asarray(supports["set"])[sel] == 0
    sel = sel[~(lowered & np.r_[False, lowered[:-1]])]
    t = np.asarray(supports["t"], float)[sel]
    p_t = np.column_stack([np.asarray(supports[f"p_t_{a}"], float)[sel] for a in "enu"])
    lowered = np.asarray(supports["set"])[sel] == 0
    height = np.asarray(supports["canopy"], float)[sel]
    adv = np.asarray(supports["advance"], float)[sel]
    reach = np.maximum.accumulate(adv)
    anchor = np.searchsorted(reach, adv - TILT_CHORD_M, side="right") - 1
    has = anchor >= 0
    tilt = np.zeros(t.size)
    if has.any():
        a = anchor[has]
        tilt[has] = -np.arctan2(p_t[has, 2] - p_t[a, 2], adv[has] - adv[a])
        # Rows without a chord of their own keep the last tilt before them (the first one's, at the start).
        last = np.maximum.accumulate(np.where(has, np.arange(t.size), -1))
        tilt = tilt[np.where(last >= 0, last, np.argmax(has))]
    return CanopyRows(t, p_t, height, tilt, lowered, along_face_slope(scn, supports, support))


@dataclass(frozen=True)
class CanopyMotion:
    """A canopy unit's kinematics at sample times: attitude in t, tilt rate, position and derivatives in t."""

    q_tc: np.ndarray  # (K, 4)
    tilt_rate: np.ndarray  # (K,)
    p_t: np.ndarray  # (K, 3)
    v_t: np.ndarray  # (K, 3)
    a_t: np.ndarray  # (K, 3)


def canopy_motion(scn: Scenario, rows: CanopyRows, t: np.ndarray) -> CanopyMotion:
    """The unit's attitude, tilt rate, position, velocity and acceleration at times t (module docstring).

    Only the samples inside a segment in which something changes are blended; elsewhere (a set support, most
    of the time) the unit rests at its row's values.
    """
    t = np.asarray(t, float)
    m = rows.t.size
    i = np.clip(np.searchsorted(rows.t, t, side="right") - 1, 0, m - 1)
    k = np.arange(m - 1)
    changes = np.zeros(m, bool)  # segment from row k to k + 1 moves something
    changes[:-1] = (np.any(rows.p_t[k + 1] != rows.p_t[k], axis=1) | (rows.height[k + 1] != rows.height[k])
                    | (rows.tilt[k + 1] != rows.tilt[k]) | rows.lowered[k])
    changes[:-1] &= rows.t[k + 1] > rows.t[k]
    act = np.flatnonzero(changes[i] & (t > rows.t[i]))

    th, h = rows.tilt[i], rows.height[i]
    base = rows.p_t[i]
    th_v = np.zeros_like(t)
    # Kinematics in the canopy's slope frame (the face frame turned by Rx(slope): x advance, y along the canopy)
    # on the active samples: the unit sits at base + Ry(tilt) [0, 0, h] there.
    v_f, a_f = np.zeros((t.size, 3)), np.zeros((t.size, 3))
    if act.size:
        ia = i[act]
        span = rows.t[ia + 1] - rows.t[ia]
        tau, inv = ((t[act] - rows.t[ia]) / span).clip(0.0, 1.0), 1.0 / span
        s, ds, dds = smooth_step(tau)

        def blend(v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            """Value, rate, acceleration of a per-row quantity (m,) or (m, 3) blended from row ia to ia + 1."""
            step = v[ia + 1] - v[ia]
            if v.ndim == 2:
                return v[ia] + s[:, None] * step, (ds * inv)[:, None] * step, (dds * inv ** 2)[:, None] * step
            return v[ia] + s * step, ds * inv * step, dds * inv ** 2 * step

        base_a_t = blend(rows.p_t)
        ha, ha_v, ha_a = blend(rows.height)
        tha, tha_v, tha_a = blend(rows.tilt)
        drop = np.where(rows.lowered[ia], scn.supports.lower_m, 0.0)
        b, db, ddb = lowering_bump(tau)
        ha, ha_v, ha_a = ha - drop * b, ha_v - drop * db * inv, ha_a - drop * ddb * inv ** 2
        st, ct = np.sin(tha), np.cos(tha)
        v_f[act, 0] = ha_v * st + ha * ct * tha_v
        v_f[act, 2] = ha_v * ct - ha * st * tha_v
        a_f[act, 0] = ha_a * st + 2 * ha_v * ct * tha_v - ha * st * tha_v ** 2 + ha * ct * tha_a
        a_f[act, 2] = ha_a * ct - 2 * ha_v * st * tha_v - ha * ct * tha_v ** 2 - ha * st * tha_a
        th, h, base = th.copy(), h.copy(), base.copy()
        th[act], h[act], th_v[act], base[act] = tha, ha, tha_v, base_a_t[0]
    frame = FaceFrame(np.radians(scn.face.azimuth_deg))
    # The lever arm and its derivatives above were in the canopy's slope frame Rx(slope): to t.
    cs, ss = np.cos(rows.slope), np.sin(rows.slope)
    mat_ts = frame.mat_tf @ np.array([[1.0, 0.0, 0.0], [0.0, cs, -ss], [0.0, ss, cs]])
    zero = np.zeros_like(t)
    p_t = base + np.stack([h * np.sin(th), zero, h * np.cos(th)], axis=-1) @ mat_ts.T
    v_t, a_t = v_f @ mat_ts.T, a_f @ mat_ts.T
    if act.size:
        v_t[act] += base_a_t[1]
        a_t[act] += base_a_t[2]
    q_ts = quat_mul(np.array([np.cos(frame.yaw_tf / 2), 0.0, 0.0, np.sin(frame.yaw_tf / 2)]),
                    np.array([np.cos(rows.slope / 2), np.sin(rows.slope / 2), 0.0, 0.0]))
    q_y = np.stack([np.cos(th / 2), zero, np.sin(th / 2), zero], axis=-1)
    return CanopyMotion(quat_mul(np.broadcast_to(q_ts, q_y.shape), q_y), th_v, p_t, v_t, a_t)


def canopy_attitude_n(scn: Scenario, supports: dict, support: int, t: np.ndarray) -> np.ndarray:
    """True canopy attitude q_nc (K, 4) of a support at times t (n at the support's initial station)."""
    rows = canopy_rows(scn, supports, support)
    q_nt = _station_q_nt(scn, rows)[0]
    q_tc = canopy_motion(scn, rows, np.asarray(t, float)).q_tc
    return quat_mul(np.broadcast_to(q_nt, q_tc.shape), q_tc)


def _station_q_nt(scn: Scenario, rows: CanopyRows) -> tuple[np.ndarray, float, float]:
    """q_nt at the support's initial station, and the station's latitude and height."""
    site = scn.site
    lat0, lon0 = np.radians(site.lat_deg), np.radians(site.lon_deg)
    lat, lon, h = earth.enu_to_lla(rows.p_t[0], lat0, lon0, site.height_m)
    q_nt = quat_mul(quat_conj(earth.quat_en(lat, lon)), earth.quat_en(lat0, lon0))
    return q_nt, float(lat), float(h)


def shearer_disturbance(scn: Scenario, shearer: dict, support: int, t: np.ndarray) -> np.ndarray:
    """Scale (K,) in [0, 1] of the shearer's field at a support's unit: (1 - (d/R)^2)^3 for |d| < R."""
    station = support_stations(scn)[support]
    y = scn.face.pan_length_m * (station + 0.5)
    s = np.interp(t, np.asarray(shearer["t"], float), np.asarray(shearer["s"], float))
    r = DISTURBANCE_RANGE_PANS * scn.face.pan_length_m
    x = np.clip(1.0 - ((s - y) / r) ** 2, 0.0, None)
    return x ** 3


def _unit_vector(rng: np.random.Generator) -> np.ndarray:
    u = rng.normal(size=3)
    return u / np.linalg.norm(u)


def _inertial_errors(gyro: np.ndarray, accel: np.ndarray, rate_hz: float, grade_name: str,
                     rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Readings with the grade's errors: twin.sensors.imu_errors on rate * dt, divided back by dt."""
    dt = 1.0 / rate_hz
    dtheta, dv, _ = apply_imu_errors(gyro * dt, accel * dt, dt, grade(grade_name), rng)
    return dtheta / dt, dv / dt


def support_imu_stream(scn: Scenario, supports: dict, shearer: dict, rng: np.random.Generator,
                       faults: Iterable[Fault] | None = None) -> dict[str, np.ndarray]:
    """The SUPPORT_IMU stream (estimators.io.logformat.SUPPORT_IMU) of the instrumented supports.

    `supports` and `shearer` hold the truth_supports and truth_shearer columns; `faults` defaults to the
    scenario's schedule. Rows are ordered by time, then support. Each unit draws from its own child of `rng`
    (rng.spawn), in this order: the inertial errors (twin.sensors.imu_errors), the magnetometer noise, the direction of
    the shearer's field, then one direction per `mag_interference` fault targeting it; so adding a fault
    changes that unit's stream only inside the fault's window.
    """
    cfg = scn.sensors.support_imu
    faults = list(scn.faults if faults is None else faults)
    units = np.unique(np.asarray(cfg.supports, dtype=int))
    t = sample_times(float(shearer["t"][0]), float(shearer["t"][-1]), cfg.rate_hz)
    out = {c: np.empty(t.size * units.size) for c in COLUMNS}
    out["support"] = np.empty(t.size * units.size, dtype=np.int32)
    if units.size == 0:
        return out
    b_n = site_field_n(scn)
    w_ie_t = earth.earth_rate_n(np.radians(scn.site.lat_deg))
    n_u = units.size
    zero = np.zeros_like(t)
    for k, (j, gen) in enumerate(zip(units, rng.spawn(n_u))):
        rows = canopy_rows(scn, supports, int(j))
        motion = canopy_motion(scn, rows, t)
        q_nt, lat, h = _station_q_nt(scn, rows)
        q_ct = quat_conj(motion.q_tc)
        q_cn = quat_mul(q_ct, np.broadcast_to(quat_conj(q_nt), q_ct.shape))
        gyro = np.stack([zero, motion.tilt_rate, zero], axis=-1) + quat_rotate(q_ct, w_ie_t)
        accel = (quat_rotate(q_ct, motion.a_t + np.cross(2 * w_ie_t, motion.v_t))
                 - quat_rotate(q_cn, earth.gravity_n(lat, h)))
        gyro, accel = _inertial_errors(gyro, accel, cfg.rate_hz, cfg.grade, gen)
        mag = quat_rotate(q_cn, b_n)
        if scn.sensors.mag.noise_t > 0:
            mag += gen.normal(0.0, scn.sensors.mag.noise_t, mag.shape)
        near = shearer_disturbance(scn, shearer, int(j), t)
        mag += (cfg.shearer_disturbance_t * near)[:, None] * _unit_vector(gen)
        for fault in faults_of(faults, "mag_interference"):
            if fault.target == j:
                mag[window_mask(t, fault)] += fault.value * _unit_vector(gen)
        sl = slice(k, None, n_u)
        out["t"][sl] = t
        out["support"][sl] = j
        for name, arr in (("gyro", gyro), ("accel", accel), ("mag", mag)):
            for a, axis in enumerate("xyz"):
                out[f"{name}_{axis}"][sl] = arr[:, a]
    return out
