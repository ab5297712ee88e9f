"""Faults of the face against faults of the sensors (estimators.faults.hydraulic_checks with the ram checks): each
fault injected alone on the default face, detected, and attributed to the face or to a sensor.

Every case simulates the face with its fault (the faults of the face change the physics: an obstacle, a leaking
leg, a failed set, a sticking valve) and draws the sensors once; the checks see the PUSHRAM and PRESSURE logs only.
A case counts as right when a finding of the expected kind on the target support, confirmed inside the fault's
window, carries the right cause, and nothing is attributed to the other cause on that support. The fault-free run
gives the false findings.

Run: python benchmarks/bench_hydraulic_faults.py [--cycles N]   (the default face's first N cycles, default 2)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from estimators.faults.hydraulic_checks import check_hydraulics, format_attribution
from estimators.faults.ram_checks import check_log
from twin.config.scenario import Scenario, load_face_scenario, parse_scenario
from twin.pipeline.estimate import hydraulic_layout, ram_layout
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "default.toml"
CASES = [
    # (fault, expected kind, expected cause)
    ({"kind": "obstruction", "t_start_s": 250.0, "t_end_s": 700.0, "target": 20, "value": 0.3}, "ram_stall", "face"),
    ({"kind": "sticking_valve", "t_start_s": 0.0, "t_end_s": 2000.0, "target": 33, "value": 0.3}, "sticking_valve",
     "face"),
    ({"kind": "failed_set", "t_start_s": 0.0, "t_end_s": 2000.0, "target": 25, "value": 12.0}, "failed_set", "face"),
    ({"kind": "leg_leak", "t_start_s": 300.0, "t_end_s": 2000.0, "target": 12, "value": 2.0}, "leg_leak", "face"),
    ({"kind": "ram_offset", "t_start_s": 250.0, "t_end_s": 700.0, "target": 20, "value": 0.15}, "ram_offset",
     "sensor"),
    ({"kind": "ram_stuck", "t_start_s": 250.0, "t_end_s": 700.0, "target": 20, "value": 0.0}, "ram_stuck", "sensor"),
    ({"kind": "leg_pressure_offset", "t_start_s": 300.0, "t_end_s": 2000.0, "target": 12, "value": 8.0},
     "leg_pressure", "sensor"),
    ({"kind": "leg_pressure_stuck", "t_start_s": 300.0, "t_end_s": 2000.0, "target": 25, "value": 0.0},
     "leg_pressure", "sensor"),
    ({"kind": "leg_pressure_drift", "t_start_s": 300.0, "t_end_s": 2000.0, "target": 12, "value": -0.05},
     "leg_pressure", "sensor"),
]


def face(cycles: int, faults: list[dict]) -> Scenario:
    """The default face's first `cycles` cycles with `faults`."""
    return parse_scenario({**load_face_scenario(SCENARIO).model_dump(), "cycles": cycles, "faults": faults},
                          SCENARIO.name)


def run(scn: Scenario, trial: int = 0):
    result = simulate(scn)
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), trial)
    ram = streams["pushram"]
    return check_hydraulics(ram, streams["pressure"], hydraulic_layout(scn), check_log(ram, ram_layout(scn)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2)
    args = parser.parse_args()
    start = time.perf_counter()
    clean = run(face(args.cycles, []))
    print(f"default face, {args.cycles} cycles: {len(clean)} findings without a fault")
    for a in clean:
        print(f"    {format_attribution(a)}")
    print(f"\n{'fault':<22}{'value':>7}{'support':>8}  {'expected':<24}{'found':<24}{'delay [s]':>10}  right")
    right = 0
    for fault, kind, cause in CASES:
        scn = face(args.cycles, [fault])
        found = run(scn)
        target, t0, t1 = fault["target"], fault["t_start_s"], fault["t_end_s"]
        mine = [a for a in found if a.support == target and t0 <= a.t_detect < t1 + 60.0]
        hits = [a for a in mine if a.kind == kind]
        wrong = [a for a in mine if a.cause != cause]
        ok = bool(hits) and all(a.cause == cause for a in hits) and not wrong
        right += ok
        first = min(hits, key=lambda a: a.t_detect) if hits else None
        got = f"{first.kind} ({first.cause})" if first else (f"{mine[0].kind} ({mine[0].cause})" if mine else "-")
        delay = f"{first.t_detect - t0:.0f}" if first else "-"
        print(f"{fault['kind']:<22}{fault['value']:>7g}{target:>8}  {f'{kind} ({cause})':<24}{got:<24}{delay:>10}"
              f"  {'yes' if ok else 'NO'}")
        for a in found:
            if a not in hits:
                print(f"{'':<6}also: {format_attribution(a)}")
    print(f"\n{right}/{len(CASES)} faults found and attributed right; {len(clean)} findings on the fault-free run; "
          f"{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
