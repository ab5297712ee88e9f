"""Per-support checks of the push-ram stroke sensors (the PUSHRAM stream) that name the faulty support.

Input is the push-ram log alone (t, support, extension, valid; estimators.io.logformat.PUSHRAM) and what a user
knows of the face (`RamLayout`): the number of supports and their spacing, the commanded stroke of a push (the
web depth), the AFC's bend limit, and the sensors' noise and resolution. Output is a list of `Finding`s: the
support (or, for a lateral deviation, the run of supports), the kind, the window, when the data first confirmed
it, the estimated fault value and the test statistic against its threshold. `format_findings` prints one line
each. The readings are put on the log's common sample grid (the stream has one row per support per sample; a
missing row counts as an invalid reading).

The checks, in order (each module's doc gives its equations and thresholds):

* self-checks of each sensor on its own: dropout, noise_burst, stuck (estimators.faults.ram_self_checks); the
  readings they flag are left out of the checks below;
* the support advances and (a) the commanded versus the measured stroke (estimators.faults.ram_strokes);
* (b) each ram against its neighbours along the AFC chain, which also settles how many times each support has
  advanced (estimators.faults.ram_neighbours);
* each support's flagged stretches of (a) and (b) classified as stuck, scale, drift or offset, and the runs of
  supports flagged together as one rail_deviation (estimators.faults.ram_chain).

* a ram that (b) finds stuck (a sensor too fine for its quantum to show it by flatness): its frozen readings are
  left out as well and (a) and (b) run again (`check_rams`, up to STUCK_PASSES times).

Limits: a reading error that starts or ends with a jump of more than half a stroke at an advance is taken for
a miscounted advance; the end supports need about twice the error of the others; a fault of a noise-free sensor
at rest with still neighbours leaves nothing to see; strokes at a face end, where the twin pushes and advances
a row of supports within a reading or two, are not judged by (a), so a scale error there reads as an offset.

Measured here (benchmarks/bench_ram_checks.py: seed004, 6.5 h, 200 supports, 0.02 m sensors; fault on support
100 around its first push): confirmation after the fault start 5 s stuck, 7 s offset (0.15 m), 454 s drift
(0.2 mm/s, = tau / rate), 7 s scale (15 %), 0 s dropout, 26 s noise burst (0.1 m), 76 s for 004's rail
deviation (run 141-155 of the deviated 138-155); each named on its support only; no finding over 20 redrawn
fault-free trials; 3 s per log.

Not seen here
-------------
push_shortfall is a fault of the face, not of the sensor: the pan stops short while the ram reads the full
commanded stroke, so every check above passes. It is left to the rail kinematics model filter, which compares
the pan line with the shearer's measured path; nothing here pretends to detect it. (The twin adds the shortfall
to the readings from the start of its window, also before the pan has been pushed short, and takes it off at the
end: the neighbour check may flag those steps. That is not a detection of the shortfall.)
"""

from __future__ import annotations

import dataclasses

import numpy as np

from estimators.faults.ram_chain import MERGE_GAP, _chain_checks, _end_pairs, _rail_runs
from estimators.faults.ram_findings import (
    KINDS,
    VALUE_UNITS,
    Finding,
    format_finding,
    format_findings,
)
from estimators.faults.ram_grid import _grid, table_columns
from estimators.faults.ram_layout import RamLayout
from estimators.faults.ram_self_checks import _self_checks

# the public checks, and the thresholds benchmarks/bench_ram_checks.py prints, read through this module
__all__ = ["KINDS", "VALUE_UNITS", "Finding", "RamLayout", "check_log", "check_rams", "format_finding",
           "format_findings"]

STUCK_PASSES = 4
"""Most rams found stuck by their neighbours (not by flatness) that are left out, one per pass, and the checks
run again."""


def _frozen_runs(tg: np.ndarray, x: np.ndarray, stuck: list[Finding]) -> list[tuple[int, int, int]]:
    """(support, first, last grid index) of the whole run of equal readings around each stuck finding."""
    out = []
    for f in stuck:
        col = x[:, f.support]
        lo, hi = int(np.searchsorted(tg, f.t_start)), int(np.searchsorted(tg, f.t_end))
        same = np.abs(col - col[lo]) <= 1e-12
        while lo > 0 and same[lo - 1]:
            lo -= 1
        while hi + 1 < col.size and same[hi + 1]:
            hi += 1
        out.append((f.support, lo, hi))
    return out


def check_rams(t, support, extension, valid, layout: RamLayout) -> list[Finding]:
    """All push-ram findings of a log (columns of the PUSHRAM stream), sorted by time then support.

    A sensor too fine for its quantum to show a frozen reading by flatness (see `_flat_run`) is found stuck by
    the neighbour check once its neighbours move; its frozen readings are then left out like those of a flat
    stuck sensor and checks (a) and (b) run again, so the stuck ram's error of up to a stroke does not spill
    into the advance counts of its neighbours."""
    tg, x = _grid(t, support, extension, valid, layout.n_supports)
    dt = float(np.median(np.diff(tg)))
    findings, mask = _self_checks(tg, x, layout)
    usable = ~mask
    chain = _chain_checks(tg, x, usable, layout)
    stuck: list[Finding] = []
    for _ in range(STUCK_PASSES):  # the strongest stuck ram first: its error spills onto the others' counts
        new = [f for f in chain if f.kind == "stuck"
               and not any(f.support == g.support and f.t_start <= g.t_end and g.t_start <= f.t_end for g in stuck)]
        if not new:
            break
        f = max(new, key=lambda f: abs(f.statistic) / f.threshold)
        (_, lo, hi), = _frozen_runs(tg, x, [f])
        usable[lo:hi + 1, f.support] = False
        stuck.append(dataclasses.replace(f, t_start=float(tg[lo]), t_end=float(tg[hi])))
        chain = _chain_checks(tg, x, usable, layout)
    chain = stuck + [f for f in chain if not any(f.support == g.support and f.t_start <= g.t_end
                                                 and g.t_start <= f.t_end for g in stuck)]
    findings += _rail_runs(_end_pairs(chain, layout.n_supports, MERGE_GAP * dt), dt)
    findings.sort(key=lambda f: (f.t_start, f.support, f.kind))
    return findings


def check_log(pushram, layout: RamLayout) -> list[Finding]:
    """check_rams on a PUSHRAM table (a mapping of column arrays or a pyarrow table)."""
    return check_rams(*table_columns(pushram, ("t", "support", "extension", "valid"), "pushram"), layout)
