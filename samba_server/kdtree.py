"""A small KD-tree whose k-nearest query is compiled (numba), for the per-frame pose search.

scipy's ``cKDTree.query`` costs about 40 µs per call in fixed overhead on our machines, more
than the whole per-frame budget allows for three searches; this tree answers a 3-D k=10 query
in a few microseconds and can be called from inside other compiled code.

The tree is a set of flat arrays (:class:`KDTree` holds them): ``perm`` orders the points so
that every node covers ``perm[start[n]:end[n]]``; inner nodes split on ``dim[n]`` at ``val[n]``
into ``left[n]`` and ``right[n]`` (-1 for leaves).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

LEAF_SIZE = 16


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

    @staticmethod
    def build(points: np.ndarray, leaf_size: int = LEAF_SIZE) -> "KDTree":
        """Build over points (N, D) (split on the widest dimension at the median)."""
        data = np.ascontiguousarray(points, dtype=np.float64)
        n = len(data)
        if n == 0:
            raise ValueError("cannot build a KD-tree over no points")
        perm = np.arange(n, dtype=np.int64)
        start, end, dim, val, left, right = [], [], [], [], [], []

        def node(lo: int, hi: int) -> int:
            i = len(start)
            start.append(lo)
            end.append(hi)
            dim.append(0)
            val.append(0.0)
            left.append(-1)
            right.append(-1)
            if hi - lo > leaf_size:
                pts = data[perm[lo:hi]]
                d = int(np.argmax(pts.max(axis=0) - pts.min(axis=0)))
                mid = (hi - lo) // 2
                order = np.argpartition(pts[:, d], mid)
                perm[lo:hi] = perm[lo:hi][order]
                dim[i] = d
                val[i] = float(data[perm[lo + mid], d])
                left[i] = node(lo, lo + mid)
                right[i] = node(lo + mid, hi)
            return i

        import sys

        limit = sys.getrecursionlimit()
        sys.setrecursionlimit(max(limit, 10_000))
        try:
            node(0, n)
        finally:
            sys.setrecursionlimit(limit)
        as_i = lambda a: np.asarray(a, dtype=np.int64)  # noqa: E731
        box_lo = np.array([data[perm[a:b]].min(axis=0) for a, b in zip(start, end)])
        box_hi = np.array([data[perm[a:b]].max(axis=0) for a, b in zip(start, end)])
        return KDTree(data, perm, as_i(start), as_i(end), as_i(dim), np.asarray(val, np.float64), as_i(left),
                      as_i(right), box_lo, box_hi)

    def arrays(self) -> tuple:
        """The tree as a tuple of arrays, the argument form of :func:`knn`."""
        return (self.data, self.perm, self.start, self.end, self.dim, self.val, self.left, self.right, self.lo, self.hi)

    def query(self, q: np.ndarray, k: int) -> np.ndarray:
        """Indices (min(k, N),) of the nearest points to q (D,), nearest first."""
        return knn(*self.arrays(), np.ascontiguousarray(q, dtype=np.float64), min(k, len(self.data)))


@njit(cache=True)
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


@njit(cache=True)
def knn(data, perm, start, end, dim, val, left, right, lo, hi, q, k):
    """k nearest neighbours of q (D,) in the tree; indices (k,) nearest first (compiled).

    Depth-first, nearer child first, pruning nodes whose bounding box is farther than the
    current k-th distance."""
    best_d = np.full(k, np.inf)
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
                for c in range(D):
                    diff = data[p, c] - q[c]
                    s += diff * diff
                if s < best_d[k - 1]:
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
    return best_i
