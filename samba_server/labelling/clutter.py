"""Static reflections in the views: blobs that sit still and that no name ever uses.

A lamp or a shiny fitting near the body is a blob in one view that the epipolar search pairs with
markers' blobs of other views: two shoulders' blobs in two cameras crossed with such a blob in a
third made a 3-view ghost (0.32 px) between the shoulders that went before their own 2-view
points (0.0 px), and a shoulder was named on it 35 cm off for 0.3 s (633 005_14). The motes'
static mask (:class:`samba_mote.detect.StaticMask`) learns them over tens of seconds; a take
that starts with the subject already in the volume has them from its first frame.

:class:`StillBlobs` remembers, per view, where blobs sat still (within ``still_px``) and since
when, and forgets a position as soon as a named marker's point uses its blob (a marker standing
still is named, clutter never is); once a position is clutter, only an identification's names
clear it, not tracking's. A blob still for ``still_s`` counts as clutter: the points stage ranks
the candidates that use it one view fewer (:meth:`PointReconstructor.reconstruct`), and a point
fewer than two views see in blobs that are not clutter (:func:`on_clutter`) is no marker for
tracking (:meth:`Labeller._real`). A marker seen by one view only while it stands still long
enough is taken for clutter too: it stays unnamed until it moves or an identification names it.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .blobs import ViewBlobs

__all__ = ["StillBlobs", "on_clutter", "warm_up"]


class StillBlobs:
    """Per view, the blobs that sat still with no name on them (static reflections).

    still_s: seconds a blob must sit still, never named, to count as clutter (inf: never);
    still_px: how still (px); gap_s: a position no blob came back to for this long starts
    over (a moving marker leaves one per frame); forget_s: ... or, once clutter, this long
    (the body may hide a reflection for a while). Per frame, :meth:`clutter` before the points
    stage, :meth:`update` once the markers are named."""

    def __init__(self, still_s: float, still_px: float, gap_s: float = 0.25, forget_s: float = 2.0) -> None:
        self.still_s, self.still_px, self.gap_s, self.forget_s = still_s, still_px, gap_s, forget_s
        #: per view: pos (K, 2) px running means, n (K,) frames averaged (capped), since (K,) s still
        #: (and unnamed) since, seen (K,) s last frame a blob was there
        self._state: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._matched: tuple[list, list[np.ndarray]] = ([], [])  # (views, (N,) position of each blob or -1)

    def _view(self, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        while len(self._state) <= c:
            self._state.append((np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0)))
        return self._state[c]

    def clutter(self, views: list[ViewBlobs], t: float) -> list[np.ndarray]:
        """Per view (N,) bool: the blob of views (this frame's, rig order) sits where a blob sat
        still and unnamed for still_s up to t (s)."""
        if not np.isfinite(self.still_s):
            return [np.zeros(len(v), bool) for v in views]
        out, matched = [], []
        for c, v in enumerate(views):
            pos, _n, since, _seen = self._view(c)
            j, flag = _match(pos, since, np.asarray(v.uv, float).reshape(-1, 2), self.still_px, t, self.still_s)
            matched.append(j)
            out.append(flag)
        self._matched = (views, matched)
        return out

    def static(self, t: float) -> list[np.ndarray]:
        """Per view (K, 2) px: the positions that are clutter at t (s, the last frame learnt)
        and were seen within gap_s of it."""
        return [pos[(t - since >= self.still_s) & (t - seen <= self.gap_s)].copy() for pos, _n, since, seen in self._state]

    def seed(self, static: list[np.ndarray], t: float) -> None:
        """Start from static's positions (per view (K, 2) px, :meth:`static` of a pass over the
        same take) as clutter learnt by t (s): a reflection stays where it is, and a pass that
        starts with the subject standing still learns nothing for still_s (``samba-process``'s
        backward pass)."""
        self._state = [(p.copy(), np.full(len(p), 50, np.int64), np.full(len(p), -np.inf), np.full(len(p), t))
                       for p in static]

    def update(self, views: list[ViewBlobs], named: np.ndarray, t: float, identified: bool = False) -> None:
        """Learn from one frame: views (rig order); named (8, C) the blob per view of each named
        marker (-1: none; :meth:`Labeller._blobs_of`); t s (increasing); identified: the names
        come from an identification (against the body), not from tracking: they clear clutter
        too."""
        if not np.isfinite(self.still_s):
            return
        same = self._matched[0] is views
        for c, v in enumerate(views):
            pos, n, since, seen = self._view(c)
            uv = np.asarray(v.uv, float).reshape(-1, 2)
            j = self._matched[1][c] if same else _match(pos, since, uv, self.still_px, t, self.still_s)[0]
            marks = np.ascontiguousarray(named[:, c], np.int64)
            self._state[c] = _learn(pos, n, since, seen, uv, j, marks, t, self.gap_s, self.forget_s, self.still_s,
                                    identified)
        self._matched = ([], [])


def on_clutter(blob: np.ndarray, clutter: list[np.ndarray] | None) -> np.ndarray:
    """(K,) how many views see each point or candidate of blob (C, K) (index per view, -1 =
    none) in a blob that clutter (per view (N,) bool, :meth:`StillBlobs.clutter`; None: none)
    marks."""
    out = np.zeros(blob.shape[1], np.int64)
    for c, cl in enumerate(clutter or []):
        if cl.any():
            has = blob[c] >= 0
            out[has] += cl[blob[c, has]]
    return out


def warm_up() -> None:
    """Compile the kernels (the first run on a machine) or load them from disk now, not on the
    first live frame."""
    pos, since = np.zeros((1, 2)), np.zeros(1)
    j, _ = _match(pos, since, np.zeros((1, 2)), 0.5, 0.0, 2.0)
    _learn(pos, np.ones(1, np.int64), since, since, np.zeros((1, 2)), j, np.full(1, -1, np.int64), 0.0, 0.25, 2.0, 2.0,
           False)


@njit(cache=True)
def _match(pos: np.ndarray, since: np.ndarray, uv: np.ndarray, radius: float, t: float,
           still_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(N,) the position of pos (K, 2) px each blob uv (N, 2) px lies nearest, within radius
    (-1: none), and (N,) bool: that position was still since (K,) s at least still_s before t."""
    N, K = len(uv), len(pos)
    j = np.full(N, -1, np.int64)
    flag = np.zeros(N, np.bool_)
    r2 = radius * radius
    for i in range(N):
        best = r2
        for k in range(K):
            du, dv = uv[i, 0] - pos[k, 0], uv[i, 1] - pos[k, 1]
            d2 = du * du + dv * dv
            if d2 <= best:
                best, j[i] = d2, k
        if j[i] >= 0:
            flag[i] = t - since[j[i]] >= still_s
    return j, flag


@njit(cache=True)
def _learn(pos: np.ndarray, n: np.ndarray, since: np.ndarray, seen: np.ndarray, uv: np.ndarray, j: np.ndarray,
           marks: np.ndarray, t: float, gap_s: float, forget_s: float, still_s: float,
           identified: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One frame learnt: each blob uv (N, 2) px on its position j (N,) (-1: a new one) moves
    that position's running mean and marks it seen at t; a blob some marker is named on (marks:
    the named markers' blob indices, -1 = none) restarts its position's stillness, unless the
    position is clutter already and the names are tracking's (not ``identified``); positions
    gone longer than gap_s (learnt clutter: forget_s) are dropped. Returns the new (pos, n,
    since, seen)."""
    N, K = len(uv), len(pos)
    used = np.zeros(N, np.bool_)
    for b in marks:
        if 0 <= b < N:
            used[b] = True
    pos, n, since, seen = pos.copy(), n.copy(), since.copy(), seen.copy()
    n_new = 0
    for i in range(N):
        k = j[i]
        if k < 0:
            n_new += 1
            continue
        w = min(n[k], 50)
        pos[k, 0] = (pos[k, 0] * w + uv[i, 0]) / (w + 1)
        pos[k, 1] = (pos[k, 1] * w + uv[i, 1]) / (w + 1)
        n[k] += 1
        seen[k] = t
        if used[i] and (identified or t - since[k] < still_s):
            # a name uses it: a marker, not clutter. Not a track's name on learnt clutter: a
            # marker named there, its blob merging with a reflection's, made the reflection a
            # marker, and the name moved onto it (with another view's blob) as the marker left
            # that view (006_02 seed 651: a wrist 38 cm off for 0.8 s)
            since[k] = t
    keep = np.zeros(K, np.bool_)
    for k in range(K):
        absent = t - seen[k]
        keep[k] = absent <= gap_s or (seen[k] - since[k] >= still_s and absent <= forget_s)
    M = int(keep.sum()) + n_new
    pos2, n2, since2, seen2 = np.empty((M, 2)), np.empty(M, np.int64), np.empty(M), np.empty(M)
    m = 0
    for k in range(K):
        if keep[k]:
            pos2[m], n2[m], since2[m], seen2[m] = pos[k], n[k], since[k], seen[k]
            m += 1
    for i in range(N):
        if j[i] < 0:
            pos2[m, 0], pos2[m, 1], n2[m], since2[m], seen2[m] = uv[i, 0], uv[i, 1], 1, t, t
            m += 1
    return pos2, n2, since2, seen2
