"""The results of 000's SINS experiments (twin.papers.sins_experiments): error time series, figures, table rows."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from estimators.nav.rotations import quat_conj, quat_mul, quat_to_rotvec

DEG = np.pi / 180


@dataclass
class Series:
    """One error time series: quantity (attitude, velocity, position, coning, sigma) of a case, (K, 3) in SI.

    group: the sub-experiment ("" when there is one; "table2", "mti-g-700/ekf", ...); variant: what is compared
    within it ("uncompensated", "compensated"; "" when nothing is)."""

    group: str
    quantity: str
    variant: str
    t: np.ndarray
    values: np.ndarray


@dataclass
class ExperimentResult:
    name: str
    experiment: str
    ours: dict
    paper: dict
    table: list[str]
    series: list[Series] = field(default_factory=list)
    timing: dict = field(default_factory=dict)  # wall-clock figures (timing.json, not metrics.json)


def attitude_error(q_true: np.ndarray, q_est: np.ndarray) -> np.ndarray:
    """Error angles phi (K, 3) [rad] in n with C_true = Exp(phi) C_est (to first order C_est = (I - [phi x]) C_true)."""
    return quat_to_rotvec(quat_mul(q_true, quat_conj(q_est)))


def reduction_pct(uncompensated, compensated) -> np.ndarray:
    return 100.0 * (1.0 - np.asarray(compensated) / np.asarray(uncompensated))


def row(label: str, values, fmt: str | list[str], width: int = 12) -> str:
    """One table row; fmt is a format spec for all values or one per value."""
    fmts = [fmt] * len(values) if isinstance(fmt, str) else fmt
    return f"  {label:34s}" + "".join(f"{v:{width}{f}}" for v, f in zip(values, fmts))


def header(names) -> str:
    return f"  {'':34s}" + "".join(f"{n:>12s}" for n in names)
