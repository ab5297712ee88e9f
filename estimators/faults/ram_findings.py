"""What the per-support ram checks (estimators.faults.ram_checks) report: a `Finding` per fault, the kinds and
their units, and one line of text each."""

from __future__ import annotations

from dataclasses import dataclass

KINDS = ("dropout", "noise_burst", "stuck", "offset", "drift", "scale", "rail_deviation")
"""Finding kinds (the twin's faults ram_dropout, ram_noise_burst, ram_stuck, ram_offset, ram_drift, ram_scale,
rail_deviation)."""

VALUE_UNITS = {"dropout": "s", "noise_burst": "m", "stuck": "m", "offset": "m", "drift": "m/s", "scale": "1",
               "rail_deviation": "m"}
"""Unit of Finding.value per kind: dropout its length, noise_burst the extra scatter (one sigma), stuck the frozen
reading, offset the reading error, drift its rate, scale the relative error of the reading, rail_deviation the
largest lateral error over the run (positive: the pans appear further towards the coal wall)."""


@dataclass(frozen=True)
class Finding:
    """One detected fault. support..last_support is the run of supports (one support except rail_deviation);
    t_start..t_end [s] the samples it affects, t_detect [s] when the log up to then confirms it; value the
    estimated fault in VALUE_UNITS[kind]; statistic and threshold the test that fired, in `unit`."""

    support: int
    last_support: int
    kind: str
    t_start: float
    t_end: float
    t_detect: float
    value: float
    statistic: float
    threshold: float
    unit: str


def format_finding(f: Finding) -> str:
    """One line: who, what, when, how big, and the test."""
    who = f"support {f.support}" if f.last_support == f.support else f"supports {f.support}-{f.last_support}"
    return (f"{who:<16} {f.kind:<14} {f.t_start:9.1f} .. {f.t_end:9.1f} s  confirmed {f.t_detect:9.1f} s  "
            f"value {f.value:+.4g} {VALUE_UNITS[f.kind]:<3}  statistic {abs(f.statistic):.4g} > "
            f"{f.threshold:.4g} {f.unit}")


def format_findings(findings: list[Finding]) -> str:
    return "\n".join(format_finding(f) for f in findings) if findings else "no push-ram faults found"
