"""Check (b): each ram against its neighbours along the AFC chain, and the count of support advances it settles.

The AFC is a chain: neighbouring pans cannot move independently by more than their bend allows. The pan
advance implied by a ram is p_j(t) = reading_j(t) + s_c (advances of support j so far), the same for every
support whatever the order of pushes and advances. A leave-one-out quadratic through the NEIGHBOURS nearest
other supports predicts each p_j; rho = P p are the prediction residuals, and a reading error v at support k
alone makes rho = v P[:, k], so

    v_k = P[:, k] . rho / |P[:, k]|^2 = (A p)_k,    A = diag(1 / |P[:, k]|^2) P^T P,

is each support's reading error (exact for a quadratic face), and of the supports whose patterns overlap the
one whose pattern explains rho best (largest (P[:, k] . rho)^2 / |P[:, k]|^2) is named. A face bent within the
chain's limit, |D2 p| <= B = h^2 tan(bend limit) / l (h the support spacing, l the pan length), gives
|v_k| <= B |c_k|_1 with A_k = D2^T c_k. The threshold on v smoothed by a running median of NEIGHBOUR_WINDOW
readings (confirmed half a window later) is

    tau_k = B |c_k|_1 + NEIGHBOUR_SIGMAS sigma |A_k| 1.2533 / sqrt(NEIGHBOUR_WINDOW),

28 mm inside the default face (B = 31 mm), 92 mm inside seed004's (20 mm noise); about twice that at the two
supports of each face end, which are predicted by extrapolation (and whose fault patterns are over 90 % alike:
estimators.faults.ram_chain merges overlapping findings there).

The pan advance needs each support's count of advances so far; `_pan_advance` settles the count of every drop
of about a stroke (estimators.faults.ram_strokes) on the neighbours.
"""

from __future__ import annotations

import functools

import numpy as np

from estimators.faults.ram_layout import NEIGHBOURS
from estimators.faults.ram_strokes import _Advances

NEIGHBOUR_WINDOW = 15
"""Samples in the running median of the neighbour residual."""
NEIGHBOUR_SIGMAS = 6.0
"""Noise sigmas of the smoothed neighbour residual on top of the bend tolerance."""
MISCOUNT_GAIN = 0.1
"""Strokes squared by which a change of the miscounts must reduce the squared residual to be taken."""
MISCOUNT_LEFT = 0.25
"""Largest share of the squared residual a miscount fit may leave unexplained and still be taken."""
MISCOUNT_RUN = 16
"""Longest run of neighbouring supports whose counts one step of the miscount fit changes together."""


@functools.lru_cache(maxsize=8)
def _neighbour_filter(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, |P[:, k]|^2, noise gain |A_k|, bend gain |c_k|_1) of the single-support fault estimate v = A p for a
    face of n supports (cached: the benchmark checks many logs of one face; do not modify the arrays)."""
    p = np.eye(n)
    for j in range(n):
        order = np.argsort(np.abs(np.arange(n) - j) + 1e-3 * np.arange(n), kind="stable")
        others = np.sort(order[1:NEIGHBOURS + 1])
        x = (others - j).astype(float)
        design = np.column_stack([np.ones_like(x), x, x ** 2])
        p[j, others] -= np.linalg.pinv(design)[0]  # intercept row: the prediction at j
    pp = (p ** 2).sum(axis=0)
    a = (p.T @ p) / pp[:, None]
    d2 = np.zeros((n - 2, n))
    i = np.arange(n - 2)
    d2[i, i], d2[i, i + 1], d2[i, i + 2] = 1.0, -2.0, 1.0
    c = np.linalg.lstsq(d2.T, a.T, rcond=None)[0]  # a_k = d2^T c_k (a kills linear and quadratic faces)
    return a, pp, np.linalg.norm(a, axis=1), np.abs(c).sum(axis=0)


def _apply_banded(a: np.ndarray, p: np.ndarray) -> np.ndarray:
    """p @ a.T using only the non-zero entries of a, so a NaN spreads only to the supports that use it."""
    n = a.shape[0]
    out = np.zeros_like(p)
    for o in range(-(n - 1), n):
        coef = np.diagonal(a, o)  # a[k, k + o]
        if not np.any(np.abs(coef) > 1e-12):
            continue
        ks = np.arange(max(0, -o), min(n, n - o))
        use = np.abs(coef) > 1e-12
        out[:, ks[use]] += coef[use] * p[:, ks[use] + o]
    return out


def _strongest(vs: np.ndarray, a: np.ndarray, pp: np.ndarray) -> np.ndarray:
    """(T, S) mask: the support's fault pattern explains the residuals at least as well as that of any support
    whose pattern overlaps it (score v^2 |P[:, k]|^2; a fault at k moves v_i only where a[i, k] != 0)."""
    n = a.shape[0]
    score = np.nan_to_num(vs ** 2 * pp[None, :], nan=0.0)
    best = score.copy()
    for o in range(1, n):
        near = (np.abs(np.diagonal(a, o)) > 1e-12) | (np.abs(np.diagonal(a, -o)) > 1e-12)  # pairs (k, k + o)
        if not near.any():
            continue
        k = np.flatnonzero(near)
        best[:, k] = np.maximum(best[:, k], score[:, k + o])
        best[:, k + o] = np.maximum(best[:, k + o], score[:, k])
    return score >= best


def _pan_advance(x: np.ndarray, usable: np.ndarray, idxs, advances: list[_Advances], sure: list[np.ndarray],
                 a: np.ndarray, stroke: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """p = reading + stroke x (advances so far), NaN where unusable or while the ram retracts, and the number of
    advances counted at each drop (in the order of `advances`).

    Sure advances count one. The count is then re-anchored on the neighbours at every drop, at the first
    reading and after every stretch of unusable readings, since a support's reading error v = A p moves by
    A[:, k] x stroke for each advance miscounted at support k: the events within NEIGHBOUR_WINDOW samples of
    the first of them on supports whose patterns overlap (and the supports from them on to a face end within
    reach, which may have pushed and advanced within one reading) are solved together: the median v over the
    next NEIGHBOUR_WINDOW readings, or its change from the readings before, fitted with whole miscounts
    (`_miscounts`), unless the error of one support without an event there explains it as well. That drops a sensor drop of about a stroke that is no
    advance (the end of a rail deviation on several supports at once), and counts the advances hidden in a
    dropout or a stuck stretch. A reading error of more than half a stroke at such an event is taken for a
    miscount."""
    n_t, n_sup = x.shape
    pan = np.where(usable, x, np.nan)
    count = np.zeros((n_t, n_sup))
    events = []  # (grid index from which the count changes, support, index in `advances` or -1 for a gap end)
    for j in range(n_sup):
        idx, adv = idxs[j], advances[j]
        for m, (b, k) in enumerate(zip(adv.top_end, adv.post_start)):
            pan[idx[b] + 1:idx[k], j] = np.nan
            events.append((int(idx[k]), j, m))
            if sure[j][m]:
                count[idx[k]:, j] += 1.0
        if idx.size:  # the first reading (a log may start in mid-cycle) and the first after each gap
            events += [(int(idx[0]), j, -1)] + [(int(idx[g + 1]), j, -1) for g in np.flatnonzero(np.diff(idx) > 1)]
    events.sort()
    v = _apply_banded(a, pan + stroke * count)
    band = max(abs(o) for o in range(-(n_sup - 1), n_sup) if np.any(np.abs(np.diagonal(a, o)) > 1e-12))
    fixes: dict[tuple[int, int], float] = {}
    k = prev = 0
    while k < len(events):  # clusters of events close in time
        end = k + 1
        while end < len(events) and events[end][0] - events[k][0] <= NEIGHBOUR_WINDOW:
            end += 1
        cluster, k = events[k:end], end
        stop = min(events[end][0] if end < len(events) else n_t, n_t)  # v up to the next cluster
        sups = sorted({j for _, j, _ in cluster})
        groups, cur = [], [sups[0]]
        for j in sups[1:]:
            if j - cur[-1] <= band:
                cur.append(j)
            else:
                groups.append(cur)
                cur = [j]
        groups.append(cur)
        for g in groups:
            last = {j: (i, m) for i, j, m in cluster if j in g}  # the last event of each support
            t0 = max(i for i, _ in last.values())
            t_first = min(i for i, _ in last.values())
            # the supports from the group on to a face end within reach may have advanced unseen (a push and
            # an advance within one reading, as at a face end): they may take a count too
            lo_g = 0 if g[0] <= 3 * band else g[0]
            hi_g = n_sup - 1 if g[-1] >= n_sup - 1 - 3 * band else g[-1]
            for j in [*range(lo_g, g[0]), *range(g[-1] + 1, hi_g + 1)]:
                last[j] = (t0, None)
            g = sorted(last)
            rows = np.arange(max(g[0] - band, 0), min(g[-1] + band, n_sup - 1) + 1)
            after = _near_median(v[t0:max(min(t0 + 3 * NEIGHBOUR_WINDOW, stop), t0 + 1), rows])
            before = _near_median(v[max(t_first - 3 * NEIGHBOUR_WINDOW, prev, 0):t_first, rows][::-1])
            ok = np.isfinite(after)
            if not ok.any():
                continue
            # v after the events is whole miscounts, and a sensor error that either vanished with them (the end
            # of a rail deviation) or went on through them (a drift at an advance)
            design = stroke * a[np.ix_(rows[ok], g)]
            best = None
            for obs in (after[ok], after[ok] - np.nan_to_num(before[ok])):
                miss = _miscounts(design, obs, stroke)
                if miss.any():
                    left = ((obs - design @ miss) ** 2).sum()
                    if best is None or left / (obs ** 2).sum() < best[2]:
                        best = (miss, obs, left / (obs ** 2).sum())
            if best is None:
                continue
            miss, obs, share = best
            # a sensor error of a support without an event here (a stuck ram) that explains v as well is no
            # miscount of its neighbours
            others = a[np.ix_(rows[ok], [r for r in rows if r not in last])]
            norm2 = (others ** 2).sum(axis=0)
            fit = np.divide((obs @ others) ** 2, norm2, out=np.zeros_like(norm2), where=norm2 > 0)
            if others.size and (obs ** 2).sum() - fit.max() <= share * (obs ** 2).sum():
                continue
            for j, n_miss in zip(g, miss):
                if n_miss:
                    i, m = last[j]
                    if m is not None:
                        fixes[(j, m)] = fixes.get((j, m), 0.0) - n_miss
                    count[i:, j] -= n_miss
                    v[i:] -= stroke * n_miss * a[:, j][None, :]
        prev = cluster[-1][0]
    p = pan + stroke * count
    n_counted = [np.array([float(sure[j][m]) + fixes.get((j, m), 0.0) for m in range(advances[j].top.size)])
                 for j in range(n_sup)]
    return p, n_counted


def _near_median(seg: np.ndarray) -> np.ndarray:
    """Per column, the median of the first NEIGHBOUR_WINDOW finite values (NaN if none)."""
    out = np.full(seg.shape[1], np.nan)
    for r in range(seg.shape[1]):
        fin = seg[np.isfinite(seg[:, r]), r][:NEIGHBOUR_WINDOW]
        if fin.size:
            out[r] = np.median(fin)
    return out


def _miscounts(design: np.ndarray, obs: np.ndarray, stroke: float) -> np.ndarray:
    """Whole miscounts m (one per column, columns in support order) with obs ~ design @ m: from m = 0, the
    change by one of a run of neighbouring counts (a block of neighbours miscounted together looks almost like a
    smooth face: only its edges show, so single changes alone do not find it), or of two neighbours in opposite
    senses, that reduces |obs - design m|^2 most, while it reduces it by more than MISCOUNT_GAIN strokes
    squared; taken only if it leaves at most MISCOUNT_LEFT of |obs|^2."""
    n = design.shape[1]
    if (obs ** 2).sum() <= MISCOUNT_GAIN * stroke ** 2:  # no change can gain more than all there is
        return np.zeros(n)
    moves = []
    for k in range(n):
        for end in range(k + 1, min(k + MISCOUNT_RUN, n) + 1):  # a run of neighbours, all one more or one less
            step = np.zeros(n)
            step[k:end] = 1.0
            moves += [step, -step]
    for k in range(1, n):  # every count from one end of the group on (a face end that advanced unseen)
        step = np.zeros(n)
        step[k:] = 1.0
        moves += [step, -step, step[::-1].copy(), -step[::-1]]
    for k in range(n - 1):  # one more and one less next to each other
        step = np.zeros(n)
        step[k], step[k + 1] = 1.0, -1.0
        moves += [step, -step]
    moves = np.array(moves).T  # (n, moves)
    miss = np.zeros(n)
    resid = obs.copy()
    for _ in range(4 * n):
        after = resid[:, None] - design @ moves
        gain = (resid ** 2).sum() - (after ** 2).sum(axis=0)
        k = int(np.argmax(gain))
        if gain[k] <= MISCOUNT_GAIN * stroke ** 2:
            break
        miss += moves[:, k]
        resid = after[:, k]
    # miscounts explain the residual nearly whole; a fit that leaves much is a sensor error, not a count
    return miss if (resid ** 2).sum() <= MISCOUNT_LEFT * (obs ** 2).sum() else np.zeros(n)
