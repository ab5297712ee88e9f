"""IMU error model: what a real sensor reports for ideal increments, given an ImuGrade and a random generator.

For each sample k, the interval (t_k - dt, t_k], and each sensor (gyroscope on dtheta, accelerometer on dv):

    x_k   = M x_k^ideal + (b + beta_k) dt + N sqrt(dt) w_k          w_k ~ N(0, I)
    y_k   = clip(x_k, -R dt, +R dt)                                 saturation of the rate / specific force
    out_k = quantized y_k with the rounding residual carried on      sum(out) = Q(sum(y)): no rounding drift

with, drawn once per run: the turn-on bias b ~ N(0, bias^2 I) and the sensor matrix
M = I + diag(s) + A, s ~ N(0, scale^2), A symmetric with zero diagonal and N(0, nonorth^2) elements (skew-free:
A has no rotation part, the rotation of the triad is the mounting misalignment applied by twin.sensors.imu);
and, per sample, the in-run bias beta, a stationary first-order Gauss-Markov process discretized exactly:

    beta_0 ~ N(0, sigma^2),   beta_k = phi beta_{k-1} + sigma sqrt(1 - phi^2) v_k,   phi = exp(-dt / tau).

beta is held over the interval (its change within dt << tau is neglected). The quantizer keeps the residual r of
each rounding and adds it to the next sample, like a sensor that accumulates increments internally: every
output is a whole number of steps and the running sum stays within half a step of the unquantized running sum
(so a saturated increment can be reported up to, but less than, one step beyond R dt).

Randomness: the generator passed in seeds five independent child streams (constants, gyro drift, gyro noise,
accelerometer drift, accelerometer noise), so the same seed gives the same output and, across grades, the same
underlying unit draws (common random numbers): par4 and par5 differ only by the scale of one noise record.

A run may be fed in blocks (`ImuErrorModel.step`, as a streaming run hands over its truth): beta, the quantizer
residual, the clip counts and the generators carry on from block to block, so any split of a run gives, bit for
bit, the output of one block (`apply_imu_errors`).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba as nb
import numpy as np

from twin.config.imu_grades import ImuGrade

_N_STREAMS = 5
_THREAD_MIN_SAMPLES = 50_000
"""Records at least this long run the gyroscope and accelerometer kernels on two threads."""
_CONST, _GYRO_DRIFT, _GYRO_NOISE, _ACCEL_DRIFT, _ACCEL_NOISE = range(_N_STREAMS)


@dataclass(frozen=True)
class ImuErrorInfo:
    """The error constants drawn for one run (ground truth for tests and estimators).

    gyro_bias [rad/s], accel_bias [m/s^2]: turn-on biases (3,).
    gyro_matrix, accel_matrix: the sensor matrices M (3, 3), reported = M ideal + ...
    gyro_clipped, accel_clipped: number of saturated samples per axis (3,).
    gyro_drift [rad/s], accel_drift [m/s^2]: the Gauss-Markov in-run bias per sample (N, 3), only when asked
    for with keep_drift=True (else None).
    """

    gyro_bias: np.ndarray
    accel_bias: np.ndarray
    gyro_matrix: np.ndarray
    accel_matrix: np.ndarray
    gyro_clipped: np.ndarray
    accel_clipped: np.ndarray
    gyro_drift: np.ndarray | None = None
    accel_drift: np.ndarray | None = None


@nb.njit(cache=True, nogil=True)
def _sensor_kernel(ideal, m, bias_dt, dt, gm_sigma, phi, gm_gen, noise_std, noise_gen, lim, q, out, drift, keep, first,
                   beta, resid, clipped):
    """One sensor's error model over a block of samples (see the module docstring), writing out (N, 3).

    Carried from block to block, read and updated in place: beta (3,) the Gauss-Markov bias [rad/s or m/s^2],
    resid (3,) the quantizer's residual [rad or m/s], clipped (3,) the saturated samples per axis; first says
    whether the block's sample 0 is the run's first (beta_0 is drawn there). The unit normals are drawn here,
    sample by sample and axis by axis, from gm_gen (only if gm_sigma > 0) and noise_gen (only if noise_std > 0);
    drift (N, 3) receives beta when keep is True. Runs without the GIL, so the two sensors can run on two threads.
    """
    n = ideal.shape[0]
    has_gm = gm_sigma > 0.0
    has_noise = noise_std > 0.0
    drive = gm_sigma * np.sqrt(1.0 - phi * phi)
    for k in range(n):
        x0, x1, x2 = ideal[k, 0], ideal[k, 1], ideal[k, 2]
        for i in range(3):
            x = m[i, 0] * x0 + m[i, 1] * x1 + m[i, 2] * x2 + bias_dt[i]
            if has_gm:
                if first and k == 0:
                    beta[i] = gm_sigma * gm_gen.standard_normal()
                else:
                    beta[i] = phi * beta[i] + drive * gm_gen.standard_normal()
                x += beta[i] * dt
                if keep:
                    drift[k, i] = beta[i]
            if has_noise:
                x += noise_std * noise_gen.standard_normal()
            if x > lim:
                x = lim
                clipped[i] += 1
            elif x < -lim:
                x = -lim
                clipped[i] += 1
            if q > 0.0:
                v = x + resid[i]
                y = np.rint(v / q) * q
                resid[i] = v - y
                out[k, i] = y
            else:
                out[k, i] = x


def _check_increments(name: str, a) -> np.ndarray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} contains NaN or infinite values")
    return np.ascontiguousarray(arr)


def _sensor_matrix(scale: float, nonorth: float, z: np.ndarray) -> np.ndarray:
    """I + diag(scale z[:3]) + symmetric off-diagonals nonorth z[3:] (xy, xz, yz)."""
    m = np.eye(3) + np.diag(scale * z[:3])
    for (i, j), zij in zip(((0, 1), (0, 2), (1, 2)), z[3:]):
        m[i, j] = m[j, i] = nonorth * zij
    return m


class _Sensor:
    """One sensor (gyroscope or accelerometer) of a run: its drawn constants, its two generators and the state
    carried between blocks (beta, the quantizer residual, the clip counts, the drift records if kept)."""

    def __init__(self, m, bias, dt, sigma, tau, density, rate_range, quant, gm_gen, noise_gen, keep):
        self.m, self.bias = m, bias
        phi = float(np.exp(-dt / tau)) if sigma > 0.0 else 0.0
        self._consts = (m, bias * dt, dt, float(sigma), phi, gm_gen, density * np.sqrt(dt), noise_gen,
                        rate_range * dt, float(quant))  # rate_range * dt: inf stays inf
        self.beta, self.resid = np.zeros(3), np.zeros(3)
        self.clipped = np.zeros(3, dtype=np.int64)
        self.drift: list[np.ndarray] | None = [] if keep else None

    def run(self, ideal: np.ndarray, first: bool) -> np.ndarray:
        keep = self.drift is not None
        out = np.empty((ideal.shape[0], 3))
        drift = np.zeros((ideal.shape[0], 3)) if keep else np.empty((0, 3))
        _sensor_kernel(ideal, *self._consts, out, drift, keep, first, self.beta, self.resid, self.clipped)
        if keep:
            self.drift.append(drift)
        return out

    def drift_record(self) -> np.ndarray | None:
        if self.drift is None:
            return None
        return np.concatenate(self.drift) if self.drift else np.zeros((0, 3))


class ImuErrorModel:
    """A sensor's errors over a run fed in consecutive blocks of ideal increments (`step`); stepping the run in
    blocks gives, bit for bit, what one step over the whole run gives.

    dt: the sample interval [s]; g: the error budget; rng: the run's generator (advanced here by one draw of four
    seeds, from which the constants are drawn and the per-sample generators made). keep_drift=True also records
    the Gauss-Markov bias per sample (in `info`). `samples` counts the samples stepped so far.
    """

    def __init__(self, dt: float, g: ImuGrade, rng: np.random.Generator, *, keep_drift: bool = False):
        dt = float(dt)
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive finite number, got {dt!r}")
        if not isinstance(g, ImuGrade):
            raise TypeError(f"g must be an ImuGrade, got {type(g).__name__}")
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        seq = np.random.SeedSequence(rng.integers(0, 2 ** 63, size=4))
        gens = [np.random.Generator(np.random.PCG64(child)) for child in seq.spawn(_N_STREAMS)]
        z = gens[_CONST].standard_normal(18)
        self.gyro = _Sensor(_sensor_matrix(g.gyro_scale, g.gyro_nonorth, z[3:9]), g.gyro_bias * z[0:3], dt,
                            g.gyro_bias_instability, g.gyro_bias_tau, g.gyro_arw, g.gyro_range, g.gyro_quant,
                            gens[_GYRO_DRIFT], gens[_GYRO_NOISE], keep_drift)
        self.accel = _Sensor(_sensor_matrix(g.accel_scale, g.accel_nonorth, z[12:18]), g.accel_bias * z[9:12], dt,
                             g.accel_bias_instability, g.accel_bias_tau, g.accel_vrw, g.accel_range, g.accel_quant,
                             gens[_ACCEL_DRIFT], gens[_ACCEL_NOISE], keep_drift)
        self.samples = 0

    def step(self, dtheta, dv) -> tuple[np.ndarray, np.ndarray]:
        """The reported increments (new arrays) for the next block of ideal increments dtheta [rad] and dv [m/s],
        both (N, 3), the samples following those of the previous steps."""
        dtheta = _check_increments("dtheta", dtheta)
        dv = _check_increments("dv", dv)
        if dtheta.shape != dv.shape:
            raise ValueError(f"dtheta and dv must have the same shape, got {dtheta.shape} and {dv.shape}")
        first = self.samples == 0
        if dtheta.shape[0] >= _THREAD_MIN_SAMPLES:
            # The kernel releases the GIL and each sensor owns its streams: same result as the serial path.
            with ThreadPoolExecutor(max_workers=2) as pool:
                gyro_job = pool.submit(self.gyro.run, dtheta, first)
                out_dv = self.accel.run(dv, first)
                out_th = gyro_job.result()
        else:
            out_th = self.gyro.run(dtheta, first)
            out_dv = self.accel.run(dv, first)
        self.samples += dtheta.shape[0]
        return out_th, out_dv

    @property
    def info(self) -> ImuErrorInfo:
        """The constants drawn, the clip counts and (with keep_drift) the drift records of the samples so far."""
        return ImuErrorInfo(self.gyro.bias, self.accel.bias, self.gyro.m, self.accel.m, self.gyro.clipped.copy(),
                            self.accel.clipped.copy(), self.gyro.drift_record(), self.accel.drift_record())


def apply_imu_errors(dtheta, dv, dt: float, g: ImuGrade, rng: np.random.Generator, *, keep_drift: bool = False
                     ) -> tuple[np.ndarray, np.ndarray, ImuErrorInfo]:
    """The increments the sensor reports for ideal increments `dtheta` [rad] and `dv` [m/s], both (N, 3): an
    ImuErrorModel(dt, g, rng, keep_drift=keep_drift) stepped once. Returns new arrays (dtheta, dv) and the drawn
    constants.
    """
    model = ImuErrorModel(dt, g, rng, keep_drift=keep_drift)
    out_th, out_dv = model.step(dtheta, dv)
    return out_th, out_dv, model.info
