"""Checks (a) and (b) together along the chain of supports: each support's flagged stretches and their kind, the
face ends' merged findings, and the runs of supports that make one lateral rail deviation.

The neighbour check's flagged runs (estimators.faults.ram_neighbours) shorter than MIN_FLAGGED readings, or lying
inside a longer one two supports away or less, are the attribution flicking and are dropped. At each face end the
last two supports' fault patterns are over 90 % alike, so overlapping findings there are merged.

A support's flagged stretch (the neighbour flags and its failed strokes, MERGE_GAP apart at most) is classified
on its flagged readings by fitting v with a constant, with c r and with a + b t:

* stuck   (a sensor finer than its quantum) the reading stays put while v moves by more than tau;
* scale   c r beats the constant by MODEL_SIGMAS residual sigmas and c explains more than tau / 2 over the
          stretch, r = reading - v the true ram length: the error grows with the extension (value: c, the
          relative error); a stretch only the stroke check saw is a scale error too. Without a stroke in the
          window a scale error reads as an offset (c times the rest length);
* drift   a + b t beats the constant so, b explains more than tau / 2 (value: b [m/s]; the window starts where
          the line crosses zero);
* offset  otherwise (value: median v).

A run of at least RAIL_MIN_SUPPORTS supports, each within RAIL_REACH of another, flagged by (a) or (b) at
overlapping times (RAIL_GAP readings apart at most) is one lateral deviation over the run (`rail_deviation`:
004's deviated rail seen by the supports it covers as the shearer passes; the deviation is smooth along the run,
so the chain check sees its moving end, one support after the other).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from estimators.faults.ram_findings import Finding
from estimators.faults.ram_grid import _running_median, _runs, _runs_1d
from estimators.faults.ram_layout import RamLayout
from estimators.faults.ram_neighbours import (
    NEIGHBOUR_SIGMAS,
    NEIGHBOUR_WINDOW,
    _apply_banded,
    _neighbour_filter,
    _pan_advance,
    _strongest,
)
from estimators.faults.ram_self_checks import _flat_run
from estimators.faults.ram_strokes import _advances, _Stroke, _stroke_checks

MIN_FLAGGED = NEIGHBOUR_WINDOW // 2 + 1
"""Fewest consecutive flagged samples of the neighbour check that count (shorter: the attribution flicked)."""
MERGE_GAP = 8 * NEIGHBOUR_WINDOW
"""Samples between two flagged stretches of one support that still make one finding."""
MODEL_SIGMAS = 5.0
"""Significance (in sigmas of the residual scatter) with which a scale or drift model must beat a constant."""
RAIL_MIN_SUPPORTS = 3
"""Fewest supports flagged together that make a lateral deviation of the rail."""
RAIL_REACH = 2
"""Supports apart that still join one run."""
RAIL_GAP = 4 * NEIGHBOUR_WINDOW
"""Readings between two findings of one run."""


def _classify(j: int, lo: int, hi: int, tg, x, v, vs, thr, strokes: list[_Stroke], flat_ok: bool) -> Finding:
    """One finding for support j's flagged stretch lo..hi (grid indices): the neighbour check's flagged readings
    decide the kind; a stretch only the stroke check saw is a scale error."""
    n_t = len(tg)
    own = [s for s in strokes if s.support == j and s.last >= lo and s.first <= hi]
    confirmed = min([s.confirmed for s in own], default=n_t - 1)
    span = np.arange(lo, hi + 1)
    hot = span[np.isfinite(vs[span, j]) & (np.abs(np.nan_to_num(vs[span, j])) > thr[j])]
    use = hot[np.isfinite(v[hot, j]) & np.isfinite(x[hot, j])]
    if use.size < 3:
        if own:
            s = max(own, key=lambda s: abs(s.error))
            return Finding(j, j, "scale", tg[lo], tg[hi], tg[confirmed], s.relative, s.error, s.threshold, "m")
        stat = float(vs[hot[np.argmax(np.abs(vs[hot, j]))], j])
        return Finding(j, j, "offset", tg[hot[0]], tg[hot[-1]], tg[min(hot[0] + NEIGHBOUR_WINDOW // 2, n_t - 1)],
                       stat, stat, float(thr[j]), "m")
    confirmed = min(confirmed, hot[0] + NEIGHBOUR_WINDOW // 2, n_t - 1)
    first, last = tg[hot[0]], tg[hot[-1]]
    t, e = tg[use], v[use, j]
    r = x[use, j] - e  # the true ram length, as the neighbours see it
    stat = float(vs[hot[np.argmax(np.abs(vs[hot, j]))], j])
    tau = float(thr[j])
    if not flat_ok:  # a reading that stays put while the neighbours say the ram moved
        col = x[:, j]
        lo_f = hi_f = int(use[0])
        while lo_f > 0 and col[lo_f - 1] == col[lo_f]:  # back to where the reading froze
            lo_f -= 1
        while hi_f < hi and col[hi_f + 1] == col[hi_f]:
            hi_f += 1
        frozen = use[use <= hi_f]
        if frozen.size >= MIN_FLAGGED and np.ptp(v[lo_f:hi_f + 1, j][np.isfinite(v[lo_f:hi_f + 1, j])]) > tau:
            return Finding(j, j, "stuck", tg[lo_f], tg[hi_f], tg[confirmed], float(col[lo_f]), stat, tau, "m")
    rss_const = float(((e - e.mean()) ** 2).sum())
    c = float(e @ r / (r @ r))
    rss_scale = float(((e - c * r) ** 2).sum())
    tc = t - t.mean()
    slope = float(tc @ e / (tc @ tc)) if tc @ tc > 0 else 0.0
    rss_drift = float(((e - e.mean() - slope * tc) ** 2).sum())
    var = max(min(rss_scale, rss_drift), 1e-30) / max(e.size - 2, 1)  # scatter about the better model
    gain = MODEL_SIGMAS ** 2 * var  # a model must explain this much more than a constant
    is_scale = rss_const - rss_scale > gain and abs(c) * np.ptp(r) > 0.5 * tau
    is_drift = rss_const - rss_drift > gain and abs(slope) * (t[-1] - t[0]) > 0.5 * tau
    if is_scale and (not is_drift or rss_scale <= rss_drift):
        return Finding(j, j, "scale", first, last, tg[confirmed], c, stat, tau, "m")
    if is_drift:
        start = min(max(float(t.mean() - e.mean() / slope), tg[0]), first)
        return Finding(j, j, "drift", start, last, tg[confirmed], slope, stat, tau, "m")
    return Finding(j, j, "offset", first, last, tg[confirmed], float(np.median(e)), stat, tau, "m")


def _end_pairs(chain: list[Finding], n_sup: int, gap: float) -> list[Finding]:
    """At each face end the last two supports' fault patterns are nearly alike (one side only: the pattern of
    support 0 and that of support 1 are over 90 % parallel), so the attribution may flick between them: of two
    overlapping findings there, keep the longer, stretched over both windows."""
    out = list(chain)
    for pair in ((0, 1), (n_sup - 2, n_sup - 1)):
        changed = True
        while changed:
            changed = False
            ends = [f for f in out if f.support in pair and f.last_support == f.support]
            for f in ends:
                for g in ends:
                    if (f is not g and f.support != g.support and f.t_start <= g.t_end + gap
                            and g.t_start <= f.t_end + gap):
                        keep, drop = (f, g) if f.t_end - f.t_start >= g.t_end - g.t_start else (g, f)
                        merged = dataclasses.replace(keep, t_start=min(keep.t_start, drop.t_start),
                                                     t_end=max(keep.t_end, drop.t_end),
                                                     t_detect=min(keep.t_detect, drop.t_detect))
                        out = [merged if h is keep else h for h in out if h is not drop]
                        changed = True
                        break
                if changed:
                    break
    return out


def _rail_runs(findings: list[Finding], dt: float) -> list[Finding]:
    """Merge chain findings on RAIL_MIN_SUPPORTS or more neighbouring supports at overlapping times into one
    rail_deviation finding each."""
    n = len(findings)
    if n < RAIL_MIN_SUPPORTS:
        return findings
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    gap = RAIL_GAP * dt
    for i in range(n):
        for k in range(i + 1, n):
            fi, fk = findings[i], findings[k]
            if (fi.support != fk.support and abs(fi.support - fk.support) <= RAIL_REACH
                    and fi.t_start <= fk.t_end + gap and fk.t_start <= fi.t_end + gap):
                parent[root(i)] = root(k)
    groups: dict[int, list[Finding]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(findings[i])
    out = []
    for members in groups.values():
        sups = sorted({f.support for f in members})
        if len(sups) < RAIL_MIN_SUPPORTS:
            out.extend(members)
            continue
        seen: set[int] = set()
        confirmed = members[0].t_detect
        for f in sorted(members, key=lambda f: f.t_detect):
            seen.add(f.support)
            if len(seen) >= RAIL_MIN_SUPPORTS:
                confirmed = f.t_detect
                break
        lateral = [f.value for f in members if f.kind in ("offset", "stuck")] or [f.statistic for f in members]
        big = max(members, key=lambda f: abs(f.statistic) / f.threshold)
        out.append(Finding(sups[0], sups[-1], "rail_deviation", min(f.t_start for f in members),
                           max(f.t_end for f in members), confirmed, float(max(lateral, key=abs)),
                           big.statistic, big.threshold, big.unit))
    return out


def _chain_checks(tg: np.ndarray, x: np.ndarray, usable: np.ndarray, layout: RamLayout) -> list[Finding]:
    """Checks (a) and (b) on the usable readings: one finding per flagged stretch of a support."""
    n_sup = x.shape[1]
    idxs, candidates, sure = _advances(x, usable, layout)
    # (b) neighbour consistency: each support's reading error against the chain of its neighbours
    a, pp, noise_gain, bend_gain = _neighbour_filter(n_sup)
    pan, counts = _pan_advance(x, usable, idxs, candidates, sure, a, layout.stroke_m)
    v = _apply_banded(a, pan)
    # (a) commanded stroke, on the drops the neighbours confirm as advances
    strokes = _stroke_checks(x, idxs, [c.keep(n >= 1) for c, n in zip(candidates, counts)], layout,
                             [idx[c.post_start] for idx, c in zip(idxs, candidates)])
    vs = _running_median(v, NEIGHBOUR_WINDOW)
    thr = layout.bend_m * bend_gain + NEIGHBOUR_SIGMAS * layout.sigma_m * noise_gain * 1.2533 / math.sqrt(
        NEIGHBOUR_WINDOW)
    flag = (np.abs(np.nan_to_num(vs)) > thr[None, :]) & _strongest(vs, a, pp)
    for j, lo, hi in zip(*_runs(flag)):  # a flick of the attribution to a neighbour is no finding
        if hi - lo + 1 < MIN_FLAGGED:
            flag[lo:hi + 1, j] = False
    # stretches per support: neighbour flags and failed strokes, merged; a stretch inside a longer one of a
    # support two or fewer away is that fault's spill-over
    chain: list[Finding] = []
    flat_ok = _flat_run(layout) is not None
    for j in range(n_sup):
        marks = flag[:, j].copy()
        for s in strokes:
            if s.support == j:
                marks[s.first:s.last + 1] = True
        for lo, hi in _runs_1d(marks, gap=MERGE_GAP):
            chain.append(_classify(j, lo, hi, tg, x, v, vs, thr, strokes, flat_ok))
    return [f for f in chain if not any(g is not f and 0 < abs(g.support - f.support) <= 2
                                        and g.t_start <= f.t_start and f.t_end <= g.t_end
                                        and g.t_end - g.t_start > f.t_end - f.t_start for g in chain)]
