"""The base of every scenario-file section, its one-line errors, the field types they share, and the site.

Every kind of scenario file (face scenarios, twin.config.scenario; 000's SINS experiments,
twin.config.experiments; 002's turntable, twin.config.turntable) is a tree of `Section` models: unknown keys
are errors, values are not coerced (strict), and a validated section is frozen. A validation error becomes
one line naming the file and the key (`format_error`).
"""

from __future__ import annotations

import datetime
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError

Finite = Annotated[float, Field(allow_inf_nan=False)]
PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegativeFloat = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Vector3 = Annotated[list[Finite], Field(min_length=3, max_length=3)]

Rate = Annotated[float, Field(gt=0, le=2000, allow_inf_nan=False)]
"""A sampling or update rate [Hz]: above 2 kHz no instrument of a face (nor the papers' simulations) samples."""
Duration = Annotated[float, Field(gt=0, le=86400, allow_inf_nan=False)]
"""A simulated span [s]: at most a day (a longwall shift is 8 h; longer spans are several runs)."""


def between(lo: float, hi: float) -> Any:
    """A finite float type within [lo, hi] (the bounds' reason goes in the field's docstring)."""
    return Annotated[float, Field(ge=lo, le=hi, allow_inf_nan=False)]


def vector3(limit: float) -> Any:
    """Three finite floats, each within [-limit, limit]."""
    return Annotated[list[between(-limit, limit)], Field(min_length=3, max_length=3)]


WMM_YEARS = (2010, 2029)
"""Years the World Magnetic Model of pygeomag covers: its coefficient files WMM2010, 2015, 2020 and 2025, each
valid five years (tests/twin/config/test_ranges.py checks both ends against pygeomag)."""


def _wmm_date(text: str) -> str:
    try:
        day = datetime.date.fromisoformat(text)
    except ValueError:
        raise ValueError(f"{text!r} is not a calendar date YYYY-MM-DD") from None
    if not WMM_YEARS[0] <= day.year <= WMM_YEARS[1]:
        raise ValueError(f"{text} is outside the geomagnetic model's years {WMM_YEARS[0]}-01-01 .. "
                         f"{WMM_YEARS[1]}-12-31 (pygeomag's WMM)")
    return text


WmmDate = Annotated[str, Field(pattern=r"^\d{4}-\d{2}-\d{2}$"), AfterValidator(_wmm_date)]
"""A date YYYY-MM-DD for the geomagnetic model: a real calendar date within WMM_YEARS."""


class ScenarioError(ValueError):
    """A scenario that cannot be run; the message is one line: file, key, what is wrong (line breaks a file's
    keys or values bring in are escaped)."""

    def __init__(self, message: str):
        super().__init__(str(message).replace("\r", "\\r").replace("\n", "\\n"))


class Section(BaseModel):
    """A table of a scenario file: no unknown keys, no coercion, frozen once valid."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class Site(Section):
    """Reference geodetic point: origin of the MuJoCo world (ENU tangent plane); the site of 000's experiments."""

    lat_deg: Annotated[float, Field(ge=-89, le=89, allow_inf_nan=False)] = 34.27
    lon_deg: Annotated[float, Field(ge=-180, le=180, allow_inf_nan=False)] = 117.18
    height_m: Annotated[float, Field(ge=-5000, le=9000, allow_inf_nan=False)] = 36.0


def format_error(source: str, err: ValidationError, keys_file: str = "scenarios/default.toml") -> str:
    """The first error of a validation as one line: `source: key: what is wrong (got value)`; an unknown key
    points to `keys_file`, a shipped file of the same kind that has every key."""
    first = err.errors()[0]
    loc = ".".join(str(x) for x in first["loc"] if not str(x).startswith("function-after"))
    msg = first["msg"].removeprefix("Value error, ")
    if first["type"] == "extra_forbidden":
        msg = f"unknown key (check the spelling; see {keys_file} for the keys)"
    got = first.get("input")
    detail = f" (got {got!r})" if first["type"] not in ("extra_forbidden", "value_error") and not isinstance(
        got, dict) else ""
    where = f"{loc}: " if loc else ""
    return f"{source}: {where}{msg}{detail}"


def validate(model: type[Section], data: dict, source: str, keys_file: str = "scenarios/default.toml"):
    """`model` validated from a file's data (the TOML as a dict); a one-line ScenarioError naming `source`."""
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ScenarioError(format_error(source, err, keys_file)) from None
