"""Benchmark: strapdown mechanization throughput with 4-sample coning/sculling compensation.

Target (issue 4): >= 1,000,000 IMU samples/s on this 2-core machine, printed with the ratio to pyins's
integrator (package `python-ins`, a benchmark-only dependency: pip install python-ins) on the same increments
in the same process. The data: 6.4 h at 200 Hz (4.6 M samples) of a slowly turning, accelerating body.
`schuler()` (not printed by main; benchmarks/compare.py's 000 row): 24 h stationary at 34 deg latitude with a
0.01 deg/h z-gyro bias, height held, the mechanization's position and attitude errors against the linear SINS
error model (Schuler 84.4 min and 24 h components); target (issue 4) within 5 %.
Run: python benchmarks/bench_strapdown.py
"""

from __future__ import annotations

import time

import numpy as np

from estimators.sins.strapdown import mechanize

RATE_HZ = 200.0
HOURS = 6.4


def increments(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(n) / RATE_HZ
    dt = 1.0 / RATE_HZ
    dtheta = np.column_stack([1e-3 * np.sin(t / 50), 2e-3 * np.cos(t / 70), 5e-3 * np.sin(t / 300)]) * dt
    dv = np.column_stack([0.05 * np.sin(t / 40), 0.05 * np.cos(t / 60), 9.79 + 0.01 * np.sin(t / 30)]) * dt
    dtheta[0] = dv[0] = 0.0
    return t, dtheta, dv


def ours(t, dtheta, dv) -> float:
    mechanize(t[:1000], dtheta[:1000], dv[:1000], 0.6, 2.0, 36.0, np.zeros(3), np.array([1.0, 0, 0, 0]))
    start = time.perf_counter()
    mechanize(t, dtheta, dv, 0.6, 2.0, 36.0, np.zeros(3), np.array([1.0, 0, 0, 0]), n_samples=4)
    return time.perf_counter() - start


def pyins_time(t, dtheta, dv) -> float | None:
    try:
        import pandas as pd
        from pyins import strapdown
    except ImportError:
        return None
    imu = pd.DataFrame(np.hstack([dtheta, dv]), index=t,
                       columns=["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"])
    pva = pd.Series({"lat": np.degrees(0.6), "lon": np.degrees(2.0), "alt": 36.0, "VN": 0.0, "VE": 0.0,
                     "VD": 0.0, "roll": 0.0, "pitch": 0.0, "heading": 0.0})
    start = time.perf_counter()
    inc = strapdown.compute_increments_from_imu(imu, "increment")
    strapdown.Integrator(pva).integrate(inc)
    return time.perf_counter() - start


def schuler() -> dict:
    """Largest deviation of the mechanization from the linear error model (estimators.sins.error_model.stationary_day),
    north, east position and attitude, in % of the linear model's largest error (`north_pct`, `east_pct`,
    `attitude_pct`), and that largest east error [m]."""
    from estimators.sins.error_model import stationary_day

    d = stationary_day()

    def pct(ours, lin):
        return float(100 * np.abs(ours - lin).max() / np.abs(lin).max())

    return {"north_pct": pct(d["north"], d["lin_north"]), "east_pct": pct(d["east"], d["lin_east"]),
            "attitude_pct": float(100 * np.linalg.norm(d["phi"] - d["lin_phi"], axis=1).max()
                                  / np.linalg.norm(d["lin_phi"], axis=1).max()),
            "east_max_m": float(np.abs(d["lin_east"]).max())}


def main() -> None:
    n = int(HOURS * 3600 * RATE_HZ)
    t, dtheta, dv = increments(n)
    mine = ours(t, dtheta, dv)
    theirs = pyins_time(t, dtheta, dv)
    print(f"samples                 {n:,} ({HOURS} h at {RATE_HZ:.0f} Hz)")
    print(f"ours, 4-sample          {mine:.2f} s = {n / mine:,.0f} samples/s   (target >= 1,000,000/s)")
    if theirs is None:
        print("pyins                   not installed (pip install python-ins)")
    else:
        print(f"pyins Integrator        {theirs:.2f} s = {n / theirs:,.0f} samples/s; ours is {theirs / mine:.1f}x faster")


if __name__ == "__main__":
    main()
