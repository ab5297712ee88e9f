"""Benchmark of issue 24 (panel scale): whole `longwall run` commands timed as a user runs them, with the peak
memory of the run's whole process tree (the estimators' forked workers included), printed beside the targets.

    python benchmarks/bench_scale.py                      # seed004 end to end, first run vs warm run
    python benchmarks/bench_scale.py --cycles 5 20 100    # also peak memory over cycles of panel_100 (seed004's face)

Figures:
* seed004 end to end (`longwall run scenarios/seed004.toml`): wall time <= 60 s, peak memory <= 2 GB.
* The first run of a fresh install within 2x a warm run (`longwall run`, the default scenario). A fresh install
  differs from a warm one by numba's compiled kernels only, so the first run is measured with an empty
  NUMBA_CACHE_DIR (nothing else is cached between runs).
* Peak memory at N cycles of scenarios/panel_100.toml (seed004's face on a 110 m panel, KF + CPOEM + RTS and fkf_rail streamed;
  `longwall run scenarios/panel_100.toml --cycles N`): 100-cycle / 5-cycle <= 1.25; the 100-cycle run within 20
  minutes. A run the resource estimate refuses (twin.config.resources) is printed with its one-line refusal.

Peak memory is the largest sum over the process tree of each process's proportional set size (PSS: pages shared
copy-on-write with the forked workers counted once), sampled every 0.2 s; ru_maxrss of the largest single process
is printed beside it, and the peak in each stage of the run (the stages' ends on the clock from its timing.json).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import psutil

ROOT = Path(__file__).resolve().parent.parent
SEED004 = ROOT / "scenarios" / "seed004.toml"
PANEL = ROOT / "scenarios" / "panel_100.toml"
TARGET_SEED004_S = 60.0
TARGET_SEED004_GB = 2.0
TARGET_FIRST_RUN_RATIO = 2.0
TARGET_MEMORY_RATIO = 1.25
TARGET_100_CYCLES_S = 20 * 60.0


@dataclass(frozen=True)
class Timed:
    """One command: exit code, wall time [s], peak PSS of its process tree and largest single RSS [bytes], stderr's
    last line, and from the run's timing.json (when it wrote one) its wall time and peak PSS by stage."""

    rc: int
    wall_s: float
    peak_pss: float
    max_rss: float
    last_err: str
    stages_s: dict[str, float]
    stage_peaks: dict[str, float]


def stage_peaks(samples: list[tuple[float, float]], ends: list[list]) -> dict[str, float]:
    """The largest of `samples` ((Unix s, bytes)) in each stage of `ends` ([end in Unix s, stage], in time order, the
    time up to each end going to its stage): the run's start to its first stage, the time after the last end (the
    run's closing) to "closing"."""
    times = np.array([end for end, _ in ends])
    peaks: dict[str, float] = {}
    for t, value in samples:
        i = int(np.searchsorted(times, t))
        name = ends[i][1] if i < len(ends) else "closing"
        peaks[name] = max(peaks.get(name, 0.0), value)
    return peaks


def _tree_pss(proc: psutil.Process) -> float:
    total = 0.0
    for p in [proc, *proc.children(recursive=True)]:
        try:
            total += p.memory_full_info().pss
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            pass
    return total


def timed(args: list[str], env: dict[str, str] | None = None, out: Path | None = None) -> Timed:
    """Run a command to its end, sampling its process tree's memory; `out`: the run directory it writes."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    start = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, **(env or {})})
    samples: list[tuple[float, float]] = []  # (Unix s, PSS of the tree)

    def sample() -> None:
        ps = psutil.Process(proc.pid)
        while proc.poll() is None:
            try:
                samples.append((time.time(), _tree_pss(ps)))
            except psutil.NoSuchProcess:
                break
            time.sleep(0.2)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, err = proc.communicate()
    wall = time.perf_counter() - start
    sampler.join()
    max_rss = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before) * 1024.0
    lines = [line for line in err.splitlines() if line.strip()]
    timing = out / "timing.json" if out is not None else None
    figures = json.loads(timing.read_text()) if timing is not None and timing.is_file() else {}
    peaks = stage_peaks(samples, figures["stage_ends_unix_s"]) if figures.get("stage_ends_unix_s") else {}
    return Timed(proc.returncode, wall, max((m for _, m in samples), default=0.0), max_rss,
                 lines[-1] if lines else "", figures.get("stages_s", {}), peaks)


def longwall(*args: str, out: Path) -> list[str]:
    return [sys.executable, "-m", "twin.cli", "run", *args, "--out", str(out), "--force", "--quiet"]


def verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def gb(x: float) -> str:
    return f"{x / 1e9:.2f} GB"


def describe(label: str, r: Timed) -> str:
    if r.rc != 0:
        return f"{label:42s} failed (rc {r.rc}): {r.last_err}"
    stages = ", ".join(f"{k} {v:.1f}" for k, v in r.stages_s.items())
    peaks = ", ".join(f"{k} {v / 1e9:.2f}" for k, v in r.stage_peaks.items())
    return (f"{label:42s} {r.wall_s:7.1f} s   peak {gb(r.peak_pss)} (largest process {gb(r.max_rss)})"
            + (f"\n{'':44s}stages [s]: {stages}" if stages else "")
            + (f"\n{'':44s}peak by stage [GB]: {peaks}" if peaks else ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cycles", type=int, nargs="*", default=[], metavar="N",
                    help="also run panel_100 (seed004's face) for N cycles each (e.g. 5 20 100)")
    ap.add_argument("--skip-seed004", action="store_true", help="leave out the seed004 end-to-end run")
    ap.add_argument("--skip-first-run", action="store_true", help="leave out the first run against a warm run")
    opts = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench-scale-") as tmp:
        tmp = Path(tmp)
        if not opts.skip_first_run:
            print("first run of a fresh install (empty numba cache) against a warm run: longwall run (default.toml)")
            cold = timed(longwall(out=tmp / "cold"), env={"NUMBA_CACHE_DIR": str(tmp / "numba-cache")},
                         out=tmp / "cold")
            timed(longwall(out=tmp / "warm"))  # fills numba's own cache if a kernel changed since
            warm = timed(longwall(out=tmp / "warm"), out=tmp / "warm")
            print(describe("  first run", cold))
            print(describe("  warm run", warm))
            if cold.rc == 0 and warm.rc == 0:
                ratio = cold.wall_s / warm.wall_s
                print(f"  first / warm {ratio:.2f}   (target <= {TARGET_FIRST_RUN_RATIO:.0f}: "
                      f"{verdict(ratio <= TARGET_FIRST_RUN_RATIO)})")
        if not opts.skip_seed004:
            print("\nseed004 end to end: longwall run scenarios/seed004.toml (6.4 h simulated, 5 cycles)")
            r = timed(longwall(str(SEED004), out=tmp / "seed004"), out=tmp / "seed004")
            print(describe("  seed004", r))
            if r.rc == 0:
                print(f"  wall {r.wall_s:.1f} s (target <= {TARGET_SEED004_S:.0f} s: "
                      f"{verdict(r.wall_s <= TARGET_SEED004_S)}), peak {gb(r.peak_pss)} (target <= "
                      f"{TARGET_SEED004_GB:.0f} GB: {verdict(r.peak_pss <= TARGET_SEED004_GB * 1e9)})")
        runs = {}
        if opts.cycles:
            print("\npeak memory over cycles of seed004's face: longwall run scenarios/panel_100.toml --cycles N")
        for n in opts.cycles:
            runs[n] = timed(longwall(str(PANEL), "--cycles", str(n), out=tmp / f"cycles{n}"), out=tmp / f"cycles{n}")
            print(describe(f"  {n} cycles", runs[n]))
        ok = {n: r for n, r in runs.items() if r.rc == 0}
        if ok:
            low = min(ok)
            for n in sorted(ok):
                if n != low:
                    ratio = ok[n].peak_pss / ok[low].peak_pss
                    print(f"  peak at {n} / at {low} cycles: {ratio:.2f}"
                          + (f"   (target <= {TARGET_MEMORY_RATIO} for 100 / 5: {verdict(ratio <= TARGET_MEMORY_RATIO)})"
                             if (low, n) == (5, 100) else ""))
        if 100 in runs:
            r = runs[100]
            print(f"  100 cycles within {TARGET_100_CYCLES_S / 60:.0f} min: "
                  + (verdict(r.wall_s <= TARGET_100_CYCLES_S) if r.rc == 0 else "NOT met (refused or failed)"))


if __name__ == "__main__":
    main()
