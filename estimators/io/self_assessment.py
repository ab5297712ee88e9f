"""What an estimate says of itself, needing no truth (a real face's log has none): its span, distance, final and
largest one-sigma, the epochs each flag marks, and its residuals against the survey's fixes; over rows pushed a
block at a time (`SelfAssessment`) or a whole estimate (`self_assessment`). Tables as estimators.io.metrics takes
them."""

from __future__ import annotations

import numpy as np

from estimators.io.logformat import (
    FLAG_COVARIANCE_REPAIRED,
    FLAG_ISOLATED,
    FLAG_MAG,
    FLAG_POSITION,
    FLAG_SKIPPED,
    FLAG_UNHEALTHY,
    FLAG_VELOCITY,
    FLAG_ZUPT,
)
from estimators.io.metrics import ENU, column, columns, geodetic_to_enu_offset

FLAG_COUNTS = {"velocity_updates": FLAG_VELOCITY, "position_fixes": FLAG_POSITION, "zupts": FLAG_ZUPT,
               "skipped": FLAG_SKIPPED, "covariance_repaired": FLAG_COVARIANCE_REPAIRED, "mag_updates": FLAG_MAG,
               "isolated": FLAG_ISOLATED, "unhealthy": FLAG_UNHEALTHY}
"""The flag bits `self_assessment` counts, by the name it gives their count."""


def _finite(x) -> float | None:
    """x as a float, None when not finite (JSON has no NaN)."""
    x = float(x)
    return x if np.isfinite(x) else None


def _residual(row: dict[str, np.ndarray], fix: dict[str, float], t_fix: float) -> dict:
    """survey_residuals' entry for one estimate row (lat, lon, h, t, sd_pos (3,)) against one fix."""
    d = geodetic_to_enu_offset(row["lat"], row["lon"], row["h"], fix["lat"], fix["lon"], fix["h"])[0]
    var = row["sd_pos"] ** 2 + np.array([fix["sd_horizontal"]] * 2 + [fix["sd_vertical"]]) ** 2
    return {"t_fix": float(t_fix), "t_estimate": float(row["t"][0]), "east": float(d[0]), "north": float(d[1]),
            "up": float(d[2]), "horizontal": float(np.hypot(d[0], d[1])),
            "nis": _finite(np.sum(d ** 2 / var)) if np.all(var > 0) else None}


class SelfAssessment:
    """`self_assessment` over an estimate's rows pushed in blocks of increasing time (a pass at a time): the
    counts, sums and extremes carried, with the last row (the step into the next block, and the estimate just
    before a fix at a block's start). One block gives self_assessment's numbers bit for bit; more sum the
    distance block by block (the last bits may differ)."""

    FIX_KEYS = ("lat", "lon", "h", "sd_horizontal", "sd_vertical")

    def __init__(self, survey=None):
        self.survey = survey
        self.t_fix = column(survey, "t") if survey is not None else np.zeros(0)
        self.residuals: dict[int, dict] = {}  # by the fix's row, once its estimate row has come
        self.samples, self.distance_m = 0, 0.0
        self.max_sd_h, self.finite_sd_h = np.nan, False  # the largest horizontal sigma (NaN skipped); any finite
        self.flags = dict.fromkeys(FLAG_COUNTS, 0)
        self.t_start, self.last = float("nan"), None  # the last row: t, lat, lon, h (1,), sd_pos (3,), sd_att

    def push(self, estimate) -> SelfAssessment:
        t = column(estimate, "t")
        if not t.size:
            return self
        lat, lon, h = (column(estimate, k) for k in ("lat", "lon", "h"))
        sd_pos, sd_att = columns(estimate, "sd_pos"), np.degrees(columns(estimate, "sd_att"))
        if self.last is None:
            self.t_start = float(t[0])
            steps = geodetic_to_enu_offset(lat[1:], lon[1:], h[1:], lat[:-1], lon[:-1], h[:-1])
        else:
            steps = geodetic_to_enu_offset(lat, lon, h, *(np.concatenate([self.last[k], v[:-1]])
                                                          for k, v in (("lat", lat), ("lon", lon), ("h", h))))
        self.distance_m += np.linalg.norm(steps, axis=1).sum()
        sd_h = np.hypot(sd_pos[:, 0], sd_pos[:, 1])
        if not np.isnan(sd_h).all():
            self.max_sd_h = np.fmax(self.max_sd_h, np.nanmax(sd_h))
        self.finite_sd_h |= bool(np.isfinite(sd_h).any())
        flags = column(estimate, "flags").astype(np.int64)
        for name, bit in FLAG_COUNTS.items():
            self.flags[name] += int(np.count_nonzero(flags & bit))
        self.samples += t.size
        for k in np.flatnonzero(self.t_fix <= t[-1]):  # the fixes whose last estimate row before them has come
            if k in self.residuals:
                continue
            i = int(np.searchsorted(t, self.t_fix[k], side="left")) - 1
            row = self.last if i < 0 else {"t": t[i:i + 1], "lat": lat[i:i + 1], "lon": lon[i:i + 1],
                                           "h": h[i:i + 1], "sd_pos": sd_pos[i]}
            self.residuals[k] = row and _residual(row, self._fix(k), self.t_fix[k])
        self.last = {"t": t[-1:], "lat": lat[-1:], "lon": lon[-1:], "h": h[-1:], "sd_pos": sd_pos[-1],
                     "sd_att": sd_att[-1]}
        return self

    def _fix(self, k: int) -> dict[str, float]:
        return {key: column(self.survey, key)[k] for key in self.FIX_KEYS}

    def result(self) -> dict:
        if self.last is None:
            return {"samples": 0}
        sd_pos, sd_att = self.last["sd_pos"], self.last["sd_att"]
        out = {"samples": self.samples, "t_start": self.t_start, "t_end": float(self.last["t"][0]),
               "distance_m": float(self.distance_m),
               "final_sd_pos_m": {a: _finite(v) for a, v in zip(("east", "north", "up"), sd_pos)},
               "final_sd_att_deg": {a: _finite(v) for a, v in zip(ENU, sd_att)},
               "final_sd_horizontal_m": _finite(np.hypot(sd_pos[0], sd_pos[1])),
               "max_sd_horizontal_m": _finite(self.max_sd_h) if self.finite_sd_h else None,
               "flags": dict(self.flags)}
        if self.survey is not None:
            late = {k: _residual(self.last, self._fix(k), self.t_fix[k])
                    for k in range(self.t_fix.size) if k not in self.residuals}
            out["survey_residuals"] = [r for _, r in sorted((self.residuals | late).items()) if r]
        return out


def survey_residuals(estimate, survey) -> list[dict]:
    """The estimate against each surveyed fix after its first epoch, before the fix is applied: the estimate at
    the last epoch before the fix's time minus the surveyed point [m] East/North/Up, and its normalized square
    over the estimate's and the survey's variances (chi-square with 3 dof for a consistent filter; None without
    sigmas). A smoother's rows already hold the fix, so its residuals are small by construction."""
    return SelfAssessment(survey).push(estimate).result().get("survey_residuals", [])


def self_assessment(estimate, survey=None) -> dict:
    """What an estimate (ESTIMATE columns) says of itself, needing no truth: its span, the distance along its path
    [m] (3-D, summed over the epochs), its final and largest one-sigma (position [m] E/N/U and horizontal,
    attitude [deg]; None without covariance), how many epochs set each flag of FLAG_COUNTS, and its residuals
    against the survey's fixes (`survey_residuals`, with a survey table). In blocks: `SelfAssessment`."""
    return SelfAssessment(survey).push(estimate).result()
