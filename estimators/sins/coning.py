"""N-sample coning and sculling compensation coefficients (000 eqs. 57-61 and 68-70).

Over an update interval T = N h with sub-interval increments theta_1..theta_N, the simplified N-sample
algorithm writes the rotation vector as

    phi = sum theta_i + (sum_{i<N} k_i theta_i) x theta_N

and, by the coning/sculling duality, the sculling term as sum_{i<N} k_i (theta_i x dv_N + dv_i x theta_N).
The k_i are fixed by pure coning motion (rate amplitude a at frequency W, x = W h): the true correction
1/2 int alpha x w dt has z component (a/W)^2 (N x - sin N x) / 2, the algorithm's
sum_i k_i 4 sin^2(x/2) sin((N - i) x) (a/W)^2, and the k_i make their Taylor series agree up to x^(2N - 1), so
the residual drift is O(x^(2N+1)). `coefficients` solves those N - 1 linear equations in exact rational
arithmetic. It gives 2/3 for N = 2, (9/20, 27/20) for N = 3 and (54/105, 92/105, 214/105) for N = 4.

000 eq. 70 prints the four-sample sculling coefficients as 54/105, 92/105, 214/105 on the angle side and
54/105, 29/105, 214/105 on the velocity side; duality requires the same coefficients on both sides, and the
derivation here gives 92/105, so 29/105 is a typographical error in the paper.
"""

from __future__ import annotations

from fractions import Fraction
from functools import cache
from math import factorial

import numpy as np

MAX_SAMPLES = 5


def _sin_series(scale: int, order: int) -> list[Fraction]:
    """Taylor coefficients of sin(scale x) up to x^order."""
    out = [Fraction(0)] * (order + 1)
    for k in range(1, order + 1, 2):
        out[k] = Fraction((-1) ** (k // 2) * scale ** k, factorial(k))
    return out


def _mul(a: list[Fraction], b: list[Fraction], order: int) -> list[Fraction]:
    out = [Fraction(0)] * (order + 1)
    for i, ai in enumerate(a):
        if ai:
            for j, bj in enumerate(b[: order + 1 - i]):
                out[i + j] += ai * bj
    return out


@cache
def coefficients_exact(n: int) -> tuple[Fraction, ...]:
    """The N - 1 coefficients k_i as exact fractions (N = 1: none)."""
    if not 1 <= n <= MAX_SAMPLES:
        raise ValueError(f"coning: {n} sub-samples; 1 to {MAX_SAMPLES} are supported")
    if n == 1:
        return ()
    order = 2 * n - 1
    # 4 sin^2(x/2) = 2 - 2 cos x
    cos_part = [Fraction(0)] * (order + 1)
    for k in range(0, order + 1, 2):
        cos_part[k] = Fraction((-1) ** (k // 2), factorial(k))
    four_sin2 = [Fraction(2 if k == 0 else 0) - 2 * c for k, c in enumerate(cos_part)]
    columns = [_mul(four_sin2, _sin_series(n - i, order), order) for i in range(1, n)]
    target = [Fraction(0)] * (order + 1)
    target[1] = Fraction(n, 2)
    for k, c in enumerate(_sin_series(n, order)):
        target[k] -= c / 2
    rows = list(range(3, order + 1, 2))  # x^3 .. x^(2N-1): N - 1 equations
    a = [[columns[j][r] for j in range(n - 1)] for r in rows]
    b = [target[r] for r in rows]
    return tuple(_solve(a, b))


def _solve(a: list[list[Fraction]], b: list[Fraction]) -> list[Fraction]:
    """Gauss-Jordan elimination in exact arithmetic."""
    m = len(b)
    aug = [row[:] + [b[i]] for i, row in enumerate(a)]
    for col in range(m):
        pivot = next(r for r in range(col, m) if aug[r][col] != 0)
        aug[col], aug[pivot] = aug[pivot], aug[col]
        aug[col] = [v / aug[col][col] for v in aug[col]]
        for r in range(m):
            if r != col and aug[r][col] != 0:
                factor = aug[r][col]
                aug[r] = [v - factor * w for v, w in zip(aug[r], aug[col])]
    return [aug[r][m] for r in range(m)]


def coefficients(n: int) -> np.ndarray:
    """The coefficients k_1..k_{N-1} as floats (empty for N = 1)."""
    return np.array([float(k) for k in coefficients_exact(n)], dtype=float)


def coning_drift(n: int, half_cone_rad: float, cone_rate_rad_s: float, h: float) -> float:
    """Closed-form drift rate [rad/s] of the N-sample algorithm under coning motion (about the cone axis):
    the true correction minus the algorithm's, per update interval, divided by its length N h.

    For the coning of 000 eq. 55 the rate amplitude across the cone axis is W sin(alpha)."""
    x = cone_rate_rad_s * h
    amp2 = (np.sin(half_cone_rad)) ** 2  # (a / W)^2
    exact = 0.5 * (n * x - np.sin(n * x))
    algo = sum(k * 4 * np.sin(x / 2) ** 2 * np.sin((n - i) * x) for i, k in enumerate(coefficients(n), start=1))
    return amp2 * (exact - algo) / (n * h)
