"""The face alignment loop of a scenario (OPC 40561 Longwall Operation, use case 4.2.6): which shearer path feeds the
face alignment system (estimators.face.alignment), and how the system turns a shear's face line into offsets that the
roof support system applies on a later shear (twin.pipeline.alignment_loop)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from twin.config.section import Section, between


class Alignment(Section):
    """The face alignment loop (none: open loop, the face drifts)."""

    mode: Literal["none", "truth", "kf_rts", "kf_cpoem_rts", "kf_cpoem", "kf", "fkf_rail"] = "none"
    """Path fed to the alignment system: none (open loop), truth (the true shearer path of each shear: the upper bound
    of what an estimator can give), or a shearer positioning method run online on the run's own readings (001's
    filters, 004's fkf_rail; twin.pipeline.alignment_loop.EstimatedShears)."""
    delay_shears: Annotated[int, Field(ge=0, le=5)] = 0
    """Shears between the one whose path gave the offsets and the one that applies them, besides the next: 0 applies
    a shear's offsets on the next shear (the roof support system reads them as the shear ends)."""
    gain: between(0.05, 1.0) = 0.7
    """Share of a shear's measured face-line error corrected on the next shear: under 1, so that the path's noise is
    not pushed into the face in full."""
    smoothing_shields: between(0.0, 20.0) = 1.0
    """Shields over which an offset profile is smoothed (a second-difference penalty of this length to the fourth). A
    shield's stop errors are its own, so the line's error lives at the shield spacing: on face_alignment's first 20
    cycles with the true path, 1 held the line at 7-10 mm RMS; 3 let it grow as in open loop (10 cycles: 11.4 mm
    against 11.1)."""
    target: Literal["straight", "square"] = "straight"
    """Target line: straight (the face keeps its orientation, the line through its mean), or square to the gate roads
    (turned towards F's y axis by at most max_turn_deg per shear)."""
    max_turn_deg: between(0.0, 1.0) = 0.05
    """Largest turn of the target line per shear towards a square face [deg]."""
    min_coverage: between(0.5, 1.0) = 0.8
    """Share of the shields between the path's ends it must cover for a shear to count as full."""
