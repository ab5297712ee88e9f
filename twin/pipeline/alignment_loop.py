"""The face alignment loop in the twin (OPC 40561, use case 4.2.6): the face alignment system
(estimators.face.alignment) reads each shear's shearer path as the shear ends and publishes offsets with a sequence
number; the roof support system applies the latest set on a later shear (scenario section [alignment]).

The twin hands the shearer's truth over a cycle at a time (twin.pipeline.simulate: a ride chunk ends in the reversal
stop after each cycle), so the loop sees shear k's path once cycle k's chunk is done: with delay_shears = d, the
offsets of cycle k come from shear k - 1 - d (none before the first). Mode truth feeds the system the true path of
the body reference point over each straight cut (truth_cycles' t to t_cut_end).
"""

from __future__ import annotations

import math

import numpy as np

from estimators.face.alignment import AlignmentConfig, FaceAlignmentSystem, ShearOffsets, path_in_face_frame
from twin.config.push import MAX_OFFSET_WEB_FRACTION
from twin.config.scenario import Scenario
from twin.face import snake
from twin.face.layout import support_stations


def alignment_config(scn: Scenario) -> AlignmentConfig:
    """The alignment system's figures for a scenario's face: the shields' push points along the face, the stroke
    and bend limits twin.config.push.check_offsets holds offsets to, and the [alignment] section's settings."""
    f, a, p = scn.face, scn.alignment, scn.pattern
    bend = math.radians(f.bend_limit_horizontal_deg)
    return AlignmentConfig(
        station_y_m=(support_stations(scn) + 0.5) * f.pan_length_m,
        spacing_m=scn.supports.pans_per_support * f.pan_length_m,
        azimuth_rad=math.radians(f.azimuth_deg),
        max_offset_m=MAX_OFFSET_WEB_FRACTION * f.web_depth_m,
        max_extra_push_m=snake.capacity_m(p.snake_length_pans, f.pan_length_m, bend) - f.web_depth_m,
        curvature_limit_rad=(1 - snake.BEND_FRACTION) * bend,
        gain=a.gain, smoothing_shields=a.smoothing_shields,
        planned_slope=0.0 if a.target == "square" else None, max_turn_rad=math.radians(a.max_turn_deg),
        min_coverage=a.min_coverage,
        end_zone_m=scn.shearer.length_m + (p.push_lag_pans + p.snake_length_pans + 2) * f.pan_length_m,
        shoe_spacing_m=scn.shearer.shoe_spacing_m,
        path_ends_m=(scn.shearer.length_m / 2, f.pan_count * f.pan_length_m - scn.shearer.length_m / 2),
    )


class AlignmentLoop:
    """The loop of one run: `observe` takes the shearer's truth chunks as the twin makes them, `offsets` is the
    roof support system's input for each cycle (twin.face.drift.OffsetSource). Fed a saved run's whole
    truth_shearer table at once, it gives the offsets the twin applied (no simulation)."""

    def __init__(self, scn: Scenario, cuts: list[tuple[float, float]]):
        """`cuts`: each shear's straight cut, start and end times [s] (truth_cycles' t and t_cut_end)."""
        self.cfg = alignment_config(scn)
        self.system = FaceAlignmentSystem(self.cfg)
        self.delay = scn.alignment.delay_shears
        self.cuts = cuts
        self.published: list[ShearOffsets] = []
        """The system's output after each shear, in shear order."""

    def observe(self, chunk: dict[str, np.ndarray]) -> None:
        """Read a truth_shearer chunk: every straight cut that ends in it gives the system a shear."""
        t = chunk["t"]
        for t0, t1 in self.cuts[len(self.published):]:
            if t1 > t[-1]:
                break
            rows = (t >= t0) & (t <= t1)
            p_t = np.column_stack([chunk["p_t_e"][rows], chunk["p_t_n"][rows], chunk["p_t_u"][rows]])
            p_f, _ = path_in_face_frame(p_t, None, self.cfg.azimuth_rad)
            self.published.append(self.system.shear(p_f, np.zeros(p_f.shape[0]), label=f"shear {len(self.published)}"))

    def shears_needed(self, cycle: int) -> int:
        """Shears whose paths the offsets of `cycle` depend on."""
        return max(cycle - self.delay, 0)

    def offsets(self, cycle: int, pans: np.ndarray) -> np.ndarray | None:
        """The latest offsets published from shear cycle - 1 - delay or earlier (None before any)."""
        k = cycle - 1 - self.delay
        if k < 0:
            return None
        if k >= len(self.published):
            raise RuntimeError(f"face alignment: shear {k}'s path was not handed over before cycle {cycle}")
        return self.published[k].offsets_m


def alignment_table(scn: Scenario, cycle_start_s: np.ndarray, offsets_m: np.ndarray,
                    published: list[ShearOffsets]) -> dict[str, np.ndarray]:
    """The alignment stream's columns (estimators.io.logformat.ALIGNMENT) of a run: per cycle (starting at
    `cycle_start_s`) and support, the offset applied (`offsets_m`, cycles x supports) and the alignment system's set
    among it (published[k - 1 - delay] for cycle k: its sequence number and one-sigma)."""
    n_cyc, n_sup = offsets_m.shape
    delay = scn.alignment.delay_shears
    seq = np.zeros((n_cyc, n_sup), np.int32)
    sd = np.full((n_cyc, n_sup), np.nan)
    for k in range(n_cyc):
        if published and 0 <= k - 1 - delay < len(published):
            shear = published[k - 1 - delay]
            seq[k], sd[k] = shear.sequence, shear.sd_m
    cycle = np.repeat(np.arange(n_cyc, dtype=np.int32), n_sup)
    return {"t": np.asarray(cycle_start_s, float)[cycle], "cycle": cycle,
            "support": np.tile(np.arange(n_sup, dtype=np.int32), n_cyc), "offset": offsets_m.ravel(),
            "sd": sd.ravel(), "sequence": seq.ravel()}
