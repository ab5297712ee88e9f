"""Sensor clocks: sample times on a fixed rate grid."""

from __future__ import annotations

import numpy as np


def sample_times(t0: float, t1: float, rate_hz: float) -> np.ndarray:
    """The clock k / rate_hz for every integer k with t0 <= k / rate_hz <= t1 (no accumulated rounding)."""
    k0 = int(np.ceil(t0 * rate_hz - 1e-9))
    k1 = int(np.floor(t1 * rate_hz + 1e-9))
    return np.arange(k0, k1 + 1) / rate_hz
