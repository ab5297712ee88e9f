"""Faults of the face against faults of the sensors (estimators.faults.hydraulic_checks with the ram checks): each
fault injected alone on the default face, detected, and attributed to the face or to a sensor.

Every case simulates the face with its fault (the faults of the face change the physics: an obstacle, a leaking
leg, a failed set, a sticking valve) and draws the sensors once; the checks see the PUSHRAM and PRESSURE logs only.
A case counts as right when a finding of the expected kind on the target support, confirmed inside the fault's
window, carries the right cause, and nothing is attributed to the other cause on that support. The fault-free run
gives the false findings.

Then 004's detectors (the federated SINS/odometer + rail-kinematics-model filter's fading SPRT, which isolates the
rail model when its fixes disagree with the inertial path) on the same faults of a face long enough for the rail
model (seed004's 200 pans; on the default face the end zones leave the model no fixes after the first pass): the
rail model advances each chute by its ram's reading, so a reading that does not follow its pan (a stuck sensor, a
push that falls short while the sensor reads the full stroke) raises it, and a fault of the face that the readings
follow (an obstacle, a slow valve, a leaking leg, a failed set) does not: the filter says "sensor", the hydraulic
checks say which fault of the face.

Run: python benchmarks/bench_hydraulic_faults.py [--cycles N] [--skip-004]   (the default face's first N cycles,
default 2; seed004's face for 2 cycles, about 50 s a case)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from estimators.faults.hydraulic_checks import check_hydraulics, format_attribution
from estimators.faults.ram_checks import check_log
from estimators.io.log import log_from_columns
from estimators.io.logformat import FLAG_ISOLATED
from estimators.shearer.prepare import prepare
from estimators.shearer.rail_kinematics import fsprt_alarms, run_rail
from twin.config.scenario import Scenario, load_face_scenario, parse_scenario
from twin.pipeline.estimate import hydraulic_layout, positioning_config, ram_layout
from twin.pipeline.simulate import simulate
from twin.sensors.streams import imu_truth, sensor_streams

SCENARIO = Path(__file__).resolve().parent.parent / "scenarios" / "default.toml"
SCENARIO_004 = SCENARIO.with_name("seed004.toml")
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


CASES_004 = [
    # (fault on support 100 of seed004's face from 1000 s on, the cause 004's detectors should see)
    ({"kind": "obstruction", "value": 0.3}, "face"),
    ({"kind": "sticking_valve", "value": 0.3}, "face"),
    ({"kind": "leg_leak", "value": 2.0}, "face"),
    ({"kind": "failed_set", "value": 12.0}, "face"),
    ({"kind": "push_shortfall", "value": 0.3}, "sensor"),
    ({"kind": "ram_stuck", "value": 0.0}, "sensor"),
    ({"kind": "ram_scale", "value": 0.3}, "sensor"),
]


def face(cycles: int, faults: list[dict], path: Path = SCENARIO) -> Scenario:
    """A shipped face's first `cycles` cycles with `faults` (default: the default face)."""
    return parse_scenario({**load_face_scenario(path).model_dump(), "cycles": cycles, "faults": faults}, path.name)


def run(scn: Scenario, trial: int = 0):
    result = simulate(scn)
    streams = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), trial)
    ram = streams["pushram"]
    return check_hydraulics(ram, streams["pressure"], hydraulic_layout(scn), check_log(ram, ram_layout(scn)))


def rail_detectors(scn: Scenario) -> tuple[int, float, int]:
    """004's federated rail filter on a run of `scn`: FSPRT alarms, largest statistic, epochs isolated."""
    result = simulate(scn)
    s = sensor_streams(scn, result.tables, imu_truth(scn, result.tables["truth_shearer"]), 0)
    log = log_from_columns(s["imu"], s["odometer"], s["survey"], s["pushram"], face_survey=s["face_survey"])
    cfg = positioning_config(scn)
    sol = run_rail(log, cfg, prepare(log, cfg))
    alarms = fsprt_alarms(sol.detectors, cfg.detector.t_on)
    return alarms.size, float(np.nanmax(sol.detectors["fsprt"])), int(np.sum((sol.flags & FLAG_ISOLATED) > 0))


def main_004() -> None:
    """004's detectors on seed004's face: which faults they call the sensors'."""
    start = time.perf_counter()
    alarms, peak, isolated = rail_detectors(face(2, [], SCENARIO_004))
    cfg = positioning_config(face(2, [], SCENARIO_004))
    print(f"\n004's detectors (FSPRT, T1 {cfg.detector.t_on:g}) on seed004's face, 2 cycles, support 100 from 1000 s: "
          f"fault-free {alarms} alarms, largest statistic {peak:.1f}")
    print(f"{'fault':<16}{'value':>7}  {'expected':<9}{'alarms':>7}{'largest':>9}{'isolated':>10}  {'says':<7}right")
    right = 0
    for fault, cause in CASES_004:
        scn = face(2, [{**fault, "t_start_s": 1000.0, "t_end_s": 1.0e5, "target": 100}], SCENARIO_004)
        alarms, peak, isolated = rail_detectors(scn)
        says = "sensor" if alarms else "face"
        right += says == cause
        print(f"{fault['kind']:<16}{fault['value']:>7g}  {cause:<9}{alarms:>7}{peak:>9.1f}{isolated:>10}  {says:<7}"
              f"{'yes' if says == cause else 'NO'}")
    print(f"{right}/{len(CASES_004)} attributed right by 004's detectors; {time.perf_counter() - start:.0f} s")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=2)
    parser.add_argument("--skip-004", action="store_true", help="leave out 004's detectors on seed004's face")
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
    if not args.skip_004:
        main_004()


if __name__ == "__main__":
    main()
