"""Static reflections in the views: blobs that sit still and that no name ever uses.

A lamp or a shiny fitting near the body is a blob in one view that the epipolar search pairs with
markers' blobs of other views: two shoulders' blobs in two cameras crossed with such a blob in a
third made a 3-view ghost (0.32 px) between the shoulders that went before their own 2-view
points (0.0 px), and a shoulder was named on it 35 cm off for 0.3 s (633 005_14). The motes'
static mask (:class:`samba_mote.detect.StaticMask`) learns them over tens of seconds; a take
that starts with the subject already in the volume has them from its first frame.

:class:`StillBlobs` remembers, per view, where blobs sat still (within ``still_px``) and since
when, and forgets a position as soon as a named marker's point uses its blob (a marker standing
still is named, clutter never is). A blob still for ``still_s`` counts as clutter: the points
stage ranks the candidates that use it one view fewer (:meth:`PointReconstructor.reconstruct`).
A marker seen by one view only while it stands still long enough is taken for clutter too; its
candidates still make points, they only go after the others.
"""

from __future__ import annotations

import numpy as np

from .blobs import ViewBlobs

__all__ = ["StillBlobs"]


class _ViewStill:
    """Still positions of one view: pos (K, 2) px (running mean), since (K,) s, seen (K,) s."""

    def __init__(self) -> None:
        self.pos = np.zeros((0, 2))
        self.n = np.zeros(0, np.int64)  # frames averaged (capped)
        self.since = np.zeros(0)  # s: still there (and unnamed) since
        self.seen = np.zeros(0)  # s: last frame a blob was there

    def match(self, uv: np.ndarray, radius: float) -> np.ndarray:
        """(N,) index of the position each blob uv (N, 2) px lies within radius of, or -1."""
        out = np.full(len(uv), -1, np.int64)
        if not len(self.pos) or not len(uv):
            return out
        d2 = ((uv[:, None, :] - self.pos[None]) ** 2).sum(axis=2)  # (N, K)
        j = d2.argmin(axis=1)
        close = d2[np.arange(len(uv)), j] <= radius * radius
        out[close] = j[close]
        return out


class StillBlobs:
    """Per view, the blobs that sat still with no name on them (static reflections).

    still_s: seconds a blob must sit still, never named, to count as clutter (inf: never);
    still_px: how still (px); gap_s: a position no blob came back to for this long starts
    over (a moving marker leaves one per frame); forget_s: ... or, once clutter, this long
    (the body may hide a reflection for a while)."""

    def __init__(self, still_s: float, still_px: float, gap_s: float = 0.25, forget_s: float = 2.0) -> None:
        self.still_s, self.still_px, self.gap_s, self.forget_s = still_s, still_px, gap_s, forget_s
        self._views: list[_ViewStill] = []

    def clutter(self, views: list[ViewBlobs], t: float) -> list[np.ndarray]:
        """Per view (N,) bool: the blob of views (this frame's, rig order) sits where a blob sat
        still and unnamed for still_s up to t (s)."""
        out = [np.zeros(len(v), bool) for v in views]
        if not np.isfinite(self.still_s):
            return out
        for c, v in enumerate(views):
            if c >= len(self._views) or not len(v):
                continue
            vs = self._views[c]
            j = vs.match(v.uv, self.still_px)
            has = j >= 0
            out[c][has] = t - vs.since[j[has]] >= self.still_s
        return out

    def update(self, views: list[ViewBlobs], named: np.ndarray, t: float) -> None:
        """Learn from one frame: views (rig order); named (8, C) the blob per view of each named
        marker (-1: none; :meth:`Labeller._blobs_of`); t s (increasing)."""
        if not np.isfinite(self.still_s):
            return
        while len(self._views) < len(views):
            self._views.append(_ViewStill())
        for c, v in enumerate(views):
            vs = self._views[c]
            uv = v.uv
            j = vs.match(uv, self.still_px)
            used = np.zeros(len(uv), bool)
            if c < named.shape[1]:
                b = named[:, c]
                used[b[(b >= 0) & (b < len(uv))]] = True
            has = np.flatnonzero(j >= 0)
            if len(has):
                k = j[has]
                w = np.minimum(vs.n[k], 50)[:, None]
                vs.pos[k] = (vs.pos[k] * w + uv[has]) / (w + 1)
                vs.n[k] += 1
                vs.seen[k] = t
                vs.since[k[used[has]]] = t  # a name uses it: a marker, not clutter
            new = np.flatnonzero(j < 0)
            absent = t - vs.seen
            keep = (absent <= self.gap_s) | ((vs.seen - vs.since >= self.still_s) & (absent <= self.forget_s))
            vs.pos = np.vstack([vs.pos[keep], uv[new]])
            vs.n = np.r_[vs.n[keep], np.ones(len(new), np.int64)]
            vs.since = np.r_[vs.since[keep], np.full(len(new), t)]
            vs.seen = np.r_[vs.seen[keep], np.full(len(new), t)]
