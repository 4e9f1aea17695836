"""A small KD-tree whose k-nearest query is compiled (numba), for the per-frame pose search.

scipy's ``cKDTree.query`` costs about 40 µs per call in fixed overhead on our machines, more
than the whole per-frame budget allows for three searches; this tree answers a 3-D k=10 query
in a few microseconds and can be called from inside other compiled code.

The points are first rotated onto their principal axes (``center``, ``rot``; distances are
unchanged). The tree is a set of flat arrays (:class:`KDTree` holds them): ``perm`` orders the points so
that every node covers ``perm[start[n]:end[n]]``; inner nodes split on ``dim[n]`` at ``val[n]``
into ``left[n]`` and ``right[n]`` (-1 for leaves).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

#: fast-math flags for the compiled kernels: reassociation lets reductions vectorise; no
#: "nnan"/"ninf", which would make NaN tests (missing markers) always false
FAST = {"nsz", "arcp", "contract", "afn", "reassoc"}

LEAF_SIZE = 32


@dataclass
class KDTree:
    """KD-tree over ``data`` (N, D) float64; see the module docstring for the arrays."""

    data: np.ndarray
    perm: np.ndarray
    start: np.ndarray
    end: np.ndarray
    dim: np.ndarray
    val: np.ndarray
    left: np.ndarray
    right: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    center: np.ndarray
    rot: np.ndarray

    @staticmethod
    def build(points: np.ndarray, leaf_size: int = LEAF_SIZE) -> "KDTree":
        """Build over points (N, D): rotated onto their principal axes (distances unchanged, but
        the splits follow the data: about twice as fast on pose features), then split on the
        widest dimension at the median."""
        points = np.asarray(points, dtype=np.float64)
        if len(points) == 0:
            raise ValueError("cannot build a KD-tree over no points")
        center = points.mean(axis=0)
        _u, _s, vt = np.linalg.svd(points - center, full_matrices=False)
        rot = np.ascontiguousarray(vt.T) if vt.shape[0] == points.shape[1] else np.eye(points.shape[1])
        data = np.ascontiguousarray((points - center) @ rot)
        return KDTree(data, *_build(data, leaf_size), center, rot)

    def arrays(self) -> tuple:
        """The tree as a tuple of arrays, the argument form of :func:`knn`."""
        return (self.data, self.perm, self.start, self.end, self.dim, self.val, self.left, self.right, self.lo, self.hi,
                self.center, self.rot)

    def query(self, q: np.ndarray, k: int) -> np.ndarray:
        """Indices (min(k, N),) of the nearest points to q (D,), nearest first."""
        return knn(*self.arrays(), np.ascontiguousarray(q, dtype=np.float64), min(k, len(self.data)))

    def nearest_distance(self, queries: np.ndarray, within: np.ndarray | float = np.inf) -> np.ndarray:
        """Distance (H,) from each of queries (H, D) to its nearest point, in one compiled call;
        inf where no point is nearer than within (scalar or (H,)), which a small bound finds fast."""
        queries = np.ascontiguousarray(queries, dtype=np.float64).reshape(-1, self.data.shape[1])
        bound = np.ascontiguousarray(np.broadcast_to(np.asarray(within, dtype=np.float64), len(queries)))
        return _nearest_distances(*self.arrays(), queries, bound)


@njit(cache=True, fastmath=FAST, nogil=True)
def _build(data, leaf_size):
    """Compiled tree construction: (perm, start, end, dim, val, left, right, lo, hi)."""
    n, D = data.shape
    max_nodes = 2 * (n // max(leaf_size // 2, 1) + 1) + 1
    perm = np.arange(n)
    start = np.empty(max_nodes, np.int64)
    end = np.empty(max_nodes, np.int64)
    dim = np.zeros(max_nodes, np.int64)
    val = np.zeros(max_nodes)
    left = np.full(max_nodes, -1, np.int64)
    right = np.full(max_nodes, -1, np.int64)
    lo = np.empty((max_nodes, D))
    hi = np.empty((max_nodes, D))
    stack = np.empty(max_nodes, np.int64)
    start[0], end[0] = 0, n
    count, sp = 1, 1
    stack[0] = 0
    while sp > 0:
        sp -= 1
        nd = stack[sp]
        a, b = start[nd], end[nd]
        for c in range(D):
            mn, mx = np.inf, -np.inf
            for j in range(a, b):
                v = data[perm[j], c]
                mn = min(mn, v)
                mx = max(mx, v)
            lo[nd, c], hi[nd, c] = mn, mx
        if b - a <= leaf_size:
            continue
        d = 0
        for c in range(1, D):
            if hi[nd, c] - lo[nd, c] > hi[nd, d] - lo[nd, d]:
                d = c
        seg = perm[a:b].copy()
        order = np.argsort(data[seg, d])
        perm[a:b] = seg[order]
        mid = a + (b - a) // 2
        dim[nd], val[nd] = d, data[perm[mid], d]
        for child, (ca, cb) in enumerate(((a, mid), (mid, b))):
            start[count], end[count] = ca, cb
            if child == 0:
                left[nd] = count
            else:
                right[nd] = count
            stack[sp] = count
            sp += 1
            count += 1
    return (perm, start[:count].copy(), end[:count].copy(), dim[:count].copy(), val[:count].copy(),
            left[:count].copy(), right[:count].copy(), lo[:count].copy(), hi[:count].copy())


@njit(cache=True, fastmath=FAST)
def _box_dist(lo, hi, n, q):
    s = 0.0
    for c in range(q.shape[0]):
        if q[c] < lo[n, c]:
            d = lo[n, c] - q[c]
            s += d * d
        elif q[c] > hi[n, c]:
            d = q[c] - hi[n, c]
            s += d * d
    return s


@njit(cache=True, fastmath=FAST)
def knn(data, perm, start, end, dim, val, left, right, lo, hi, center, rot, q_raw, k):
    """k nearest neighbours of q_raw (D,) in the tree; indices (k,) nearest first (compiled)."""
    return _search(data, perm, start, end, dim, val, left, right, lo, hi, center, rot, q_raw, k, np.inf)[0]


@njit(cache=True, fastmath=FAST)
def _search(data, perm, start, end, dim, val, left, right, lo, hi, center, rot, q_raw, k, bound2):
    """The k nearest points to q_raw (D,) closer than sqrt(bound2): (indices (k,), squared
    distances (k,)), nearest first, -1 / inf where fewer are that close.

    Depth-first, nearer child first, pruning nodes whose bounding box is farther than the
    current k-th distance (at first ``bound2``: a small bound prunes most of the tree)."""
    q = np.dot(q_raw - center, rot)
    best_d = np.full(k, bound2)
    best_i = np.full(k, -1, dtype=np.int64)
    stack = np.empty(128, dtype=np.int64)
    stack[0] = 0
    sp = 1
    D = data.shape[1]
    while sp > 0:
        sp -= 1
        nd = stack[sp]
        if _box_dist(lo, hi, nd, q) >= best_d[k - 1]:
            continue
        if left[nd] < 0:
            for j in range(start[nd], end[nd]):
                p = perm[j]
                s = 0.0
                bound = best_d[k - 1]
                for c in range(D):  # the principal axes come first: most points fail early
                    diff = data[p, c] - q[c]
                    s += diff * diff
                    if s >= bound:
                        break
                if s < bound:
                    pos = k - 1
                    while pos > 0 and best_d[pos - 1] > s:
                        best_d[pos] = best_d[pos - 1]
                        best_i[pos] = best_i[pos - 1]
                        pos -= 1
                    best_d[pos] = s
                    best_i[pos] = p
            continue
        if q[dim[nd]] < val[nd]:
            stack[sp] = right[nd]
            stack[sp + 1] = left[nd]
        else:
            stack[sp] = left[nd]
            stack[sp + 1] = right[nd]
        sp += 2
    for j in range(k):
        if best_i[j] < 0:
            best_d[j] = np.inf
    return best_i, best_d


@njit(cache=True, fastmath=FAST)
def _nearest_distances(data, perm, start, end, dim, val, left, right, lo, hi, center, rot, queries, within):
    """Distance (H,) from each row of queries (H, D) to its nearest point, inf where none is
    nearer than within (H,)."""
    out = np.empty(queries.shape[0])
    for h in range(queries.shape[0]):
        d2 = _search(data, perm, start, end, dim, val, left, right, lo, hi, center, rot, queries[h], 1,
                     within[h] * within[h])[1][0]
        out[h] = math.sqrt(d2)
    return out
