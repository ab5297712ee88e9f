"""The survey "sensor": surveyed fixes of the shearer body point at the face ends (001 section 2.2, Fig. 3), and
the face line surveyed at installation (`face_survey_stream`).

Before the first cut the shearer stands at face end A and its pose is surveyed (position and yaw); face end B,
where the first straight cut ends, is surveyed in advance (position only; 001: "the two optimal points
corresponding to both ends of the longwall face can be accurately measured in advance"). With face_ends =
"every_cut" (the default) both ends of every straight cut are fixed: the gate-road survey marks where the face
ends stand after each advance; "first_cut" is 001's experiment. Each fix is the
true body point plus independent N(0, sd) errors in East, North and Up; the start yaw is the true body yaw
plus N(0, sd_yaw). Errors come from 001 Table 1 by default (twin.config.sensors.Survey).

Both are drawn a TruthChunk at a time (twin.sensors.chunks: `Survey`, `FaceSurvey`); `survey_stream` and
`face_survey_stream` are the whole run in one chunk.
"""

from __future__ import annotations

import numpy as np

from estimators.io.metrics import enu_offset_to_geodetic, truth_at
from estimators.nav.rotations import quat_to_euler
from twin.config.scenario import Scenario
from twin.sensors.chunks import TruthChunk, halo_rows, split_truth

Columns = dict[str, np.ndarray]

SURVEY_COLUMNS = ("t", "lat", "lon", "h", "yaw", "sd_horizontal", "sd_vertical", "sd_yaw")
FACE_SURVEY_COLUMNS = ("t", "u", "lat", "lon", "h", "sd_horizontal", "sd_vertical")
CUT_COLUMNS = ("t", "s", "lat", "lon", "h", "q_nb_w", "q_nb_x", "q_nb_y", "q_nb_z")
"""The truth columns FaceSurvey keeps over the first straight cut (those estimators.io.metrics.truth_at reads,
and the arc length s)."""


def _empty(names: tuple[str, ...]) -> Columns:
    return {k: np.zeros(0) for k in names}


class Survey:
    """The SURVEY stream one TruthChunk at a time: the fixes at the start pose (t = 0, with yaw) and the face ends
    (`survey_stream`). Their times are known before the run from `truth_cycles` (None: the start pose only) up to
    `t_last`, the run's last truth time [s]; so all the errors are drawn at construction, in the whole-run order:
    the East/North/Up offsets [m] (n, 3), then the start yaw's error [rad]."""

    def __init__(self, scn: Scenario, truth_cycles: Columns | None, rng: np.random.Generator, t_last: float):
        cfg = scn.sensors.survey
        t = [0.0]
        if truth_cycles is not None and len(truth_cycles["t"]):
            starts, ends = np.asarray(truth_cycles["t"], float), np.asarray(truth_cycles["t_cut_end"], float)
            cuts = range(len(starts)) if cfg.face_ends == "every_cut" else range(1)
            t += [float(x) for k in cuts for x in ((starts[k],) if k else ()) + (ends[k],)]
            if cfg.face_ends == "every_cut":
                t.append(float(truth_cycles["t_end"][-1]))  # where the last cycle leaves the shearer
        self.t = np.asarray([x for x in t if x <= t_last])
        self.sd_horizontal, self.sd_vertical = cfg.sd_horizontal_m, cfg.sd_vertical_m
        sd = np.array([cfg.sd_horizontal_m, cfg.sd_horizontal_m, cfg.sd_vertical_m])
        self.d_enu = rng.normal(size=(self.t.size, 3)) * sd
        self.sd_yaw = np.radians(cfg.sd_yaw_deg)
        self.yaw_error = self.sd_yaw * rng.normal()

    def step(self, chunk: TruthChunk) -> Columns:
        """The fixes whose times the chunk owns; the truth columns t, lat, lon, h, q_nb_* are read."""
        own = chunk.owns(self.t)
        if not own.any():
            return _empty(SURVEY_COLUMNS)
        t = self.t[own]
        true = truth_at(chunk.padded()[0], t)
        lat, lon, h = enu_offset_to_geodetic(self.d_enu[own], true["lat"], true["lon"], true["h"])
        yaw = np.full(t.size, np.nan)
        if own[0]:  # the start pose
            yaw_true = quat_to_euler(true["q_nb"][0])[2]
            yaw[0] = np.angle(np.exp(1j * (yaw_true + self.yaw_error)))  # wrapped to (-pi, pi]
        return {
            "t": t, "lat": lat, "lon": lon, "h": h, "yaw": yaw,
            "sd_horizontal": np.full(t.size, self.sd_horizontal), "sd_vertical": np.full(t.size, self.sd_vertical),
            "sd_yaw": np.where(np.isnan(yaw), np.nan, self.sd_yaw),
        }


def survey_stream(scn: Scenario, truth_shearer: Columns, truth_cycles: Columns | None,
                  rng: np.random.Generator) -> Columns:
    """The SURVEY columns (estimators.io.logformat): the start pose at t = 0 (face end A, with yaw) and face end B
    at the end of cycle 0's straight cut (t_cut_end, yaw NaN) when the run reaches it; with face_ends =
    "every_cut", also both ends of every later straight cut (its start and t_cut_end) and the last face end.
    The Survey over the run's truth in one chunk."""
    survey = Survey(scn, truth_cycles, rng, float(truth_shearer["t"][-1]))
    return survey.step(next(split_truth(truth_shearer, [], halo_rows(scn))))


class FaceSurvey:
    """The FACE_SURVEY stream one TruthChunk at a time (`face_survey_stream`). Keeps the CUT_COLUMNS of the truth
    rows in the first straight cut (truth_cycles' t[0] .. t_cut_end[0]) over the chunks the cut spans and emits
    every point (t = 0) from the chunk in which the cut ends (or the run's last), then drops them; carries the
    run's first arc length s [m], from which u counts. Draws the points' errors from `rng` when it emits them."""

    def __init__(self, scn: Scenario, truth_cycles: Columns | None, rng: np.random.Generator):
        cfg = scn.sensors.survey
        self.active = bool(cfg.face_line and truth_cycles is not None and len(truth_cycles["t"]))
        if self.active:
            self.t_cut = float(truth_cycles["t"][0]), float(truth_cycles["t_cut_end"][0])
        self.pan_length = scn.face.pan_length_m
        self.sd_horizontal, self.sd_vertical = cfg.sd_horizontal_m, cfg.sd_vertical_m
        self.rng = rng
        self.s0 = 0.0
        self.cut: list[Columns] = []

    def step(self, chunk: TruthChunk) -> Columns:
        """The face line's points if the first straight cut ends in this chunk, else none."""
        if not self.active:
            return _empty(FACE_SURVEY_COLUMNS)
        rows = {k: np.asarray(chunk.rows[k], float) for k in CUT_COLUMNS}
        if chunk.first:
            self.s0 = rows["s"][0]
        t0, t1 = self.t_cut
        in_cut = (rows["t"] >= t0) & (rows["t"] <= t1)
        if in_cut.any():
            self.cut.append({k: v[in_cut] for k, v in rows.items()})
        if not (chunk.last or chunk.t_end > t1):
            return _empty(FACE_SURVEY_COLUMNS)
        self.active = False
        parts, self.cut = self.cut, []
        if not parts:  # the run ended before the cut began
            return _empty(FACE_SURVEY_COLUMNS)
        return self._points({k: np.concatenate([part[k] for part in parts]) for k in CUT_COLUMNS})

    def _points(self, cut: Columns) -> Columns:
        """The face line's points from the truth rows of the whole first cut."""
        travel = np.maximum.accumulate(np.abs(cut["s"] - self.s0))  # the straight cut moves one way; stands repeat
        u = np.arange(0.0, travel[-1], self.pan_length)
        if u.size == 0:
            return _empty(FACE_SURVEY_COLUMNS)
        keep = np.concatenate([[True], np.diff(travel) > 0])
        true = truth_at(cut, np.interp(u, travel[keep], cut["t"][keep]))
        sd = np.array([self.sd_horizontal, self.sd_horizontal, self.sd_vertical])
        d_enu = self.rng.normal(size=(u.size, 3)) * sd
        lat, lon, h = enu_offset_to_geodetic(d_enu, true["lat"], true["lon"], true["h"])
        return {"t": np.zeros(u.size), "u": u, "lat": lat, "lon": lon, "h": h,
                "sd_horizontal": np.full(u.size, self.sd_horizontal), "sd_vertical": np.full(u.size, self.sd_vertical)}


def face_survey_stream(scn: Scenario, truth_shearer: Columns, truth_cycles: Columns | None,
                       rng: np.random.Generator) -> Columns:
    """The FACE_SURVEY columns (estimators.io.logformat): the installed face line, one point per chute length of the
    first straight cut, as the shearer body point runs over it (the pans ahead of the shearer do not move before
    it passes, so the first cut runs on the installed line): the true body point where the shearer has covered
    u = k * pan_length_m since the start pose, plus independent N(0, sd) errors in East, North and Up (the
    survey's sd_horizontal_m, sd_vertical_m). Empty when the run has no first straight cut or the face survey is
    off. The FaceSurvey over the run's truth in one chunk."""
    face = FaceSurvey(scn, truth_cycles, rng)
    return face.step(next(split_truth(truth_shearer, [], halo_rows(scn))))
