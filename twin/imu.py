"""Ideal shearer-IMU increments from the truth: lever arm, mounting misalignment and vibration included.

A real strapdown IMU reports, over each interval (t - Ts, t], the integrals of its own angular rate and
specific force in its own (sensor) frame s:

    dtheta_k = int w_is^s dt,        dv_k = int f_s^s dt.

The sensor sits at rho(t) = r + u(t) in b (r the lever arm, u the linear vibration) and its axes are
C_s^b(t) = M Exp(phi(t)) (M the fixed mounting misalignment, phi the angular vibration). Rigid-body
kinematics give, with w = w_ib^b of the body and all derivatives relative to b,

    w_is^s = C_s^b w + J_r(phi) dphi/dt
    f_s^s  = C_s^b (f^b + dw/dt x rho + w x (w x rho) + 2 w x drho/dt + d2rho/dt2).

The body's w and f^b come from the truth samples (cubic Hermite interpolation between them); the vibration
is analytic (sums of sines with random phases and a smooth amplitude envelope per machine state). Each
interval is integrated with 4-point Gauss-Legendre quadrature, exact for the cubic body part and to ~1e-12
relative for vibration up to 40 Hz at 200 Hz, so an uncompensated mechanization shows exactly the coning and
sculling the vibration creates, and a compensated one removes it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from estimators import earth
from estimators.rotations import euler_to_mat, quat_conj, quat_mul, quat_rotate
from twin.haulage import STOPPED
from twin.scenario import Scenario
from twin.sensor_config import VibrationState

G0 = 9.80665
GL_NODES = np.array([-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526])
GL_WEIGHTS = np.array([0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538])

# Machine states of the vibration model.
IDLE, COAL, ROCK = range(3)


@dataclass(frozen=True)
class VibrationTones:
    """Sines of the sensor's angle phi_i = sum a sin(2 pi f t + p) and displacement u_i, per machine state.

    Shapes: freq_hz (n_states, n_tones); ang_amp and lin_amp (n_states, n_tones, 3) per axis [rad], [m];
    phase_ang and phase_lin (3, n_tones) [rad]."""

    freq_hz: np.ndarray
    ang_amp: np.ndarray
    lin_amp: np.ndarray
    phase_ang: np.ndarray
    phase_lin: np.ndarray


def vibration_tones(states: list[VibrationState], rng: np.random.Generator) -> VibrationTones:
    """Amplitudes from the RMS specifications: each tone carries half the power on every axis.

    A sine of rate amplitude a has RMS a / sqrt(2); so a tone with angular-rate RMS s / sqrt(2) (half the
    power) has rate amplitude s and angle amplitude s / (2 pi f); likewise for acceleration and displacement.
    """
    freq = np.array([[max(st.drum_hz, 1e-3), max(st.pick_hz, 1e-3)] for st in states])
    rate_rms = np.array([np.radians(st.angular_rms_deg_s) for st in states])[:, None]
    acc_rms = np.array([st.accel_rms_g * G0 for st in states])[:, None]
    omega = 2 * np.pi * freq
    per_axis = np.ones((1, 1, 3))
    return VibrationTones(freq, (rate_rms / omega)[..., None] * per_axis, (acc_rms / omega ** 2)[..., None] * per_axis,
                          rng.uniform(0, 2 * np.pi, (3, 2)), rng.uniform(0, 2 * np.pi, (3, 2)))


def machine_state(scn: Scenario, phase: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Idle while stopped, cutting coal while moving, cutting rock inside the scenario's rock zones."""
    state = np.where(phase == STOPPED, IDLE, COAL)
    for lo, hi in scn.sensors.vibration.rock_zones_m:
        state = np.where((state == COAL) & (s >= min(lo, hi)) & (s <= max(lo, hi)), ROCK, state)
    return state


@nb.njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@nb.njit(cache=True)
def _hermite(y0, y1, d0, d1, h, x):
    """Cubic Hermite value and derivative at x in [0, 1] of an interval of length h."""
    x2, x3 = x * x, x * x * x
    val = (2 * x3 - 3 * x2 + 1) * y0 + (x3 - 2 * x2 + x) * h * d0 + (-2 * x3 + 3 * x2) * y1 + (x3 - x2) * h * d1
    der = ((6 * x2 - 6 * x) * y0 + (-6 * x2 + 6 * x) * y1) / h + (3 * x2 - 4 * x + 1) * d0 + (3 * x2 - 2 * x) * d1
    return val, der


@nb.njit(cache=True)
def _increments_kernel(t, w, dw, f, df, amp_state, freq, ang_amp, lin_amp, ph_ang, ph_lin, lever, mat_bs,
                       nodes, weights, dtheta, dv):
    """Gauss-Legendre integration of the sensor's rate and specific force over each interval (t[k-1], t[k]].

    amp_state (K, n_states): the weight of each machine state at each sample (a smooth envelope, linear
    between samples). Sines at the nodes come from one sine and cosine per interval and tone, turned by
    the node offsets (angle addition), so the cost is a few trigonometric calls per sample."""
    n_states, n_tones, n_nodes = freq.shape[0], freq.shape[1], nodes.size
    w_b, w_dot, f_b = np.empty(3), np.empty(3), np.empty(3)
    phi, phi_dot, u, u_dot, u_ddot = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    rho, tmp, tmp2, f_pt, w_vib = np.empty(3), np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    kx, exp_phi, jr, c_sb = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    eye = np.eye(3)
    for k in range(1, t.size):
        h = t[k] - t[k - 1]
        acc_th = np.zeros(3)
        acc_v = np.zeros(3)
        for q in range(n_nodes):
            x = 0.5 * (nodes[q] + 1.0)
            for i in range(3):
                w_b[i], w_dot[i] = _hermite(w[k - 1, i], w[k, i], dw[k - 1, i], dw[k, i], h, x)
                f_b[i], _ = _hermite(f[k - 1, i], f[k, i], df[k - 1, i], df[k, i], h, x)
                phi[i] = phi_dot[i] = u[i] = u_dot[i] = u_ddot[i] = 0.0
            for st in range(n_states):
                wgt = (1 - x) * amp_state[k - 1, st] + x * amp_state[k, st]
                if wgt == 0.0:
                    continue
                for tone in range(n_tones):
                    om = 2 * np.pi * freq[st, tone]
                    c_node, s_node = np.cos(om * x * h), np.sin(om * x * h)
                    for i in range(3):
                        a_ang, a_lin = wgt * ang_amp[st, tone, i], wgt * lin_amp[st, tone, i]
                        s0, c0 = np.sin(om * t[k - 1] + ph_ang[i, tone]), np.cos(om * t[k - 1] + ph_ang[i, tone])
                        s_a, c_a = s0 * c_node + c0 * s_node, c0 * c_node - s0 * s_node
                        s0, c0 = np.sin(om * t[k - 1] + ph_lin[i, tone]), np.cos(om * t[k - 1] + ph_lin[i, tone])
                        s_l, c_l = s0 * c_node + c0 * s_node, c0 * c_node - s0 * s_node
                        phi[i] += a_ang * s_a
                        phi_dot[i] += a_ang * om * c_a
                        u[i] += a_lin * s_l
                        u_dot[i] += a_lin * om * c_l
                        u_ddot[i] -= a_lin * om * om * s_l
            # C_b^s = (M Exp(phi))^T; the envelope's own slope is neglected (it changes over seconds).
            theta2 = phi[0] ** 2 + phi[1] ** 2 + phi[2] ** 2
            theta = np.sqrt(theta2)
            if theta < 1e-4:
                a, b, c = 1.0 - theta2 / 6, 0.5 - theta2 / 24, 1.0 / 6 - theta2 / 120
            else:
                a = np.sin(theta) / theta
                b = (1 - np.cos(theta)) / theta2
                c = (theta - np.sin(theta)) / (theta2 * theta)
            kx[0, 0], kx[0, 1], kx[0, 2] = 0.0, -phi[2], phi[1]
            kx[1, 0], kx[1, 1], kx[1, 2] = phi[2], 0.0, -phi[0]
            kx[2, 0], kx[2, 1], kx[2, 2] = -phi[1], phi[0], 0.0
            for r in range(3):
                for col in range(3):
                    kk = phi[r] * phi[col] - theta2 * eye[r, col]  # [phi x]^2
                    exp_phi[r, col] = eye[r, col] + a * kx[r, col] + b * kk
                    jr[r, col] = eye[r, col] - b * kx[r, col] + c * kk
            for r in range(3):
                for col in range(3):
                    c_sb[col, r] = mat_bs[r, 0] * exp_phi[0, col] + mat_bs[r, 1] * exp_phi[1, col] + \
                        mat_bs[r, 2] * exp_phi[2, col]
                rho[r] = lever[r] + u[r]
            # f of the point: f_b + dw x rho + w x (w x rho) + 2 w x du + d2u
            _cross(w_dot, rho, f_pt)
            _cross(w_b, rho, tmp)
            _cross(w_b, tmp, tmp2)
            _cross(w_b, u_dot, tmp)
            for i in range(3):
                f_pt[i] += f_b[i] + tmp2[i] + 2 * tmp[i] + u_ddot[i]
            for i in range(3):
                w_vib[i] = jr[i, 0] * phi_dot[0] + jr[i, 1] * phi_dot[1] + jr[i, 2] * phi_dot[2]
                acc_th[i] += weights[q] * (c_sb[i, 0] * w_b[0] + c_sb[i, 1] * w_b[1] + c_sb[i, 2] * w_b[2]
                                           + w_vib[i])
                acc_v[i] += weights[q] * (c_sb[i, 0] * f_pt[0] + c_sb[i, 1] * f_pt[1] + c_sb[i, 2] * f_pt[2])
        for i in range(3):
            dtheta[k, i] = 0.5 * h * acc_th[i]
            dv[k, i] = 0.5 * h * acc_v[i]


def sensor_increments(t: np.ndarray, w_ib_b: np.ndarray, f_b: np.ndarray, amp_state: np.ndarray,
                      tones: VibrationTones, lever_arm_b: np.ndarray, mat_bs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Increments (K, 3) of a sensor at lever_arm_b with axes C_s^b = mat_bs Exp(phi(t)) on a body with
    samples of w_ib^b and f^b at times t; amp_state (K, n_states) weighs the tones of each state."""
    dtheta, dv = np.zeros_like(w_ib_b), np.zeros_like(f_b)
    dw = np.gradient(w_ib_b, t, axis=0, edge_order=2)
    df = np.gradient(f_b, t, axis=0, edge_order=2)
    _increments_kernel(t, w_ib_b, dw, f_b, df, amp_state, tones.freq_hz, tones.ang_amp, tones.lin_amp,
                       tones.phase_ang, tones.phase_lin, np.asarray(lever_arm_b, float), mat_bs, GL_NODES,
                       GL_WEIGHTS, dtheta, dv)
    return dtheta, dv


def gravity_at_lever_arm_b(shearer: dict[str, np.ndarray], lever_arm_b: np.ndarray, lat0: float, lon0: float,
                           h0: float) -> np.ndarray:
    """g at the sensor minus g at the body reference point, in b (K, 3): the gravity gradient over the lever
    arm, ~3e-6 s^-2 per metre up and the turn of the vertical, 1.6e-7 rad per metre across. The truth's
    f^b holds the reference point's gravity; the sensor feels its own."""
    q_nb = np.column_stack([shearer[f"q_nb_{a}"] for a in "wxyz"])
    q_tn = quat_mul(quat_conj(earth.quat_en(lat0, lon0))[None], earth.quat_en(shearer["lat"], shearer["lon"]))
    p_t = np.column_stack([shearer[f"p_t_{a}"] for a in "enu"])
    lat_s, lon_s, h_s = earth.enu_to_lla(p_t + quat_rotate(quat_mul(q_tn, q_nb), lever_arm_b[None]), lat0, lon0, h0)
    q_ts = quat_mul(quat_conj(earth.quat_en(lat0, lon0))[None], earth.quat_en(lat_s, lon_s))
    g_sensor_n = quat_rotate(quat_mul(quat_conj(q_tn), q_ts), earth.gravity_n(lat_s, h_s))
    return quat_rotate(quat_conj(q_nb), g_sensor_n - earth.gravity_n(shearer["lat"], shearer["h"]))


def mounting_matrix(misalignment_deg) -> np.ndarray:
    """C_s^b at rest from the small mounting angles about x, y, z (DESIGN's Euler order)."""
    m = np.radians(np.asarray(misalignment_deg, float))
    return euler_to_mat(m[0], m[1], m[2])


def ideal_increments(scn: Scenario, shearer: dict[str, np.ndarray], rng: np.random.Generator,
                     vibration: bool | None = None) -> dict[str, np.ndarray]:
    """Error-free IMU increments at the truth rate (IMU stream columns; the first row is zero).

    `vibration` overrides the scenario's sensors.vibration.enabled (False for the round-trip checks).
    """
    cfg = scn.sensors
    t = shearer["t"]
    w = np.column_stack([shearer[f"w_ib_b_{a}"] for a in "xyz"])
    f = np.column_stack([shearer[f"f_b_{a}"] for a in "xyz"])
    vib = cfg.vibration
    on = vib.enabled if vibration is None else vibration
    tones = vibration_tones([vib.idle, vib.cutting_coal, vib.cutting_rock], rng)
    amp_state = np.zeros((t.size, 3))
    if on:
        amp_state[np.arange(t.size), machine_state(scn, shearer["phase"], shearer["s"])] = 1.0
        # Smooth the switching between states over about half a second (the envelope).
        width = max(1, int(0.5 / np.median(np.diff(t))))
        kernel = np.ones(width) / width
        amp_state = np.column_stack([np.convolve(amp_state[:, j], kernel, mode="same") for j in range(3)])
    lever = np.asarray(cfg.imu.lever_arm_m, float)
    site = scn.site
    # f = a - g: the sensor's specific force loses what its own gravity adds over the reference point's.
    f = f - gravity_at_lever_arm_b(shearer, lever, np.radians(site.lat_deg), np.radians(site.lon_deg), site.height_m)
    dtheta, dv = sensor_increments(t, w, f, amp_state, tones, lever, mounting_matrix(cfg.imu.misalignment_deg))
    return {"t": t, **{f"dtheta_{a}": dtheta[:, i] for i, a in enumerate("xyz")},
            **{f"dv_{a}": dv[:, i] for i, a in enumerate("xyz")}}
