"""What a user knows of the face and its push-ram sensors (`RamLayout`), the input of the per-support ram checks
(estimators.faults.ram_checks), and the reading error and tolerances that follow from it."""

from __future__ import annotations

import math
from dataclasses import dataclass

from estimators.faults.ram_levels import change_sigma, level_tolerance

STROKE_TOLERANCE = 0.03
"""Share of the commanded stroke that a healthy stroke may differ by (ram line geometry)."""
NEIGHBOURS = 4
"""Other supports in each leave-one-out quadratic prediction of a support's pan advance."""


@dataclass(frozen=True)
class RamLayout:
    """What a user knows of the face and its push-ram sensors (SI units).

    stroke_m is the commanded stroke of every push and advance: the web depth (scenario face.web_depth_m).
    pan_length_m defaults to spacing_m (one support per pan); bend_limit_deg is the AFC's horizontal bend limit
    between pans; stroke_tolerance_m defaults to STROKE_TOLERANCE * stroke_m."""

    n_supports: int
    spacing_m: float
    stroke_m: float
    noise_m: float
    resolution_m: float = 0.0
    pan_length_m: float | None = None
    bend_limit_deg: float = 1.0
    stroke_tolerance_m: float | None = None

    def __post_init__(self):
        checks = [
            (int(self.n_supports) == self.n_supports and self.n_supports >= NEIGHBOURS + 1, "n_supports",
             f"an integer >= {NEIGHBOURS + 1} (the neighbour check needs {NEIGHBOURS} neighbours)"),
            (self.spacing_m > 0, "spacing_m", "positive"),
            (self.stroke_m > 0, "stroke_m", "positive (the web depth)"),
            (self.noise_m >= 0, "noise_m", "non-negative"),
            (self.resolution_m >= 0, "resolution_m", "non-negative"),
            (self.pan_length_m is None or self.pan_length_m > 0, "pan_length_m", "positive or None"),
            (0 < self.bend_limit_deg < 90, "bend_limit_deg", "in (0, 90)"),
            (self.stroke_tolerance_m is None or self.stroke_tolerance_m >= 0, "stroke_tolerance_m",
             "non-negative or None"),
        ]
        for ok, name, what in checks:
            value = getattr(self, name)
            if not (ok and (value is None or math.isfinite(value))):
                raise ValueError(f"RamLayout.{name} = {value!r}: must be {what}")

    @property
    def sigma_m(self) -> float:
        """One-sigma error of a reading: noise and quantization."""
        return math.sqrt(self.noise_m ** 2 + self.resolution_m ** 2 / 12.0)

    @property
    def bend_m(self) -> float:
        """Largest second difference of the pan advance across three neighbouring supports [m]."""
        pan = self.spacing_m if self.pan_length_m is None else self.pan_length_m
        return self.spacing_m ** 2 * math.tan(math.radians(self.bend_limit_deg)) / pan

    @property
    def stroke_tol_m(self) -> float:
        return STROKE_TOLERANCE * self.stroke_m if self.stroke_tolerance_m is None else self.stroke_tolerance_m

    @property
    def change_sigma_m(self) -> float:
        """Sigma of the level-change test (estimators.faults.ram_levels.change_sigma)."""
        return change_sigma(self.sigma_m)

    @property
    def level_tol_m(self) -> float:
        """Plateau tolerance (estimators.faults.ram_levels.level_tolerance, as estimators.shearer.cpoem.ram_stroke)."""
        return level_tolerance(self.sigma_m)
