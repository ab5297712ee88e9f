"""The record rate of the Rerun recordings: one setting for run.rrd and estimates.rrd (`longwall run --record-rate HZ`,
`longwall estimate DIR --record-rate HZ`, `twin.run(..., record_rate_hz=...)`), recorded in the run directory's
metrics.json under "recordings" (file name: Hz, or "full").

A rate is a finite number of Hz > 0, or FULL (None): every sample, neither decimated nor thinned
(twin.view.visible_cut.visible_rows). Kept apart from the writers so the command line reads it without importing
Rerun.
"""

from __future__ import annotations

import math

RECORD_RATE_HZ = 10.0
"""Default record rate: a person follows a replay at about 10 frames a second."""
FULL = None
"""The record rate that logs every sample (`--record-rate full`)."""
FULL_SPELLING = "full"
"""How the command line and metrics.json spell FULL."""


def parse_record_rate(text: str) -> float | None:
    """A record rate as the command line spells it: a positive number of Hz, or "full" (FULL: every sample).
    ValueError (one line) otherwise."""
    if text.strip().lower() == FULL_SPELLING:
        return FULL
    try:
        rate = float(text)
    except ValueError:
        rate = math.nan
    return check_record_rate(rate, f"'{text}'")


def check_record_rate(rate_hz: float | None, shown: str | None = None) -> float | None:
    """`rate_hz` if it is a record rate (a finite number of Hz > 0, or FULL); ValueError (one line) otherwise."""
    if rate_hz is FULL:
        return FULL
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, int | float) or not (0 < rate_hz < math.inf):
        raise ValueError(f"{shown or f'record_rate_hz={rate_hz!r}'} is not a record rate: give Hz > 0 (e.g. 10), or "
                         f"'{FULL_SPELLING}' for every sample")
    return float(rate_hz)


def rate_label(rate_hz: float | None) -> float | str:
    """The record rate as the run directory records it (metrics.json "recordings"): Hz, or "full"."""
    return FULL_SPELLING if rate_hz is FULL else float(rate_hz)
