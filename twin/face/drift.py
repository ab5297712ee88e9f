"""A face that drifts: pushes by ram stroke from the supports, supports that follow their pans along the face, and
the per-support offsets of face alignment (OPC 40561, use case 4.2.6) from the scenario and the Python API.

Stroke control (`supports.push.control = "stroke"`, twin.config.push). A real face pushes a pan by extending its ram
from the support a stroke, stopped when the stroke sensor reads the target, and advances a support by closing its
ram to its rest length. With the controller's targets (twin.face.pushadvance: pan p_j and support a_j advance since
the start, metres) and each ram's rest length L_j at the start, the ram goals are

    push:     L_j + p_j - a_j(last advance) + e_j,      e_j ~ N(overtravel, stop_noise)   (drawn per new target)
    advance:  L_j + p_j - a_j                            (the ram closed, the support up to its pan)

so every error of a push, a shortfall, a pan pulled back by an advancing support, or the floor (a ram's length is
not its pan's advance where the floor tilts it) stays in the face: the line's straightness error walks from cycle to
cycle. Supports follow their pans along the face: an advancing support comes to stand square behind its pan's ram
point, so the pans' along-face slide during the pushes (MuJoCo: gravity on the seam dip, the snake's pull through
the connectors) adds up as creep, and the supports stay with their pans instead of standing at fixed stations.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from twin.config.push import check_offsets, offset_limits
from twin.config.scenario import Scenario, support_count
from twin.face.layout import pan_axes, support_stations

if TYPE_CHECKING:
    from twin.face.window import FaceState

STOP_NOISE_STREAM = 25
"""Random stream of the push stop errors, apart from the floor's and the face's so that they change nothing else."""
SUPPORT_DEADBAND_M = 5e-3
"""A support this far short of its advance (its ram this much longer than closed) advances again at the next event."""

OffsetSource = Callable[[int, np.ndarray], "np.ndarray | None"]
"""The roof support system's input for the next shear: called at the start of each cycle with the cycle number and
the pans' states (N, 6: x, y, z, yaw, pitch, roll in the face frame F, as pushed so far), returns one offset per
support [m, positive towards the coal wall] added to that cycle's push (None: none)."""


def cycle_offsets(scn: Scenario, cycle: int, pans: np.ndarray, *sources: OffsetSource | None) -> np.ndarray:
    """The offsets of a cycle: the scenario's (supports.push.offsets) plus each source's (the API's, the face
    alignment loop's), checked (ValueError, one line) as the scenario's are."""
    n, limits = support_count(scn), offset_limits(scn)
    offsets = sum((np.asarray(e.offsets_m, float) for e in scn.supports.push.offsets if e.cycle == cycle),
                  np.zeros(n))
    for source in sources:
        extra = None if source is None else source(cycle, pans.copy())
        if extra is not None:
            check_offsets(extra, n, **limits)
            offsets = offsets + np.asarray(extra, float)
            check_offsets(offsets, n, **limits)
    return offsets


def stand_supports(scn: Scenario, ram_site_local: np.ndarray, state: FaceState, sups: np.ndarray) -> None:
    """Stand supports `sups` square behind their pans along the face: at the y of their pans' ram points."""
    st = support_stations(scn)[sups]
    state.sup_y[sups] = (state.pans[st, :3] + pan_axes(state.pans[st]) @ ram_site_local)[:, 1]


class StrokeControl:
    """Ram goals by stroke from each support's rest length (the module's equations), with the stop errors."""

    def __init__(self, scn: Scenario, ram_rest_m: np.ndarray):
        push = scn.supports.push
        self.rest = ram_rest_m.copy()
        self.overtravel, self.noise = push.stop_overtravel_m, push.stop_noise_m
        self.rng = np.random.default_rng([scn.seed, STOP_NOISE_STREAM])
        self.stop_error = np.zeros(ram_rest_m.size)
        self.advance_goal = ram_rest_m.copy()
        self.advanced = np.ones(ram_rest_m.size, bool)  # the rams rest at their last advance's goal

    def goals(self, ram: np.ndarray, pan_target: np.ndarray, sup_before: np.ndarray, sup_target: np.ndarray,
              new_target: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Push and advance goals of every ram (per support) and the supports short of their last advance, from the
        rams' lengths, the pans' and supports' advance targets (before and after this event's update) and the
        supports whose pans have a new target (a new stop error each). A push never retracts a ram."""
        n_new = int(new_target.sum())
        self.stop_error[new_target] = self.overtravel + self.noise * self.rng.standard_normal(n_new)
        stroke = pan_target - sup_before
        push = np.maximum(self.rest + stroke + np.where(stroke > 0.0, self.stop_error, 0.0), ram)
        behind = self.advanced & (ram - self.advance_goal > SUPPORT_DEADBAND_M)
        return push, self.rest + pan_target - sup_target, behind

    def commanded(self, moved: np.ndarray, advancing: np.ndarray, target: np.ndarray) -> None:
        """Note an event's commands: the supports that advanced rest at their goals, the others moved pushed."""
        self.advanced = np.where(moved, advancing, self.advanced)
        self.advance_goal = np.where(advancing, target, self.advance_goal)
