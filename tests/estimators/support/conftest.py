"""Exact data for the support attitude tests: a unit turning at a constant body rate, so the gyro's rotation over
each step is exact and the accelerometer and magnetometer see gravity and the field without error."""

from __future__ import annotations

import numpy as np

from estimators.nav.rotations import (
    euler_to_quat,
    quat_conj,
    quat_mul,
    quat_rotate,
    rotvec_to_quat,
)
from estimators.support.unit_model import UnitModel

G = np.array([0.0, 0.0, 9.79])
B_N = np.array([-1.5e-6, 2.9e-5, -4.3e-5])  # ENU, declination about -3 deg
DT = 0.01


def exact_unit(k: int = 2000, w_b=(0.02, -0.03, 0.025), start=(0.1, 0.3, -0.2)):
    q0 = euler_to_quat(*start)
    t = np.arange(1, k + 1) * DT
    q = quat_mul(q0, rotvec_to_quat(np.asarray(w_b) * t[:, None]))
    q_bn = quat_conj(q)
    return q0, q, np.tile(w_b, (k, 1)), quat_rotate(q_bn, G), quat_rotate(q_bn, B_N)


def model(var_a=1e-8, var_m=1e-20):
    return UnitModel(np.full(3, var_a), np.full(3, var_m), B_N, np.zeros(3))
