"""The survey "sensor": surveyed fixes of the shearer body point at the face ends (001 section 2.2, Fig. 3), and
the face line surveyed at installation (`face_survey_stream`).

Before the first cut the shearer stands at face end A and its pose is surveyed (position and yaw); face end B,
where the first straight cut ends, is surveyed in advance (position only; 001: "the two optimal points
corresponding to both ends of the longwall face can be accurately measured in advance"). With face_ends =
"every_cut" (the default) both ends of every straight cut are fixed: the gate-road survey marks where the face
ends stand after each advance; "first_cut" is 001's experiment. Each fix is the
true body point plus independent N(0, sd) errors in East, North and Up; the start yaw is the true body yaw
plus N(0, sd_yaw). Errors come from 001 Table 1 by default (twin.config.sensors.Survey).
"""

from __future__ import annotations

import numpy as np

from estimators.io.metrics import enu_offset_to_geodetic, truth_at
from estimators.nav.rotations import quat_to_euler
from twin.config.scenario import Scenario


def survey_stream(scn: Scenario, truth_shearer: dict[str, np.ndarray], truth_cycles: dict[str, np.ndarray] | None,
                  rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The SURVEY columns (estimators.io.logformat): the start pose at t = 0 (face end A, with yaw) and face end B
    at the end of cycle 0's straight cut (t_cut_end, yaw NaN) when the run reaches it; with face_ends =
    "every_cut", also both ends of every later straight cut (its start and t_cut_end) and the last face end."""
    cfg = scn.sensors.survey
    t = [0.0]
    if truth_cycles is not None and len(truth_cycles["t"]):
        starts, ends = np.asarray(truth_cycles["t"], float), np.asarray(truth_cycles["t_cut_end"], float)
        cuts = range(len(starts)) if cfg.face_ends == "every_cut" else range(1)
        t += [float(x) for k in cuts for x in ((starts[k],) if k else ()) + (ends[k],)]
        if cfg.face_ends == "every_cut":
            t.append(float(truth_cycles["t_end"][-1]))  # where the last cycle leaves the shearer
    t = np.asarray([x for x in t if x <= truth_shearer["t"][-1]])
    true = truth_at(truth_shearer, t)
    sd = np.array([cfg.sd_horizontal_m, cfg.sd_horizontal_m, cfg.sd_vertical_m])
    lat, lon, h = enu_offset_to_geodetic(rng.normal(size=(t.size, 3)) * sd, true["lat"], true["lon"], true["h"])
    sd_yaw = np.radians(cfg.sd_yaw_deg)
    yaw = np.full(t.size, np.nan)
    yaw_true = quat_to_euler(true["q_nb"][0])[2]
    yaw[0] = np.angle(np.exp(1j * (yaw_true + sd_yaw * rng.normal())))  # wrapped to (-pi, pi]
    return {
        "t": t, "lat": lat, "lon": lon, "h": h, "yaw": yaw,
        "sd_horizontal": np.full(t.size, cfg.sd_horizontal_m), "sd_vertical": np.full(t.size, cfg.sd_vertical_m),
        "sd_yaw": np.where(np.isnan(yaw), np.nan, sd_yaw),
    }



def face_survey_stream(scn: Scenario, truth_shearer: dict[str, np.ndarray], truth_cycles: dict[str, np.ndarray] | None,
                       rng: np.random.Generator) -> dict[str, np.ndarray]:
    """The FACE_SURVEY columns (estimators.io.logformat): the installed face line, one point per chute length of the
    first straight cut, as the shearer body point runs over it (the pans ahead of the shearer do not move before
    it passes, so the first cut runs on the installed line): the true body point where the shearer has covered
    u = k * pan_length_m since the start pose, plus independent N(0, sd) errors in East, North and Up (the
    survey's sd_horizontal_m, sd_vertical_m). Empty when the run has no first straight cut or the face survey is
    off."""
    cfg = scn.sensors.survey
    empty = {k: np.zeros(0) for k in ("t", "u", "lat", "lon", "h", "sd_horizontal", "sd_vertical")}
    if not cfg.face_line or truth_cycles is None or not len(truth_cycles["t"]):
        return empty
    t_truth, s = np.asarray(truth_shearer["t"]), np.asarray(truth_shearer["s"], float)
    cut = (t_truth >= truth_cycles["t"][0]) & (t_truth <= truth_cycles["t_cut_end"][0])
    travel = np.abs(s[cut] - s[0])
    travel = np.maximum.accumulate(travel)  # the straight cut moves one way; stands repeat values
    u = np.arange(0.0, travel[-1], scn.face.pan_length_m)
    if u.size == 0:
        return empty
    keep = np.concatenate([[True], np.diff(travel) > 0])
    t = np.interp(u, travel[keep], t_truth[cut][keep])
    true = truth_at(truth_shearer, t)
    sd = np.array([cfg.sd_horizontal_m, cfg.sd_horizontal_m, cfg.sd_vertical_m])
    lat, lon, h = enu_offset_to_geodetic(rng.normal(size=(t.size, 3)) * sd, true["lat"], true["lon"], true["h"])
    return {"t": np.zeros(u.size), "u": u, "lat": lat, "lon": lon, "h": h,
            "sd_horizontal": np.full(u.size, cfg.sd_horizontal_m), "sd_vertical": np.full(u.size, cfg.sd_vertical_m)}
