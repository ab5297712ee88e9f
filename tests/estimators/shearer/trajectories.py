"""An independent shearer trajectory for the shearer filters' tests: closed-form passes along a bent, undulating
face at any azimuth and latitude, with stops, and the exact sensor log it gives (no twin, no strapdown).

Path. The face coordinate s runs along the face line from the start pose; in the ENU tangent plane t at the
geodetic origin the body point is

    P(s) = s a + w(s) x + z(s) up,   a = (sin az, cos az, 0),   x = (cos az, -sin az, 0)  (towards the coal wall),
    w(s) = S sin(2 pi s / L) + 4 B (s / L) (1 - s / L) + web (k - 1 + r_k(s))       (plan: S curve, bend, advance),
    z(s) = F sin(2 pi s / lambda) + s tan(dip)                                     (floor),

on pass k (k = 0 from s = 0 to L, then back and forth). r_0 = 1; for k >= 1, r_k rises as (1 - cos(pi d / snake)) / 2
over the first `snake_m` metres d of the pass, so each pass after the first runs one web further towards the coal
wall, entering the new web diagonally as a cut-out does. s(t) moves with a cruise speed per pass, raised cosine
speed ramps, stops mid-face and at the ends. Attitude: body y along dP/ds (in the local n frame), roll
R sin(2 pi s / lambda_r + 0.7), C_b^n = Rz(yaw) Rx(pitch) Ry(roll).

Increments (estimators.io.logformat IMU: what a perfect IMU outputs over (t - Ts, t]): dtheta the rotation vector
of C_b^i(t - Ts)^T C_b^i(t), C_b^i = Rz(w_ie t) C_n^e C_b^n (the Earth's rotation and the transport rate of the
geodetic position are in C_n^e(t)); dv the integral of f_b = C_e^b (d2r_e/dt2 + 2 w_ie x dr_e/dt - g_e) by
3-point Gauss-Legendre, r_e the ECEF position (affine in P), g the WGS-84 normal gravity of estimators.nav.earth.
The odometer counts the arc length of P (exact, optionally in pulses, with a scale error).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from estimators.io.log import Log, log_from_columns
from estimators.nav import earth
from estimators.nav.geomagnetic import geomagnetic_reference
from estimators.nav.rotations import (
    euler_to_mat,
    mat_to_quat,
    quat_to_euler,
    quat_to_rotvec,
)
from estimators.shearer.config import Config, ImuNoise, MagSettings

DEG = np.pi / 180
G0 = 9.80665
GL_X, GL_W = np.polynomial.legendre.leggauss(3)

GRADES = {
    "ideal": ImuNoise(gyro_arw=1e-6, accel_vrw=1e-5, gyro_bias=1e-7, accel_bias=1e-5),
    "mti-g-700": ImuNoise(gyro_arw=0.6 * DEG / 60, accel_vrw=0.08e-3 * G0, gyro_bias=720 * DEG / 3600,
                          accel_bias=3e-3 * G0),
    "tactical": ImuNoise(gyro_arw=0.05 * DEG / 60, accel_vrw=0.03e-3 * G0, gyro_bias=5 * DEG / 3600,
                         accel_bias=0.5e-3 * G0),
}
"""IMU error budgets: white noise and turn-on biases drawn as the filter's Config models them ("ideal": the
floors the twin's ideal grade gets, for error-free increments)."""


@dataclass(frozen=True)
class Face:
    """A trajectory: face geometry, cutting passes and sensor rates (SI but the angles in degrees)."""

    azimuth_deg: float = 0.0  # of the along-face direction (body y on the first pass), clockwise from north
    lat_deg: float = 55.0
    lon_deg: float = 20.0
    h_m: float = 250.0
    length_m: float = 60.0
    speeds_mps: tuple[float, ...] = (0.3, 0.45, 0.2)  # cruise speed of each pass (the passes count)
    ramp_s: float = 4.0
    stand_s: float = 30.0  # before the first pass
    end_stop_s: float = 8.0
    mid_stop_s: float = 6.0  # a stop in the middle of every pass (0: none)
    s_curve_m: float = 0.3
    bend_m: float = 0.2
    floor_m: float = 0.3
    floor_wavelength_m: float = 40.0
    dip_deg: float = 1.5
    roll_deg: float = 1.5
    roll_wavelength_m: float = 25.0
    web_m: float = 0.8
    snake_m: float = 15.0
    imu_hz: float = 200.0
    odo_hz: float = 50.0
    ram_hz: float = 1.0
    support_spacing_m: float = 1.75


@dataclass(frozen=True)
class Errors:
    """Sensor errors of a log: an IMU grade of GRADES; the odometer reads (1 + odo_scale) times the true distance
    (the truth of the filters' odometer scale state is then odo_scale), in pulses of pulse_m (0: exact); the
    survey's and face survey's sigmas (drawn as errors with `draw_survey`); magnetometer noise [T]."""

    grade: str = "ideal"
    odo_scale: float = 0.0
    pulse_m: float = 0.0
    sd_h: float = 0.005
    sd_v: float = 0.005
    sd_yaw: float = 0.05 * DEG
    draw_survey: bool = False
    mag_noise_t: float = 0.0
    seed: int = 0
    face_ends: bool = True
    streams: tuple[str, ...] = field(default=("pushram", "mag", "face_survey"))


class Trajectory:
    """The closed-form motion of a Face: `truth(t)`, `increments()`, and the sensor log (`log`, `config`)."""

    def __init__(self, face: Face):
        self.face = face
        f = face
        az = f.azimuth_deg * DEG
        self._a, self._x = np.array([np.sin(az), np.cos(az), 0.0]), np.array([np.cos(az), -np.sin(az), 0.0])
        self.origin = np.array([f.lat_deg * DEG, f.lon_deg * DEG, f.h_m])
        self._r0 = earth.lla_to_ecef(*self.origin)
        self._c_te = earth.mat_en(*self.origin[:2])
        rows, t, s = [], 0.0, 0.0
        rows.append((t, f.stand_s, 0.0, 0.0, 0.0, 0))
        t += f.stand_s
        self.arrivals = []  # time the shearer reaches the far end of each pass
        for k, v in enumerate(f.speeds_mps):
            end = f.length_m if k % 2 == 0 else 0.0
            stops = [0.5 * (s + end), end] if f.mid_stop_s > 0 else [end]
            for target, pause in zip(stops, [f.mid_stop_s] * (len(stops) - 1) + [f.end_stop_s]):
                dist = target - s
                if abs(dist) < v * f.ramp_s:
                    raise ValueError(f"pass {k}: {abs(dist):.2f} m is shorter than the speed ramps")
                rows.append((t, abs(dist) / v + f.ramp_s, s, dist, v, k))
                t += abs(dist) / v + f.ramp_s
                s = target
                if target == end:
                    self.arrivals.append(t)
                rows.append((t, pause, s, 0.0, 0.0, k))
                t += pause
        self._seg = np.array(rows)
        self.duration = t

    # ------------------------------------------------------------------------------------------------ motion

    def along(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Face coordinate s, ds/dt, d2s/dt2 and the pass k at times t."""
        seg = self._seg
        i = np.clip(np.searchsorted(seg[:, 0], t, side="right") - 1, 0, len(seg) - 1)
        t0, dur, s0, dist, v, k = seg[i].T
        ta = self.face.ramp_s
        tau = np.clip(t - t0, 0.0, dur)

        def ramp(x):  # distance, speed, acceleration x seconds into a ramp up to v
            ph = np.pi * np.clip(x, 0.0, ta) / ta
            return 0.5 * v * (np.clip(x, 0.0, ta) - ta / np.pi * np.sin(ph)), 0.5 * v * (1 - np.cos(ph)), \
                0.5 * v * np.pi / ta * np.sin(ph)

        d_up, v_up, a_up = ramp(tau)
        d_dn, v_dn, a_dn = ramp(dur - tau)
        up, down = tau < ta, tau > dur - ta
        dist_abs = np.abs(dist)
        d = np.where(up, d_up, np.where(down, dist_abs - d_dn, 0.5 * v * ta + v * (tau - ta)))
        sp = np.where(up, v_up, np.where(down, v_dn, v))
        ac = np.where(up, a_up, np.where(down, -a_dn, 0.0))
        sign = np.sign(dist)
        moving = v > 0
        return (s0 + np.where(moving, sign * d, 0.0), np.where(moving, sign * sp, 0.0),
                np.where(moving, sign * ac, 0.0), k.astype(int))

    def shape(self, s: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """P(s), dP/ds, d2P/ds2 in t (K, 3) and the roll on pass k."""
        f = self.face
        length, om_f = f.length_m, 2 * np.pi / f.floor_wavelength_m
        om_s = 2 * np.pi / length
        start = np.where(k % 2 == 0, 0.0, length)
        x = np.abs(s - start) / f.snake_m
        ramping = (k > 0) & (x < 1.0)
        r = np.where(ramping, 0.5 * (1 - np.cos(np.pi * x)), 1.0)
        r1 = np.where(ramping, 0.5 * np.pi / f.snake_m * np.sin(np.pi * x) * np.sign(s - start), 0.0)
        r2 = np.where(ramping, 0.5 * (np.pi / f.snake_m) ** 2 * np.cos(np.pi * x), 0.0)
        u = s / length
        w = f.s_curve_m * np.sin(om_s * s) + 4 * f.bend_m * u * (1 - u) + f.web_m * (k - 1 + r)
        w1 = f.s_curve_m * om_s * np.cos(om_s * s) + 4 * f.bend_m * (1 - 2 * u) / length + f.web_m * r1
        w2 = -f.s_curve_m * om_s ** 2 * np.sin(om_s * s) - 8 * f.bend_m / length ** 2 + f.web_m * r2
        z = f.floor_m * np.sin(om_f * s) + s * np.tan(f.dip_deg * DEG)
        z1 = f.floor_m * om_f * np.cos(om_f * s) + np.tan(f.dip_deg * DEG)
        z2 = -f.floor_m * om_f ** 2 * np.sin(om_f * s)
        up = np.array([0.0, 0.0, 1.0])

        def vec(along, across, vertical):
            return along[:, None] * self._a + across[:, None] * self._x + vertical[:, None] * up

        roll = f.roll_deg * DEG * np.sin(2 * np.pi * s / f.roll_wavelength_m + 0.7)
        return vec(s, w, z), vec(np.ones_like(s), w1, z1), vec(np.zeros_like(s), w2, z2), roll

    def states(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """The body state at times t: lat, lon, h, v_n (ENU ground velocity), c_bn, c_ne (C_n^e), f_b."""
        t = np.asarray(t, float)
        s, sd, sdd, k = self.along(t)
        p, p1, p2, roll = self.shape(s, k)
        c_te = self._c_te
        r_e = self._r0 + p @ c_te.T
        v_e = (p1 * sd[:, None]) @ c_te.T
        a_e = (p2 * sd[:, None] ** 2 + p1 * sdd[:, None]) @ c_te.T
        lat, lon, h = earth.ecef_to_lla(r_e)
        c_ne = earth.mat_en(lat, lon)
        g_e = -earth.normal_gravity(lat, h)[:, None] * c_ne[:, :, 2]
        w_ie = np.array([0.0, 0.0, earth.OMEGA_IE])
        f_e = a_e + 2 * np.cross(w_ie, v_e) - g_e
        y_n = _t_mul(c_ne, p1 @ c_te.T)
        y_n /= np.linalg.norm(y_n, axis=1, keepdims=True)
        c_bn = euler_to_mat(np.arcsin(y_n[:, 2]), roll, np.arctan2(-y_n[:, 0], y_n[:, 1]))
        f_b = _t_mul(c_bn, _t_mul(c_ne, f_e))
        return {"lat": lat, "lon": lon, "h": h, "v_n": _t_mul(c_ne, v_e), "c_bn": c_bn,
                "c_ne": c_ne, "f_b": f_b, "s": s, "pass": k}

    def truth(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """llh (K, 3), v_n (K, 3), q_nb (K, 4) at times t."""
        st = self.states(t)
        return {"llh": np.column_stack([st["lat"], st["lon"], st["h"]]), "v_n": st["v_n"],
                "q_nb": mat_to_quat(st["c_bn"])}

    def arc_rate(self, t: np.ndarray) -> np.ndarray:
        """Signed rate of the path's arc length (|dP/ds| ds/dt)."""
        s, sd, _, k = self.along(t)
        return np.linalg.norm(self.shape(s, k)[1], axis=1) * sd

    def quadrature(self, t: np.ndarray, fn) -> np.ndarray:
        """Integral of fn (vectors (K, ...) at times) over each interval (t[i-1], t[i]] by Gauss-Legendre."""
        mid, half = 0.5 * (t[1:] + t[:-1]), 0.5 * np.diff(t)
        nodes = (mid[:, None] + half[:, None] * GL_X).ravel()
        vals = fn(nodes)
        vals = vals.reshape((mid.size, GL_X.size) + vals.shape[1:])
        return np.einsum("kg...,g->k...", vals, GL_W) * half.reshape((-1,) + (1,) * (vals.ndim - 2))

    @cached_property
    def exact(self) -> tuple[np.ndarray, ...]:
        """The increments over the whole trajectory (`increments`), computed once."""
        return self.increments()

    def increments(self, duration: float | None = None, chunk: int = 20000) -> tuple[np.ndarray, ...]:
        """(t (N+1,), dtheta (N+1, 3), dv (N+1, 3)) at the IMU rate from t = 0, row 0 zero (the rows of
        estimators.sins.strapdown.mechanize)."""
        n = round((duration or self.duration) * self.face.imu_hz)
        t = np.arange(n + 1) / self.face.imu_hz
        dtheta, dv = np.zeros((n + 1, 3)), np.zeros((n + 1, 3))
        for a in range(0, n, chunk):
            b = min(a + chunk, n)
            tt = t[a:b + 1]
            st = self.states(tt)
            c_be = st["c_ne"] @ st["c_bn"]
            ang = earth.OMEGA_IE * np.diff(tt)
            rz = np.zeros((ang.size, 3, 3))
            rz[:, 0, 0] = rz[:, 1, 1] = np.cos(ang)
            rz[:, 1, 0], rz[:, 0, 1], rz[:, 2, 2] = np.sin(ang), -np.sin(ang), 1.0
            rel = np.swapaxes(c_be[:-1], 1, 2) @ rz @ c_be[1:]
            dtheta[a + 1:b + 1] = quat_to_rotvec(mat_to_quat(rel))
            dv[a + 1:b + 1] = self.quadrature(tt, lambda x: self.states(x)["f_b"])
        return t, dtheta, dv

    # ------------------------------------------------------------------------------------------- sensor log

    def face_points(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        """Face coordinate s on the first pass at arc lengths u = 0, spacing, ... (u, s)."""
        s = np.linspace(0.0, self.face.length_m, 60001)
        rate = np.linalg.norm(self.shape(s, np.zeros(s.size, int))[1], axis=1)
        arc = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(s))])
        u = np.arange(0.0, arc[-1], spacing)
        return u, np.interp(u, arc, s)

    def support_u(self) -> np.ndarray:
        """Face coordinate (arc length from the start pose) of each support."""
        u, _ = self.face_points(self.face.support_spacing_m)
        return u[1:] - 0.5 * self.face.support_spacing_m

    def pushram(self) -> dict[str, np.ndarray]:
        """PUSHRAM rows: each support's ram extends by the pan's shift between two passes after the shearer has
        passed (a quarter of the time to its return, over 2 s) and retracts as the support advances (at 0.6)."""
        f = self.face
        u_sup = self.support_u()
        s_sup = np.interp(u_sup, *self.face_points(0.01))
        t_grid = np.arange(0.0, self.duration, 1.0 / f.odo_hz)
        s_grid, _, _, k_grid = self.along(t_grid)
        t_ram = np.arange(0.0, self.duration, 1.0 / f.ram_hz)
        ext = np.full((t_ram.size, s_sup.size), 1.0)
        for k in range(1, len(f.speeds_mps)):
            crossing = []
            for kk in (k - 1, k):
                sel = k_grid == kk
                order = np.argsort(s_grid[sel], kind="stable")
                crossing.append(np.interp(s_sup, s_grid[sel][order], t_grid[sel][order]))
            shift = (self.shape(s_sup, np.full(s_sup.size, k))[0] - self.shape(s_sup, np.full(s_sup.size, k - 1))[0]) \
                @ self._x
            t_push = crossing[0] + 0.25 * (crossing[1] - crossing[0])
            t_adv = crossing[0] + 0.6 * (crossing[1] - crossing[0])
            ext += shift * (np.clip((t_ram[:, None] - t_push) / 2.0, 0, 1) - np.clip((t_ram[:, None] - t_adv) / 2.0, 0, 1))
        support = np.broadcast_to(np.arange(s_sup.size), ext.shape)
        return {"t": np.repeat(t_ram, s_sup.size), "support": support.ravel().astype(np.int32),
                "extension": ext.ravel(), "valid": np.ones(ext.size, np.int8)}

    def log(self, errors: Errors = Errors()) -> Log:
        """The sensor log of this trajectory with `errors` (estimators.io.log.log_from_columns)."""
        rng = np.random.default_rng(errors.seed)
        f = self.face
        t, dtheta, dv = (a.copy() for a in self.exact)
        imu_dt = 1.0 / f.imu_hz
        g = GRADES[errors.grade]
        if errors.grade != "ideal":
            n = t.size - 1
            dtheta[1:] += rng.normal(0, g.gyro_bias, 3) * imu_dt + rng.normal(0, g.gyro_arw * np.sqrt(imu_dt), (n, 3))
            dv[1:] += rng.normal(0, g.accel_bias, 3) * imu_dt + rng.normal(0, g.accel_vrw * np.sqrt(imu_dt), (n, 3))
        imu = {"t": t[1:], **{f"dtheta_{a}": dtheta[1:, i] for i, a in enumerate("xyz")},
               **{f"dv_{a}": dv[1:, i] for i, a in enumerate("xyz")}}
        t_odo = np.arange(0.0, self.duration + 0.5 / f.odo_hz, 1.0 / f.odo_hz)
        dist = np.concatenate([[0.0], np.cumsum(self.quadrature(t_odo, self.arc_rate))]) * (1 + errors.odo_scale)
        pulses = np.round(dist / (errors.pulse_m or 0.002)).astype(np.int64)
        if errors.pulse_m:
            dist = pulses * errors.pulse_m
        odo = {"t": t_odo, "distance": dist, "pulses": pulses,
               "direction": np.sign(self.along(t_odo)[1]).astype(np.int8)}
        t_fix = np.array([0.0] + (self.arrivals if errors.face_ends else []))
        true = self.truth(t_fix)
        sd_enu = np.array([errors.sd_h, errors.sd_h, errors.sd_v])
        llh = self._perturb(true["llh"], rng.normal(size=(t_fix.size, 3)) * sd_enu * errors.draw_survey)
        yaw = np.full(t_fix.size, np.nan)
        yaw[0] = quat_to_euler(true["q_nb"][0])[2] + errors.draw_survey * errors.sd_yaw * rng.normal()
        survey = {"t": t_fix, "lat": llh[:, 0], "lon": llh[:, 1], "h": llh[:, 2], "yaw": yaw,
                  "sd_horizontal": np.full(t_fix.size, errors.sd_h), "sd_vertical": np.full(t_fix.size, errors.sd_v),
                  "sd_yaw": np.where(np.isnan(yaw), np.nan, errors.sd_yaw)}
        extra = {}
        if "pushram" in errors.streams:
            extra["pushram"] = self.pushram()
        if "mag" in errors.streams:
            field_n = geomagnetic_reference(*self.origin, MagSettings().date).field_n
            t_mag = t_odo[1:]
            b = np.einsum("kji,j->ki", self.states(t_mag)["c_bn"], field_n)
            b += rng.normal(0, errors.mag_noise_t, b.shape)
            extra["mag"] = {"t": t_mag, **{f"b_{a}": b[:, i] for i, a in enumerate("xyz")}}
        if "face_survey" in errors.streams:
            u, s = self.face_points(f.support_spacing_m)
            p = self.shape(s, np.zeros(s.size, int))[0]
            pts = self._perturb(np.column_stack(earth.enu_to_lla(p, *self.origin)),
                                rng.normal(size=(u.size, 3)) * sd_enu * errors.draw_survey)
            extra["face_survey"] = {"t": np.zeros(u.size), "u": u, "lat": pts[:, 0], "lon": pts[:, 1],
                                    "h": pts[:, 2], "sd_horizontal": np.full(u.size, errors.sd_h),
                                    "sd_vertical": np.full(u.size, errors.sd_v)}
        return log_from_columns(imu, odo, survey, **extra)

    @staticmethod
    def _perturb(llh: np.ndarray, d_enu: np.ndarray) -> np.ndarray:
        """Geodetic points moved by ENU offsets (K, 3) at each point."""
        return np.array([earth.enu_to_lla(d, *p) for p, d in zip(llh, d_enu)]).reshape(-1, 3)

    def config(self, errors: Errors = Errors(), **kw) -> Config:
        """The filter configuration for this face and these errors (the IMU budget of the grade drawn)."""
        f = self.face
        base = {"metres_per_pulse": errors.pulse_m or 0.002, "support_u_m": tuple(self.support_u()),
                "chute_length_m": f.support_spacing_m, "end_zone_m": f.snake_m + 2 * f.support_spacing_m,
                "mag": MagSettings(noise_t=max(errors.mag_noise_t, 1e-9))}
        return Config(imu=GRADES[errors.grade], **(base | kw))


def _t_mul(c: np.ndarray, v: np.ndarray) -> np.ndarray:
    """C^T v row by row (C (K, 3, 3), v (K, 3))."""
    return np.matmul(v[:, None, :], c)[:, 0, :]
