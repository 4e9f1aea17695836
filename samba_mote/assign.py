"""Small assignment problems: tracks to blobs by minimum total distance within gates."""

from __future__ import annotations

import itertools

import numpy as np


def _min_cost_assignment(D: np.ndarray, gate: np.ndarray, C: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Pairs (track, blob) minimising the total cost C (T, N) (default D) among gated pairs
    D (T, N) < gate (T,).

    Tracks and blobs split into connected groups of gated pairs; groups up to 5 tracks are
    solved exactly (the injective matching minimising the sum of squared costs, a track left
    unassigned costing its squared gate, so a fresh track keeps its blob rather than giving it
    up to a stale one); bigger groups greedily by cost.
    """
    ok = D < gate[:, None]
    if C is not None:
        D = C
    pairs: list[tuple[int, int]] = []
    T, N = D.shape
    # fast path: a track with a single gated blob that no other track can reach
    row = ok.sum(axis=1)
    col = ok.sum(axis=0)
    single = ok & (row[:, None] == 1) & (col[None, :] == 1)
    ts, bs = np.nonzero(single)
    pairs += list(zip(ts.tolist(), bs.tolist()))
    seen_t = single.any(axis=1) | (row == 0)
    if seen_t.all():
        return pairs
    for t0 in range(T):
        if seen_t[t0]:
            continue
        # grow the connected component
        ts, bs = {t0}, set()
        frontier_t = [t0]
        while frontier_t:
            new_b = set()
            for t in frontier_t:
                new_b |= set(np.flatnonzero(ok[t]).tolist())
            new_b -= bs
            bs |= new_b
            new_t = set()
            for b in new_b:
                new_t |= set(np.flatnonzero(ok[:, b]).tolist())
            new_t -= ts
            ts |= new_t
            frontier_t = list(new_t)
        for t in ts:
            seen_t[t] = True
        tl, bl = sorted(ts), sorted(bs)
        if len(tl) == 1 and len(bl) == 1:
            pairs.append((tl[0], bl[0]))
            continue
        if len(tl) <= 5 and len(bl) <= 7:
            best_key, best = None, []
            options = [[b for b in bl if ok[t, b]] + [None] for t in tl]
            for combo in itertools.product(*options):
                used = [b for b in combo if b is not None]
                if len(used) != len(set(used)):
                    continue
                # squared cost of each pair; a track left out costs its squared gate
                key = sum(D[t, b] ** 2 if b is not None else gate[t] ** 2 for t, b in zip(tl, combo))
                if best_key is None or key < best_key:
                    best_key, best = key, [(t, b) for t, b in zip(tl, combo) if b is not None]
            pairs += best
        else:
            sub = [(D[t, b], t, b) for t in tl for b in bl if ok[t, b]]
            used_t, used_b = set(), set()
            for _, t, b in sorted(sub):
                if t not in used_t and b not in used_b:
                    pairs.append((t, b))
                    used_t.add(t)
                    used_b.add(b)
    return pairs
