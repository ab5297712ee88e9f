"""Gradient-descent tuning of the rate-noise variances of Q of 002's UKF (002_5cc0b59ad045ffaa.txt section 3.1,
eq. 35, steps 1.1-1.4): the GD-UKF is the UKF (estimators.support.filters_002) with the variances this finds on a
reference segment with known truth."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.support.batch import batch_inputs
from estimators.support.filters_002 import SIGMA_002, SigmaSettings, ukf
from estimators.support.unit_model import UnitModel, euler_errors, initial_attitude


@dataclass
class Tuning:
    """Result of `tune_q`: the tuned variances [(rad/s)^2], the objective [rad] and variances per iteration."""

    var_w: np.ndarray
    objective: list[float] = field(default_factory=list)
    history: list[np.ndarray] = field(default_factory=list)
    converged: bool = False


def objective(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """002 eq. 35: RMSE of the estimate against the truth, here over pitch, roll and yaw together [rad];
    per filter of the batch (leading axis)."""
    e = euler_errors(q_true, q_est)
    return np.sqrt(np.mean(e ** 2, axis=tuple(range(1, e.ndim))))


def tune_q(gyro, accel, mag, dt: float, model: UnitModel, q_true: np.ndarray, var_w0, q0=None,
           sigma: SigmaSettings = SIGMA_002, iterations: int = 30, tol: float = 1e-4,
           step: float = 0.1, line: np.ndarray | None = None) -> Tuning:
    """Gradient descent on the variances of Q against a reference segment with truth q_true (K, 4), 002 steps
    1.1-1.4: the gradient by central differences in log(var) (step `step`), a line search over the factors
    `line` (default 2^1 .. 2^-6 of the unit step along -g/|g|, the best kept), stop when |g| < tol f, when the
    best does not lower f by a relative `tol`, or after `iterations`. Each batch of Q candidates is one call of the
    UKF kernel. f never rises: a step is taken only if it lowers f.
    """
    gyro, accel, mag = batch_inputs(gyro, accel, mag)
    if gyro.shape[0] != 1:
        raise ValueError("tune_q works on one unit's reference segment")
    line = 2.0 ** -np.arange(-1, 7) if line is None else np.asarray(line, float)
    if q0 is None:
        q0 = initial_attitude(accel, mag, model)[0]
    theta = np.log(np.asarray(var_w0, float))

    def run(thetas: np.ndarray) -> np.ndarray:
        n = thetas.shape[0]
        est = ukf(np.broadcast_to(gyro, (n,) + gyro.shape[1:]), np.broadcast_to(accel, (n,) + gyro.shape[1:]),
                  np.broadcast_to(mag, (n,) + gyro.shape[1:]), dt, model, np.exp(thetas), q0=q0, sigma=sigma)
        return objective(np.broadcast_to(q_true, est.shape), est)

    f = float(run(theta[None])[0])
    out = Tuning(np.exp(theta), [f], [np.exp(theta)])
    for _ in range(iterations):
        probes = theta + step * np.concatenate([np.eye(3), -np.eye(3)])
        fp = run(probes)
        g = (fp[:3] - fp[3:]) / (2 * step)
        gn = float(np.linalg.norm(g))
        if gn < tol * f:
            out.converged = True
            break
        cands = theta - line[:, None] * (g / gn)
        fc = run(cands)
        best = int(np.argmin(fc))
        if not fc[best] < f * (1 - tol):
            out.converged = True
            break
        theta, f = cands[best], float(fc[best])
        out.objective.append(f)
        out.history.append(np.exp(theta))
    out.var_w = np.exp(theta)
    return out
