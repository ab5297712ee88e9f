"""The haulage odometer: a signed pulse counter driven by the shearer's travel (the ODOMETER stream).

Model (001 eqs. 1-4 and 10, scenario section `[sensors.odometer]`)
------------------------------------------------------------------
Frames. 001 defines the MIMU frame b (right = AFC advance, forward = shearer moving direction, up) and the
odometer frame m with the same axis roles; the project's body frame b is the same (x towards the coal wall,
y along the face towards the tailgate, z up), so the odometer's forward axis is y_m and it nominally
coincides with body y. The mounting angles `mounting_deg` = (a_x, a_y, a_z) turn m relative to b with the
project's Euler convention (as the IMU misalignment in twin.sensors.imu): C_m^b = Rz(a_z) Rx(a_x) Ry(a_y). The
odometer's forward axis in b is therefore the second column of C_m^b,

    y_m^b = [-sin a_z cos a_x, cos a_z cos a_x, sin a_x],

and a rotation about y (a_y) leaves it unchanged. The shearer itself moves along body y (it rides the pan
rails), so these angles only shorten the count by their cosine; the mounting 001's filter estimates, between
the IMU and the frame the machine moves in, is the IMU's misalignment (twin.sensors.imu, [sensors.imu]
misalignment_deg), and its truth is twin.pipeline.estimate.true_states.

True travel. The encoder measures travel along its own forward axis (001 eq. 2: v^m = [0, v_y^m, 0]), i.e.
the body's ground velocity projected on y_m,

    v_y^m = (C_b^m C_n^b v^n)_y = y_m^b . (C_n^b v^n),

from the truth's v_n and q_nb. This is |v| cos(angle between the velocity and the odometer axis) and it
carries the sign of the travel (positive towards the tailgate, since b does not flip when the shearer
reverses). We integrate v_y^m (trapezoidal rule at the truth rate) rather than differencing the arc length
s: s is measured along the AFC running line and cannot see the mounting angles, while the integral of the
body velocity is the path the IMU increments are derived from, so an error-free SINS and this odometer agree
exactly up to the modelled odometer errors (what the 001 velocity measurement eq. 19 assumes). The two
differ by far less than a pulse per metre (the body moves along its own y up to the small suspension and
bend motion).

Pulses. The sprocket delivers one pulse per metres_per_pulse * (1 + scale_error) true metres; the counter is
an up/down counter (quadrature), so the cumulative signed count is the floor of the encoder travel in pulse
lengths, plus a random initial phase of the sprocket within its first pulse (the only randomness of the
model, drawn from the passed rng):

    pulses(t) = floor(D_enc(t) / (mpp (1 + scale_error)) + u),   u ~ U[0, 1),   pulses(0) = 0,
    distance  = pulses * mpp                                     (nominal metres per pulse).

So distance = D / (1 + scale_error) up to one pulse: the relative error of the metres per pulse is
`scale_error`, and 001's odometer scale factor error is delta k_D = 1 / (1 + scale_error) - 1 ~= -scale_error.

Slip (fault `odometer_slip`, value = fraction of the travel the encoder misses): each truth-rate travel
increment over (t_{i-1}, t_i] is multiplied by 1 - value * (share of the interval inside the window), so the
count grows slower exactly inside the window; the count lost stays lost after the window (the odometer
reports cumulative distance).

Direction: the haulage drive's direction of travel at the sample time: the sign of v_y^m, 0 while the true
speed along the odometer axis is below STANDSTILL_M_S.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from estimators.nav.rotations import euler_to_mat
from twin.config.scenario import Scenario
from twin.config.sensors import Fault
from twin.sensors.chunks import TruthChunk, halo_rows, split_truth
from twin.sensors.faults import faults_of, window_overlap

STANDSTILL_M_S = 0.005
"""Speed along the odometer axis below which the direction column reads 0 (standing); 0.3 m/min."""


def odometer_axis_b(mounting_deg) -> np.ndarray:
    """The odometer's forward axis y_m in body components: column y of C_m^b = Rz(a_z) Rx(a_x) Ry(a_y)."""
    a = np.radians(np.asarray(mounting_deg, dtype=float))
    return euler_to_mat(a[0], a[1], a[2])[:, 1]


def speed_along_axis(shearer: dict[str, np.ndarray], axis_b: np.ndarray) -> np.ndarray:
    """v_y^m = axis_b . (C_n^b v_n) = (C_b^n axis_b) . v_n at every truth sample."""
    cols = [np.ascontiguousarray(shearer[name], dtype=float) for name in
            ("q_nb_w", "q_nb_x", "q_nb_y", "q_nb_z", "v_n_e", "v_n_n", "v_n_u")]
    out = np.empty(cols[0].size)
    _speed_kernel(*cols, *(float(c) for c in axis_b), out)
    return out


@nb.njit(cache=True, parallel=True)
def _speed_kernel(w, x, y, z, v_e, v_n, v_u, ax, ay, az, out):
    """speed_along_axis per sample: the rows of C_b^n (unit quaternion) applied to the fixed axis, each dotted with
    the matching v_n component."""
    for k in nb.prange(out.size):
        xx, yy, zz = x[k] * x[k], y[k] * y[k], z[k] * z[k]
        xy, xz, yz = x[k] * y[k], x[k] * z[k], y[k] * z[k]
        wx, wy, wz = w[k] * x[k], w[k] * y[k], w[k] * z[k]
        row_e = (1 - 2 * (yy + zz)) * ax + 2 * (xy - wz) * ay + 2 * (xz + wy) * az
        row_n = 2 * (xy + wz) * ax + (1 - 2 * (xx + zz)) * ay + 2 * (yz - wx) * az
        row_u = 2 * (xz - wy) * ax + 2 * (yz + wx) * ay + (1 - 2 * (xx + yy)) * az
        out[k] = row_e * v_e[k] + row_n * v_n[k] + row_u * v_u[k]


class Odometer:
    """The ODOMETER stream (t, distance, pulses, direction) at scn.sensors.odometer.rate_hz, one TruthChunk at a
    time (twin.sensors.chunks). `faults` is the scenario's fault schedule (only odometer_slip acts here).

    Carries the sprocket's pulse phase u (drawn once, at construction: the model's only draw from `rng`) and
    the encoder travel [m] at the next chunk's first truth row (the trapezoid sum of v_y^m from the run's start,
    slip applied)."""

    def __init__(self, scn: Scenario, rng: np.random.Generator, faults: list[Fault]):
        cfg = scn.sensors.odometer
        self.rate_hz = cfg.rate_hz
        self.metres_per_pulse = cfg.metres_per_pulse
        self.pulse_m = cfg.metres_per_pulse * (1.0 + cfg.scale_error)  # true metres per pulse
        self.axis_b = odometer_axis_b(cfg.mounting_deg)
        self.slips = faults_of(faults, "odometer_slip")
        self.phase = rng.random()
        self.travel = 0.0

    def step(self, chunk: TruthChunk) -> dict[str, np.ndarray]:
        """The readings the chunk owns; the truth columns t, v_n_*, q_nb_* are read."""
        cols, own = chunk.padded()
        rows = slice(own.start, own.stop + (not chunk.last))  # its rows and the next chunk's first
        t = np.asarray(cols["t"][rows], dtype=float)
        v_axis = speed_along_axis({k: v[rows] for k, v in cols.items()}, self.axis_b)

        # Encoder travel: trapezoidal increments of v_y^m, reduced inside slip windows, cumulated from the carry.
        step = 0.5 * (v_axis[1:] + v_axis[:-1]) * np.diff(t)
        for fault in self.slips:
            step *= 1.0 - fault.value * window_overlap(t[:-1], t[1:], fault)
        travel = np.cumsum(np.concatenate(([self.travel], step)))
        self.travel = float(travel[-1])

        t_out = chunk.clock(self.rate_hz)
        pulses = np.floor(np.interp(t_out, t, travel) / self.pulse_m + self.phase).astype(np.int64)
        speed = np.interp(t_out, t, v_axis)
        direction = np.where(np.abs(speed) < STANDSTILL_M_S, 0, np.sign(speed)).astype(np.int8)
        return {"t": t_out, "distance": pulses * self.metres_per_pulse, "pulses": pulses, "direction": direction}


def odometer_stream(scn: Scenario, shearer: dict[str, np.ndarray], rng: np.random.Generator,
                    faults: list[Fault]) -> dict[str, np.ndarray]:
    """The ODOMETER stream of a whole run: the Odometer over the truth_shearer columns in one chunk."""
    odometer = Odometer(scn, rng, faults)
    chunk = next(split_truth(shearer, [], halo_rows(scn)), None)
    if chunk is None:  # no truth: no readings
        return {"t": np.zeros(0), "distance": np.zeros(0), "pulses": np.zeros(0, np.int64),
                "direction": np.zeros(0, np.int8)}
    return odometer.step(chunk)
