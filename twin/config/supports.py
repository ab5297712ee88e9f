"""The hydraulic roof supports' section of a face scenario (their push rams' and legs' hydraulics), and the roof they
hold."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from twin.config.push import PushControl
from twin.config.section import Section


class Hydraulics(Section):
    """The supports' push rams and the pump that feeds them (twin.face.hydraulics): the ram pushes its pan on the
    annulus and pulls its support on the full bore."""

    pump_pressure_mpa: Annotated[float, Field(ge=5, le=45, allow_inf_nan=False)] = 31.5
    """Pump (and relief) pressure: the rams' force limit is this times the pressurised area."""
    ram_bore_mm: Annotated[float, Field(ge=60, le=300, allow_inf_nan=False)] = 160.0
    ram_rod_mm: Annotated[float, Field(ge=30, le=250, allow_inf_nan=False)] = 110.0
    push_flow_l_min: Annotated[float, Field(ge=5, le=1000, allow_inf_nan=False)] = 60.0
    """Flow the push valve meters into the annulus (the push speed: 0.094 m/s with the defaults)."""
    pull_flow_l_min: Annotated[float, Field(ge=5, le=2000, allow_inf_nan=False)] = 350.0
    """Flow into the full bore while the support advances (0.29 m/s with the defaults)."""

    @model_validator(mode="after")
    def _rod_inside_bore(self) -> Hydraulics:
        if self.ram_rod_mm >= 0.95 * self.ram_bore_mm:
            raise ValueError(f"ram_rod_mm: a {self.ram_rod_mm:g} mm rod leaves no annulus in a {self.ram_bore_mm:g} mm "
                             f"bore; make the rod at most 95 % of the bore")
        return self


class Legs(Section):
    """The legs of a support (twin.face.hydraulics.LegHydraulics): cylinders that lower the canopy off the roof,
    set it against the roof to the set pressure and yield through the yield valve as the roof converges."""

    count: Annotated[int, Field(ge=1, le=4)] = 2
    bore_mm: Annotated[float, Field(ge=100, le=500, allow_inf_nan=False)] = 400.0
    set_pressure_mpa: Annotated[float, Field(ge=5, le=45, allow_inf_nan=False)] = 31.5
    """Pressure at which the setting valve closes (the pump's): 7.9 MN of set load with the defaults."""
    yield_pressure_mpa: Annotated[float, Field(ge=10, le=60, allow_inf_nan=False)] = 42.0
    """Pressure at which the yield valve opens and lets the leg close under the roof's load (10.6 MN)."""
    flow_l_min: Annotated[float, Field(ge=50, le=5000, allow_inf_nan=False)] = 1500.0
    """Flow into (setting) and out of (lowering) the legs together: 0.1 m/s of leg travel with the defaults, so a
    support lowers 0.1 m in 1.6 s and sets again in 1.6 s."""

    @model_validator(mode="after")
    def _yield_above_set(self) -> Legs:
        if self.yield_pressure_mpa < 1.1 * self.set_pressure_mpa:
            raise ValueError(f"yield_pressure_mpa: {self.yield_pressure_mpa:g} MPa is not above the set pressure "
                             f"{self.set_pressure_mpa:g} MPa by 10 %; a yield valve opens well above the set")
        return self


class Roof(Section):
    """The roof over the face: the floor plus the mining height, undulating on its own, converging on the set
    supports (twin.face.layout.Roof)."""

    mining_height_m: Annotated[float, Field(ge=1.5, le=6.5, allow_inf_nan=False)] = 3.1
    """Roof above the floor (vertical); the supports' legs reach 0.5 .. 7 m and the canopy is 0.1 m thick."""
    undulation_amplitude_m: Annotated[float, Field(ge=0, le=0.5, allow_inf_nan=False)] = 0.05
    """Amplitude of the roof's undulation relative to the floor (the seam's thickness varying)."""
    undulation_wavelength_m: Annotated[float, Field(ge=5, le=1000, allow_inf_nan=False)] = 25.0
    convergence_mm_h: Annotated[float, Field(ge=0, le=500, allow_inf_nan=False)] = 5.0
    """Rate at which the roof closes on a set support (its legs' pressure rises 2.5 MPa/h with the defaults, until
    they yield); 500 mm/h is a roof fall, not convergence."""


class Supports(Section):
    """Hydraulic roof supports (shields) and their push rams."""

    pans_per_support: Annotated[int, Field(ge=1, le=4)] = 1
    ram_length_set_m: Annotated[float, Field(ge=0.5, le=3.0, allow_inf_nan=False)] = 1.2
    """Ram length between a set support and its pan before a push (fully retracted)."""
    hydraulics: Hydraulics = Hydraulics()
    legs: Legs = Legs()
    push: PushControl = PushControl()
    sequence: Literal["after_push", "before_push"] = "after_push"
    """Support-advance sequence: after the pans are pushed (conventional), or before (immediate forward
    support, the supports following the shearer); see twin.face.pushadvance."""
    advance_lag_pans: Annotated[int, Field(ge=0, le=20)] = 2
    """after_push: a support advances once its pan and the pans this many nearer the shearer are fully
    pushed. before_push: once the shearer's trailing end is this many pans past it."""
    lower_m: Annotated[float, Field(gt=0, le=0.5, allow_inf_nan=False)] = 0.1
    """How far the canopy is lowered from the roof while the support advances."""
