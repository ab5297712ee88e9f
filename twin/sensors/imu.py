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

A streaming run hands over its truth in chunks (twin.sensors.chunks); `IdealImu` gives each chunk's IMU samples,
bit for bit those of the whole run in one chunk: a truth interval's increment reads the truth up to the envelope's reach
and a sample to either side (the envelope, its slope, the derivatives of w and f), inside the chunk's halo
(HALO_S), and the truth intervals of an IMU sample that straddles two chunks are carried to the next.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.nav import earth
from estimators.nav.rotation_kernels import qrot_parts
from estimators.nav.rotations import euler_to_mat
from twin.config.scenario import Scenario
from twin.sensors.chunks import TruthChunk
from twin.sensors.vibration import (
    VIBRATION_STREAM,
    VibrationTones,
    machine_state,
    state_envelope,
    vibration_tones,
)

GL_NODES = np.array([-0.8611363115940526, -0.3399810435848563, 0.3399810435848563, 0.8611363115940526])
GL_WEIGHTS = np.array([0.3478548451374538, 0.6521451548625461, 0.6521451548625461, 0.3478548451374538])

TURN_SLOTS = 32
"""How many truth steps h the increments kernel holds the node turns of (_node_turns), per chunk of intervals."""


def time_derivative(y: np.ndarray, t: np.ndarray, edge_order: int = 1) -> np.ndarray:
    """dy/dt (K, ...) of samples y (K, ...) at times t (K,) [s]: np.gradient's second-order formulas for uneven
    steps in the interior and of order edge_order (1 or 2) at the ends, used whatever the steps, bit for bit
    np.gradient's values where its steps are uneven. (np.gradient switches to its even-step formula when every step
    of the array is equal, so its values would depend, in the last bit, on how far the array extends.)"""
    if y.shape[0] < edge_order + 1:
        raise ValueError(f"a derivative of order-{edge_order} edges needs {edge_order + 1} samples, got {y.shape[0]}")
    rows = np.ascontiguousarray(y, dtype=float).reshape(y.shape[0], -1)
    out = np.empty_like(rows)
    _derivative_kernel(rows, np.ascontiguousarray(t, dtype=float), edge_order, out)
    return out.reshape(y.shape)


@nb.njit(cache=True, parallel=True)
def _derivative_kernel(y, t, edge_order, out):
    """time_derivative of the columns of y (K, n) into out, in np.gradient's order of operations."""
    last = y.shape[0] - 1
    for k in nb.prange(1, last):
        d1, d2 = t[k] - t[k - 1], t[k + 1] - t[k]
        a, b, c = -d2 / (d1 * (d1 + d2)), (d2 - d1) / (d1 * d2), d1 / (d2 * (d1 + d2))
        for i in range(y.shape[1]):
            out[k, i] = a * y[k - 1, i] + b * y[k, i] + c * y[k + 1, i]
    if edge_order == 1:
        d_first, d_last = t[1] - t[0], t[last] - t[last - 1]
        for i in range(y.shape[1]):
            out[0, i] = (y[1, i] - y[0, i]) / d_first
            out[last, i] = (y[last, i] - y[last - 1, i]) / d_last
        return
    d1, d2 = t[1] - t[0], t[2] - t[1]
    a, b, c = -(2. * d1 + d2) / (d1 * (d1 + d2)), (d1 + d2) / (d1 * d2), d1 / (d2 * (d1 + d2))
    for i in range(y.shape[1]):
        out[0, i] = a * y[0, i] + b * y[1, i] - c * y[2, i]
    d1, d2 = t[last - 1] - t[last - 2], t[last] - t[last - 1]
    a, b, c = d2 / (d1 * (d1 + d2)), (d2 + d1) / (d1 * d2), (2. * d2 + d1) / (d2 * (d1 + d2))
    for i in range(y.shape[1]):
        out[last, i] = a * y[last - 2, i] - b * y[last - 1, i] + c * y[last, i]


@nb.njit(cache=True, inline="always")
def _hermite(y0, y1, d0, d1, h, x):
    """Cubic Hermite value and derivative at x in [0, 1] of an interval of length h."""
    x2, x3 = x * x, x * x * x
    val = (2 * x3 - 3 * x2 + 1) * y0 + (x3 - 2 * x2 + x) * h * d0 + (-2 * x3 + 3 * x2) * y1 + (x3 - x2) * h * d1
    der = ((6 * x2 - 6 * x) * y0 + (-6 * x2 + 6 * x) * y1) / h + (3 * x2 - 4 * x + 1) * d0 + (3 * x2 - 2 * x) * d1
    return val, der


@nb.njit(cache=True, inline="always")
def _hermite2(y0, y1, d0, d1, h, x):
    """Second derivative of the same cubic Hermite at x."""
    return ((12 * x - 6) * (y0 - y1) / h + (6 * x - 4) * d0 + (6 * x - 2) * d1) / h


@nb.njit(cache=True, inline="always")
def _cross3(a0, a1, a2, b0, b1, b2):
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@nb.njit(cache=True)
def _interval(k, t, w, dw, f, df, amp_state, amp_rate, freq, ang_amp, lin_amp, ph_ang, ph_lin, lever, mat_bs, nodes,
              weights, dtheta, dv, sin0, cos0, vib, turn):
    """Increments of interval k (scratch: sin0/cos0 (n_states, n_tones, 6) sines and cosines at t[k-1],
    vib (5, 3) the vibration at a node; turn (n_states, n_tones, n_nodes, 2): each tone's cosine and sine over the
    node offsets x h of this interval's step h, _node_turns)."""
    n_states, n_tones = freq.shape
    h = t[k] - t[k - 1]
    for st in range(n_states):
        if amp_state[k - 1, st] == 0.0 and amp_state[k, st] == 0.0 and amp_rate[k - 1, st] == 0.0 \
                and amp_rate[k, st] == 0.0:
            continue
        for tone in range(n_tones):
            om = 2 * np.pi * freq[st, tone]
            for i in range(3):
                sin0[st, tone, i] = np.sin(om * t[k - 1] + ph_ang[i, tone])
                cos0[st, tone, i] = np.cos(om * t[k - 1] + ph_ang[i, tone])
                sin0[st, tone, 3 + i] = np.sin(om * t[k - 1] + ph_lin[i, tone])
                cos0[st, tone, 3 + i] = np.cos(om * t[k - 1] + ph_lin[i, tone])
    th0 = th1 = th2 = v0 = v1 = v2 = 0.0
    for q in range(nodes.size):
        x = 0.5 * (nodes[q] + 1.0)
        wb0, wd0 = _hermite(w[k - 1, 0], w[k, 0], dw[k - 1, 0], dw[k, 0], h, x)
        wb1, wd1 = _hermite(w[k - 1, 1], w[k, 1], dw[k - 1, 1], dw[k, 1], h, x)
        wb2, wd2 = _hermite(w[k - 1, 2], w[k, 2], dw[k - 1, 2], dw[k, 2], h, x)
        fb0, _ = _hermite(f[k - 1, 0], f[k, 0], df[k - 1, 0], df[k, 0], h, x)
        fb1, _ = _hermite(f[k - 1, 1], f[k, 1], df[k - 1, 1], df[k, 1], h, x)
        fb2, _ = _hermite(f[k - 1, 2], f[k, 2], df[k - 1, 2], df[k, 2], h, x)
        vib[:] = 0.0  # rows: phi, dphi/dt, u, du/dt, d2u/dt2 (columns x, y, z)
        for st in range(n_states):
            e0, e1, r0_, r1_ = amp_state[k - 1, st], amp_state[k, st], amp_rate[k - 1, st], amp_rate[k, st]
            if e0 == 0.0 and e1 == 0.0 and r0_ == 0.0 and r1_ == 0.0:
                continue
            # The envelope and its first two derivatives (cubic Hermite, C1 across samples), so that the
            # displacement, velocity and acceleration of the vibration stay one consistent motion: a switch of
            # machine state leaves no velocity offset behind.
            wgt, wgt_d = _hermite(e0, e1, r0_, r1_, h, x)
            wgt_dd = _hermite2(e0, e1, r0_, r1_, h, x)
            for tone in range(n_tones):
                om = 2 * np.pi * freq[st, tone]
                cn, sn = turn[st, tone, q, 0], turn[st, tone, q, 1]
                for i in range(3):
                    aa, al = ang_amp[st, tone, i], lin_amp[st, tone, i]
                    s_a = sin0[st, tone, i] * cn + cos0[st, tone, i] * sn
                    c_a = cos0[st, tone, i] * cn - sin0[st, tone, i] * sn
                    s_l = sin0[st, tone, 3 + i] * cn + cos0[st, tone, 3 + i] * sn
                    c_l = cos0[st, tone, 3 + i] * cn - sin0[st, tone, 3 + i] * sn
                    vib[0, i] += wgt * aa * s_a
                    vib[1, i] += aa * (wgt * om * c_a + wgt_d * s_a)
                    vib[2, i] += wgt * al * s_l
                    vib[3, i] += al * (wgt * om * c_l + wgt_d * s_l)
                    vib[4, i] += al * (-wgt * om * om * s_l + 2 * wgt_d * om * c_l + wgt_dd * s_l)
        p0, p1, p2 = vib[0, 0], vib[0, 1], vib[0, 2]
        pd0, pd1, pd2 = vib[1, 0], vib[1, 1], vib[1, 2]
        u0, u1, u2 = vib[2, 0], vib[2, 1], vib[2, 2]
        ud0, ud1, ud2 = vib[3, 0], vib[3, 1], vib[3, 2]
        uu0, uu1, uu2 = vib[4, 0], vib[4, 1], vib[4, 2]
        # C_s^b = M Exp(phi): Exp(phi) = I + a [phi]x + b [phi]x^2, J_r = I - b [phi]x + c [phi]x^2.
        theta2 = p0 * p0 + p1 * p1 + p2 * p2
        theta = np.sqrt(theta2)
        if theta < 1e-4:
            a, b, c = 1.0 - theta2 / 6, 0.5 - theta2 / 24, 1.0 / 6 - theta2 / 120
        else:
            a, b, c = np.sin(theta) / theta, (1 - np.cos(theta)) / theta2, (theta - np.sin(theta)) / (theta2 * theta)
        # Vibration rate J_r(phi) dphi/dt = dphi - b phi x dphi + c phi x (phi x dphi).
        x0, x1, x2 = _cross3(p0, p1, p2, pd0, pd1, pd2)
        y0, y1, y2 = _cross3(p0, p1, p2, x0, x1, x2)
        wv0, wv1, wv2 = pd0 - b * x0 + c * y0, pd1 - b * x1 + c * y1, pd2 - b * x2 + c * y2
        # Specific force of the sensor's point in b: f + dw x rho + w x (w x rho) + 2 w x du + d2u.
        r0, r1, r2 = lever[0] + u0, lever[1] + u1, lever[2] + u2
        a0, a1, a2 = _cross3(wd0, wd1, wd2, r0, r1, r2)
        e0, e1, e2 = _cross3(wb0, wb1, wb2, r0, r1, r2)
        g0, g1, g2 = _cross3(wb0, wb1, wb2, e0, e1, e2)
        j0, j1, j2 = _cross3(wb0, wb1, wb2, ud0, ud1, ud2)
        fp0, fp1, fp2 = fb0 + a0 + g0 + 2 * j0 + uu0, fb1 + a1 + g1 + 2 * j1 + uu1, fb2 + a2 + g2 + 2 * j2 + uu2
        # Into s: C_b^s v = Exp(-phi) M^T v = v' - a phi x v' + b phi x (phi x v'), v' = M^T v.
        m0 = mat_bs[0, 0] * wb0 + mat_bs[1, 0] * wb1 + mat_bs[2, 0] * wb2
        m1 = mat_bs[0, 1] * wb0 + mat_bs[1, 1] * wb1 + mat_bs[2, 1] * wb2
        m2 = mat_bs[0, 2] * wb0 + mat_bs[1, 2] * wb1 + mat_bs[2, 2] * wb2
        x0, x1, x2 = _cross3(p0, p1, p2, m0, m1, m2)
        y0, y1, y2 = _cross3(p0, p1, p2, x0, x1, x2)
        ws0, ws1, ws2 = m0 - a * x0 + b * y0 + wv0, m1 - a * x1 + b * y1 + wv1, m2 - a * x2 + b * y2 + wv2
        m0 = mat_bs[0, 0] * fp0 + mat_bs[1, 0] * fp1 + mat_bs[2, 0] * fp2
        m1 = mat_bs[0, 1] * fp0 + mat_bs[1, 1] * fp1 + mat_bs[2, 1] * fp2
        m2 = mat_bs[0, 2] * fp0 + mat_bs[1, 2] * fp1 + mat_bs[2, 2] * fp2
        x0, x1, x2 = _cross3(p0, p1, p2, m0, m1, m2)
        y0, y1, y2 = _cross3(p0, p1, p2, x0, x1, x2)
        wq = weights[q]
        th0 += wq * ws0
        th1 += wq * ws1
        th2 += wq * ws2
        v0 += wq * (m0 - a * x0 + b * y0)
        v1 += wq * (m1 - a * x1 + b * y1)
        v2 += wq * (m2 - a * x2 + b * y2)
    dtheta[k, 0], dtheta[k, 1], dtheta[k, 2] = 0.5 * h * th0, 0.5 * h * th1, 0.5 * h * th2
    dv[k, 0], dv[k, 1], dv[k, 2] = 0.5 * h * v0, 0.5 * h * v1, 0.5 * h * v2


@nb.njit(cache=True, parallel=True)
def _increments_kernel(t, w, dw, f, df, amp_state, amp_rate, freq, ang_amp, lin_amp, ph_ang, ph_lin, lever, mat_bs,
                       nodes, weights, dtheta, dv):
    """Gauss-Legendre integration of the sensor's rate and specific force over each interval (t[k-1], t[k]].

    amp_state (K, n_states) weighs each machine state's tones at each sample and amp_rate is its time
    derivative (a smooth envelope, cubic Hermite between samples). The sines at the nodes come from one sine and
    cosine per interval and tone, turned by the node offsets (angle addition; the turns computed once per value
    of the step, _node_turns). Intervals are independent: they run in parallel, in chunks with their own scratch
    arrays."""
    n_chunks = 64
    size = (t.size - 1 + n_chunks - 1) // n_chunks
    for chunk in nb.prange(n_chunks):
        sin0 = np.zeros((freq.shape[0], freq.shape[1], 6))
        cos0 = np.zeros((freq.shape[0], freq.shape[1], 6))
        vib = np.zeros((5, 3))
        steps = np.full(TURN_SLOTS, np.nan)  # the steps h whose node turns are held, slot by slot
        turns = np.zeros((TURN_SLOTS, freq.shape[0], freq.shape[1], nodes.size, 2))
        n_held = 0
        for k in range(1 + chunk * size, min(t.size, 1 + (chunk + 1) * size)):
            h = t[k] - t[k - 1]
            slot = -1
            for m in range(min(n_held, TURN_SLOTS)):
                if steps[m] == h:
                    slot = m
                    break
            if slot < 0:
                slot = n_held % TURN_SLOTS
                n_held += 1
                steps[slot] = h
                _node_turns(freq, nodes, h, turns[slot])
            _interval(k, t, w, dw, f, df, amp_state, amp_rate, freq, ang_amp, lin_amp, ph_ang, ph_lin, lever, mat_bs,
                      nodes, weights, dtheta, dv, sin0, cos0, vib, turns[slot])


@nb.njit(cache=True)
def _node_turns(freq, nodes, h, turn):
    """Each tone's cosine and sine of om x h at the Gauss-Legendre node offsets x of a step h, into turn
    (n_states, n_tones, n_nodes, 2). They depend on h alone: a run's truth steps take a few dozen values (the last
    bits of t[k] - t[k-1]), so _increments_kernel computes them once per value it meets (TURN_SLOTS at a time)."""
    for st in range(freq.shape[0]):
        for tone in range(freq.shape[1]):
            om = 2 * np.pi * freq[st, tone]
            for q in range(nodes.size):
                x = 0.5 * (nodes[q] + 1.0)
                turn[st, tone, q, 0], turn[st, tone, q, 1] = np.cos(om * x * h), np.sin(om * x * h)


def sensor_increments(t: np.ndarray, w_ib_b: np.ndarray, f_b: np.ndarray, amp_state: np.ndarray,
                      tones: VibrationTones, lever_arm_b: np.ndarray, mat_bs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Increments (K, 3) [rad], [m/s] over (t[k-1], t[k]] (row 0 zero) of a sensor at lever_arm_b [m] with axes
    C_s^b = mat_bs Exp(phi(t)) on a body with samples of w_ib^b [rad/s] and f^b [m/s^2] at times t [s] (K >= 3);
    amp_state (K, n_states) weighs the tones of each state. The time derivatives of w, f and amp_state are taken
    from the samples (`time_derivative`): row k's increment reads rows k - 2 .. k + 1."""
    dtheta, dv = np.zeros_like(w_ib_b), np.zeros_like(f_b)
    amp_state = np.ascontiguousarray(amp_state, float)
    amp_rate = time_derivative(amp_state, t)
    dw = time_derivative(w_ib_b, t, edge_order=2)
    df = time_derivative(f_b, t, edge_order=2)
    _increments_kernel(t, w_ib_b, dw, f_b, df, amp_state, amp_rate, tones.freq_hz, tones.ang_amp, tones.lin_amp,
                       tones.phase_ang, tones.phase_lin, np.asarray(lever_arm_b, float), mat_bs, GL_NODES,
                       GL_WEIGHTS, dtheta, dv)
    return dtheta, dv


def gravity_at_lever_arm_b(shearer: dict[str, np.ndarray], lever_arm_b: np.ndarray) -> np.ndarray:
    """g at the sensor minus g at the body reference point, in b (K, 3): the gravity gradient over the lever
    arm d_n = C_nb r. Across, the vertical turns by d/R (g_E = -gamma d_E / (R_N + h), g_N = -gamma d_N /
    (R_M + h)); up, gamma falls by about 3.1e-6 s^-2 per metre. Left out: gamma's change with latitude over d_N
    (at most 8.2e-9 s^-2 per metre north: 2 ng at 2.5 m) and the second-order terms, (r / R)^2 ~ 1e-14."""
    q_nb = np.column_stack([shearer[f"q_nb_{a}"] for a in "wxyz"])
    lat, h = (np.ascontiguousarray(shearer[name], dtype=float) for name in ("lat", "h"))
    out = np.empty((lat.size, 3))
    _gravity_kernel(q_nb, lat, h, np.asarray(lever_arm_b, dtype=float), out)
    return out


@nb.njit(cache=True, parallel=True)
def _gravity_kernel(q_nb, lat, h, lever, out):
    """gravity_at_lever_arm_b per sample: d_n = C_b^n r, dg_n, and C_n^b dg_n (earth.radii and normal gravity)."""
    for k in nb.prange(lat.size):
        w, x, y, z = q_nb[k, 0], q_nb[k, 1], q_nb[k, 2], q_nb[k, 3]
        d0, d1, d2 = qrot_parts(w, x, y, z, lever[0], lever[1], lever[2])
        r_m, r_n = earth.radii_nb(lat[k])
        gamma = earth.gravity_nb(lat[k], h[k])
        dg0, dg1, dg2 = -gamma * d0 / (r_n + h[k]), -gamma * d1 / (r_m + h[k]), gamma - earth.gravity_nb(lat[k], h[k] + d2)
        out[k, 0], out[k, 1], out[k, 2] = qrot_parts(w, -x, -y, -z, dg0, dg1, dg2)


def mounting_matrix(misalignment_deg) -> np.ndarray:
    """C_s^b at rest from the small mounting angles about x, y, z (DESIGN's Euler order)."""
    m = np.radians(np.asarray(misalignment_deg, float))
    return euler_to_mat(m[0], m[1], m[2])


def _tones(scn: Scenario, rng: np.random.Generator) -> VibrationTones:
    vib = scn.sensors.vibration
    return vibration_tones([vib.idle, vib.cutting_coal, vib.cutting_rock], rng)


def _truth_increments(scn: Scenario, shearer: dict[str, np.ndarray], tones: VibrationTones, vibration: bool
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Error-free increments dtheta [rad] and dv [m/s] (K, 3) in the sensor frame over the truth intervals
    (t[k-1], t[k]] of the truth_shearer columns `shearer` (row 0 zero)."""
    cfg = scn.sensors
    t = shearer["t"]
    w = np.column_stack([shearer[f"w_ib_b_{a}"] for a in "xyz"])
    f = np.column_stack([shearer[f"f_b_{a}"] for a in "xyz"])
    amp_state = (state_envelope(machine_state(scn, shearer["phase"], shearer["s"]), scn.rates.truth_hz) if vibration
                 else np.zeros((t.size, 3)))
    lever = np.asarray(cfg.imu.lever_arm_m, float)
    # f = a - g: the sensor's specific force loses what its own gravity adds over the reference point's.
    f = f - gravity_at_lever_arm_b(shearer, lever)
    return sensor_increments(t, w, f, amp_state, tones, lever, mounting_matrix(cfg.imu.misalignment_deg))


def ideal_increments(scn: Scenario, shearer: dict[str, np.ndarray], rng: np.random.Generator,
                     vibration: bool | None = None) -> dict[str, np.ndarray]:
    """Error-free IMU increments at the truth rate (IMU stream columns: t [s], dtheta_* [rad], dv_* [m/s]; the
    first row is zero), the vibration's tones drawn from rng.

    `vibration` overrides the scenario's sensors.vibration.enabled (False for the round-trip checks).
    """
    on = scn.sensors.vibration.enabled if vibration is None else vibration
    dtheta, dv = _truth_increments(scn, shearer, _tones(scn, rng), on)
    return {"t": shearer["t"], **{f"dtheta_{a}": dtheta[:, i] for i, a in enumerate("xyz")},
            **{f"dv_{a}": dv[:, i] for i, a in enumerate("xyz")}}


class IdealImu:
    """The error-free shearer IMU of a run handed over in TruthChunks (twin.sensors.chunks).

    The vibration's tones are drawn once, from np.random.default_rng([scn.seed, VIBRATION_STREAM]); `vibration`
    overrides the scenario's sensors.vibration.enabled. An IMU sample at scn.sensors.imu.rate_hz sums `group`
    consecutive truth intervals (1 .. group, group + 1 .. 2 group, ...; the run's row 0 is its start) and is
    stamped with the last one's time; the truth intervals of a sample not yet complete are held for the next
    chunk, and those of an incomplete one at the run's end are dropped.
    """

    def __init__(self, scn: Scenario, vibration: bool | None = None):
        self.scn = scn
        self.vibration = scn.sensors.vibration.enabled if vibration is None else vibration
        self.tones = _tones(scn, np.random.default_rng([scn.seed, VIBRATION_STREAM]))
        self.group = round(scn.rates.truth_hz / scn.sensors.imu.rate_hz)
        self._held = (np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))  # t, dtheta, dv of the incomplete sample

    def step(self, chunk: TruthChunk) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU samples the chunk owns: t (N,) [s], dtheta (N, 3) [rad] and dv (N, 3) [m/s] in the sensor
        frame, each over (t - 1 / rate_hz, t]."""
        cols, own = chunk.padded()
        dtheta, dv = _truth_increments(self.scn, cols, self.tones, self.vibration)
        rows = slice(own.start + 1 if chunk.first else own.start, own.stop)
        t, dtheta, dv = (np.concatenate([held, new[rows]]) for held, new in zip(self._held, (cols["t"], dtheta, dv)))
        g = self.group
        n = t.size // g
        self._held = (t[n * g:], dtheta[n * g:], dv[n * g:])
        dtheta, dv = (x[:n * g].reshape(n, g, 3).sum(axis=1) if g > 1 else x for x in (dtheta, dv))
        return t[g - 1:n * g:g], dtheta, dv
