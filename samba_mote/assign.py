"""Small assignment problems: tracks to blobs by minimum total cost within gates."""

from __future__ import annotations

import itertools

import numpy as np


def _min_cost_assignment(D: np.ndarray, gate: np.ndarray, C: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Pairs (track, blob) minimising the total squared cost C (T, N) (default D) among gated
    pairs D (T, N) < gate (T,).

    Tracks and blobs split into connected groups of gated pairs; groups up to 5 tracks are
    solved exactly (the injective matching minimising the sum of squared costs, a track left
    unassigned costing its squared gate, so a fresh track keeps its blob rather than giving it
    up to a stale one); bigger groups greedily by cost.
    """
    T, N = D.shape
    okl = (D < gate[:, None]).tolist()
    reach_b = [[b for b in range(N) if okl[t][b]] for t in range(T)]
    reach_t = [[t for t in range(T) if okl[t][b]] for b in range(N)]
    # fast path: a track with a single gated blob that no other track can reach
    pairs: list[tuple[int, int]] = []
    done = [False] * T
    for t in range(T):
        rb = reach_b[t]
        if not rb:
            done[t] = True
        elif len(rb) == 1 and len(reach_t[rb[0]]) == 1:
            pairs.append((t, rb[0]))
            done[t] = True
    if all(done):
        return pairs
    cost = (D if C is None else C).tolist()
    gl = gate.tolist()
    for t0 in range(T):
        if done[t0]:
            continue
        # grow the connected component of tracks and blobs
        tset, bset, frontier = {t0}, set(), [t0]
        while frontier:
            new_b = {b for t in frontier for b in reach_b[t]} - bset
            bset |= new_b
            new_t = {t for b in new_b for t in reach_t[b]} - tset
            tset |= new_t
            frontier = list(new_t)
        for t in tset:
            done[t] = True
        tl, bl = sorted(tset), sorted(bset)
        if len(tl) == 1 and len(bl) == 1:
            pairs.append((tl[0], bl[0]))
            continue
        if len(tl) <= 5 and len(bl) <= 7:
            best_key, best = None, []
            options = [reach_b[t] + [None] for t in tl]
            for combo in itertools.product(*options):
                used = [b for b in combo if b is not None]
                if len(used) != len(set(used)):
                    continue
                key = sum(cost[t][b] ** 2 if b is not None else gl[t] ** 2 for t, b in zip(tl, combo))
                if best_key is None or key < best_key:
                    best_key, best = key, [(t, b) for t, b in zip(tl, combo) if b is not None]
            pairs += best
        else:
            cands = sorted((cost[t][b], t, b) for t in tl for b in reach_b[t])
            used_t, used_b = set(), set()
            for _, t, b in cands:
                if t not in used_t and b not in used_b:
                    pairs.append((t, b))
                    used_t.add(t)
                    used_b.add(b)
    return pairs
