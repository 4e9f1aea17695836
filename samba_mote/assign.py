"""Small assignment problems: tracks to blobs by minimum total cost within gates."""

from __future__ import annotations

import numpy as np


def _min_cost_assignment(D: np.ndarray, gate, C: np.ndarray | None = None, penalty=None,
                         penalty_scale: float = 1.0) -> list[tuple[int, int]]:
    """Pairs (track, blob) minimising the total squared cost C (T, N) (default D, plus
    penalty_scale x penalty[t] per track when penalty (T,) is given: computed only if a conflict
    needs it) among gated pairs D (T, N) < gate (T,) (an array or a list of floats).

    Tracks and blobs split into connected groups of gated pairs; groups up to 5 tracks are
    solved exactly (the injective matching minimising the sum of squared costs, a track left
    unassigned costing its squared gate, so a fresh track keeps its blob rather than giving it
    up to a stale one); bigger groups greedily by cost.
    """
    T, N = D.shape
    gl = gate.tolist() if isinstance(gate, np.ndarray) else list(gate)
    ti, bi = (D < np.array(gl)[:, None]).nonzero()  # gated pairs, row-major (t, then b ascending)
    reach_b: list[list[int]] = [[] for _ in range(T)]
    reach_t: list[list[int]] = [[] for _ in range(N)]
    for t, b in zip(ti.tolist(), bi.tolist()):
        reach_b[t].append(b)
        reach_t[b].append(t)
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
    pen = None
    if C is None and penalty is not None and any(penalty):
        pen = [penalty_scale * x for x in penalty]
    for t0 in range(T):
        if done[t0]:
            continue
        # grow the connected component of tracks and blobs (breadth first)
        comp_t, comp_b, seen_t, seen_b = [t0], [], {t0}, set()
        i = 0
        while i < len(comp_t):
            for b in reach_b[comp_t[i]]:
                if b not in seen_b:
                    seen_b.add(b)
                    comp_b.append(b)
                    for t in reach_t[b]:
                        if t not in seen_t:
                            seen_t.add(t)
                            comp_t.append(t)
            i += 1
        for t in comp_t:
            done[t] = True
        tl = sorted(comp_t)
        if len(tl) == 1 and len(comp_b) == 1:
            pairs.append((tl[0], comp_b[0]))
            continue
        if len(tl) <= 5 and len(comp_b) <= 7:
            if pen is None:
                options = [[(b, cost[t][b] ** 2) for b in reach_b[t]] + [(None, gl[t] ** 2)] for t in tl]
            else:
                options = [[(b, (cost[t][b] + pen[t]) ** 2) for b in reach_b[t]] + [(None, gl[t] ** 2)]
                           for t in tl]
            pairs += [(t, b) for t, b in zip(tl, _best_injective(options)) if b is not None]
        else:
            if pen is None:
                cands = sorted((cost[t][b], t, b) for t in tl for b in reach_b[t])
            else:
                cands = sorted((cost[t][b] + pen[t], t, b) for t in tl for b in reach_b[t])
            used_t, used_b = set(), set()
            for _, t, b in cands:
                if t not in used_t and b not in used_b:
                    pairs.append((t, b))
                    used_t.add(t)
                    used_b.add(b)
    return pairs


def _best_injective(options: list[list[tuple[int | None, float]]]) -> list[int | None]:
    """One choice per track from options[i] = [(blob or None, squared cost), ...] (blobs
    ascending, None last), no blob chosen twice, minimising the summed cost; among equal sums
    the first in lexicographic (itertools.product) order. Depth-first with pruning: partial
    sums only grow, so a branch already at or above the best total is skipped."""
    k = len(options)
    if k == 2:  # the common case, without recursion
        o1 = options[1]
        best2: tuple[int | None, int | None] = (None, None)
        key2 = float("inf")
        found2 = False
        for b0, c0 in options[0]:
            s0 = 0 + c0
            for b1, c1 in o1:
                if b1 is not None and b1 == b0:
                    continue
                s1 = s0 + c1
                if not found2 or s1 < key2:
                    best2, key2, found2 = (b0, b1), s1, True
        return list(best2)
    chosen: list[int | None] = [None] * k
    best: list[int | None] = []
    best_key = float("inf")
    found = False
    used: set[int] = set()

    def rec(i: int, s: float) -> None:
        nonlocal best, best_key, found
        if i == k:
            if not found or s < best_key:
                best, best_key, found = chosen.copy(), s, True
            return
        for b, c2 in options[i]:
            if b is not None and b in used:
                continue
            s2 = s + c2
            if found and s2 >= best_key:
                continue
            chosen[i] = b
            if b is None:
                rec(i + 1, s2)
            else:
                used.add(b)
                rec(i + 1, s2)
                used.discard(b)

    rec(0, 0)
    return best
