"""How the supports push the AFC (twin.face.pushadvance, twin.face.drift): by ram stroke, with the stop errors that
make a real face drift, and the per-support offsets of face alignment (OPC 40561, use case 4.2.6)."""
# ruff: noqa: RUF012 -- the list defaults are pydantic fields (Section is a BaseModel; pydantic copies defaults)

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Literal

import numpy as np
from pydantic import Field

from twin.config.section import Section, between
from twin.face import snake

if TYPE_CHECKING:
    from twin.config.scenario import Scenario

MAX_OFFSET_WEB_FRACTION = 0.5
"""Largest per-support offset, as a fraction of the web: more is a re-cut, not a correction of the face line."""


class Offsets(Section):
    """Per-support offsets [m] (positive: pushed further towards the coal wall) applied on one cycle's shear."""

    cycle: Annotated[int, Field(ge=0)]
    offsets_m: list[between(-1.0, 1.0)]
    """One value per support (see check_offsets for the limits a face sets)."""


class PushControl(Section):
    """The push: a ram extended by a stroke measured from its support (twin.face.drift.StrokeControl)."""

    control: Literal["stroke", "position"] = "stroke"
    """stroke: each ram is extended from its support by the stroke its pan's push asks for, and a support advances
    by closing its ram to its rest length, as a real face's stroke sensors do: every stop error stays in the face
    and adds up from cycle to cycle. position: every pan and support lands on its absolute target (an ideal face
    that cannot drift; the twin before issue 25)."""
    stop_noise_m: between(0, 0.05) = 0.0
    """Standard deviation of where a push stops against its stroke target (the stroke sensor's noise and the
    valve's reaction): each push's error stays in the face (stroke control), so the line's straightness error walks
    as its square root of the cycles. 0 (default): the seed scenarios reproduce their papers' straight faces."""
    stop_overtravel_m: between(-0.05, 0.05) = 0.0
    """Mean of the stop error: how far a ram runs past its target after its valve is told to close."""
    offsets: list[Offsets] = []
    """Per-support offsets of given cycles (none: zero); an API caller adds its own per cycle (twin.face.drift)."""


def check_offsets(offsets_m: np.ndarray, n_supports: int, web_m: float, spacing_m: float, bend_limit_deg: float,
                  snake_pans: int, pan_length_m: float) -> None:
    """ValueError (one line) unless `offsets_m` has one finite value per support that a face can push: within
    MAX_OFFSET_WEB_FRACTION of the web, every push (web plus offset) within the snake's capacity, and the offset
    profile bending the face line (its second difference over the support spacing) within the bend limit's share
    the snake leaves (1 - snake.BEND_FRACTION)."""
    off = np.asarray(offsets_m, float)
    if off.shape != (n_supports,):
        raise ValueError(f"offsets_m: {off.size} values, need one per support ({n_supports})")
    if not np.isfinite(off).all():
        raise ValueError(f"offsets_m: support {int(np.flatnonzero(~np.isfinite(off))[0])} is not a finite number")
    worst = int(np.argmax(np.abs(off)))
    if abs(off[worst]) > MAX_OFFSET_WEB_FRACTION * web_m:
        raise ValueError(f"offsets_m: support {worst}: {off[worst]:g} m is more than {MAX_OFFSET_WEB_FRACTION:g} of "
                         f"the {web_m:g} m web")
    capacity = snake.capacity_m(snake_pans, pan_length_m, math.radians(bend_limit_deg))
    if web_m + off.max() > capacity:
        raise ValueError(f"offsets_m: support {int(np.argmax(off))}: a push of {web_m + off.max():.3f} m exceeds the "
                         f"snake's {capacity:.3f} m within the horizontal bend limit")
    bend = np.abs(np.diff(off, 2)) / spacing_m
    limit = (1 - snake.BEND_FRACTION) * math.radians(bend_limit_deg)
    if bend.size and bend.max() > limit:
        worst = int(np.argmax(bend)) + 1
        raise ValueError(f"offsets_m: support {worst} bends the face line {math.degrees(bend.max()):.2f} deg against its "
                         f"neighbours, more than {math.degrees(limit):.2f} deg ({1 - snake.BEND_FRACTION:g} of the "
                         f"horizontal bend limit); smooth the offsets")


def check_scenario_offsets(scn: Scenario, n_supports: int) -> None:
    """ValueError (one line) unless every cycle's offsets of supports.push.offsets can be pushed (check_offsets)."""
    seen = set()
    for k, entry in enumerate(scn.supports.push.offsets):
        where = f"supports.push.offsets[{k}]"
        if entry.cycle >= scn.cycles or entry.cycle in seen:
            raise ValueError(f"{where}: cycle {entry.cycle} is not a cycle of the run (0..{scn.cycles - 1}) without "
                             f"offsets of its own")
        seen.add(entry.cycle)
        try:
            check_offsets(np.asarray(entry.offsets_m), n_supports, **offset_limits(scn))
        except ValueError as err:
            raise ValueError(f"{where}.{err}") from None


def offset_limits(scn: Scenario) -> dict[str, float]:
    """The face's figures check_offsets needs besides the offsets and the number of supports."""
    f = scn.face
    return {"web_m": f.web_depth_m, "spacing_m": scn.supports.pans_per_support * f.pan_length_m,
            "bend_limit_deg": f.bend_limit_horizontal_deg, "snake_pans": scn.pattern.snake_length_pans,
            "pan_length_m": f.pan_length_m}
