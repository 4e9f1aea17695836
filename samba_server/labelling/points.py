"""Unlabelled 3D points from every view's blobs: correspondence, triangulation, ghosts.

Per frame (:func:`reconstruct_points`):

1. every blob undistorted to ideal normalised coordinates;
2. for every camera pair, every blob pair within ``epipolar_px`` of each other's epipolar line
   (both ways; a merged blob gets its radius more, its centroid lies between two markers) is
   a candidate, triangulated from the two views and kept if it lies in front of both cameras
   inside the capture volume;
3. each candidate is projected into every view and takes the nearest blob within
   ``support_px`` (plus the radius of a merged blob); candidates that took the same blobs
   (one marker found by several camera pairs) are one point, triangulated again from all its
   views (views off by more than the triangulator's ``max_error_px`` are dropped when >= 3);
4. the candidates are accepted greedily, best first (more views, fewer *unexplained* views,
   smaller error; a 2-view candidate more than ``body_radius_m`` from the >= 3-view ones
   counts two more unexplained views, one of more views that a view misses there ranks as one
   view fewer, and so does a rough one that a view misses that 2-view candidates show made of
   other markers' blobs, :meth:`PointReconstructor._outmatched`): a blob is used at most once, a
   merged blob twice (a
   candidate whose blob is taken is kept from its other views when >= 2 are left and ranked
   again by them; a precise 2-view one shares a single blob with a rough 3-view point, two
   markers a pixel apart there, :meth:`PointReconstructor._blended`), and two accepted points
   are never closer than ``min_separation_m``; an
   accepted point seen by >= 4 views with an error above ``rough_px`` may be a ghost made of
   two markers' blobs: the acceptance is run again without it, or with it split into two
   points from two sets of its views (two markers each hidden from the views that see the
   other), and that outcome taken when it explains as many blobs with a clearly smaller error
   (:meth:`PointReconstructor._unghost`);
5. a point seen only in merged blobs that each hold one other point (a marker hidden behind
   another wherever it is seen) lies at the two markers' midpoint: it is reflected through the
   other point (:meth:`PointReconstructor._mirror`);
6. a point seen in merged blobs in every view but one, where a free blob lies next to its own
   (two markers that only that view parts, knees passing in a walk), becomes two points on
   those two blobs' rays (:meth:`PointReconstructor._part`).

A view is *unexplained* for a point when the point projects inside that camera's image and
no blob is there (a merged blob near it explains it): the marker is hidden (the body, the edge
of the volume) or the point is a ghost. Points seen by >= 3 views are not ghosts; 2-view points
carry their unexplained count so that the naming stage can trust them less.

Cost: one vectorised pass per camera pair over (N_a x N_b) blobs and two compiled
triangulations (the pair candidates, then the points), so 20 blobs per view in 4 views stays
near a millisecond.
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from samba_common.calib import CameraRig

from ..triangulate import TriangulationResult, Triangulator
from .blobs import ViewBlobs, median_rows, percentile
from .clutter import on_clutter
from .elongation import blob_separation

__all__ = ["PointsConfig", "Points3D", "PointReconstructor"]


@dataclass(frozen=True)
class PointsConfig:
    """``[labelling.points]`` settings. Pixel tolerances are ideal (undistorted) pixels."""

    epipolar_px: float = 1.5  #: a blob pair matches within this distance to the epipolar lines
    support_px: float = 2.0  #: a third view supports a point with a blob this close to its projection
    behind_m: float = 0.03  #: m: farther than a sure point (>= 3 views) whose blob it falls on: hidden behind it
    merged_px_per_radius: float = 0.8  #: extra tolerance of a merged blob, times its radius
    min_separation_m: float = 0.035  #: two accepted points are never closer
    z_min: float = -0.3  #: capture volume, metres (world Z up, floor at 0) ...
    z_max: float = 3.3  #: ... up to this (a climber's shoulders reach 2.7-2.8 m on a 1.7 m structure; 2.7 lost them)
    max_range_m: float = 12.0  #: points farther than this from every camera are rejected
    max_points: int = 24  #: at most this many points per frame (best first)
    double_size_ratio: float = 1.5  #: a point whose blobs are this many times a typical point's holds two markers
    body_radius_m: float = 1.5  #: 2-view points farther than this (horizontally) from the >= 3-view points' median rank lower
    part_px: float = 6.0  #: two single blobs this close in the one view that parts two otherwise merged markers
    ends_min_px: float = 1.0  #: a merged blob whose moments part its markers by less is used by its centroid
    rough_px: float = 0.3  #: an accepted >= 4-view point this rough is checked for a ghost (``_unghost``)
    elongated_px: float = 2.0  #: a blob of a single marker's size whose moments part two markers by this much holds two
    split_fit_ratio: float = 0.33  #: a rough point that fits within rough_px and this share of its error less one view is one marker with a bad view: not split
    still_s: float = 2.0  #: a blob that sat still (within still_px) this long with no name on it is a static reflection: candidates using it rank one view fewer (inf: never; :mod:`.clutter`)
    still_px: float = 0.5  #: ... still within this (MJPG moves a static blob's centroid by up to 0.3 px)
    blend_px: float = 0.1  #: a 2-view candidate this precise that no view misses, seen in a merged blob by a third view, shares a single-marker blob with a rough (rough_px) point of 3 views (0: never)


@dataclass
class Points3D:
    """Accepted points of one frame.

    X: (P, 3) world metres; n_views: (P,) views used; error: (P,) rms reprojection error (px);
    unexplained: (P,) views in whose image the point falls with no blob there; blob: (C, P)
    index of the blob each view contributed (-1: none); votes: (P, 8) how many views labelled
    the point's blob as each marker (the motes' hints); merged: (P,) some view saw it in a
    merged blob; merged_all: (P,) the point's blobs are about twice the size of a single
    marker's at that distance in every view (median over views of area x depth^2, against the
    frame's typical point), so it is likely the midpoint of two markers no view separates;
    n_merged: (P,) views that saw it in a merged blob; mirrored: (P,) the point was seen only in
    merged blobs it shares with other points and was placed by reflection (see
    :meth:`PointReconstructor._mirror`) or on the blobs' far ends (:meth:`PointReconstructor._to_ends`);
    behind: (P,) of the unexplained views, those where the point falls on the blob of a point seen
    by >= 3 views nearer that camera (:meth:`PointReconstructor._behind`), or None.
    """

    X: np.ndarray
    n_views: np.ndarray
    error: np.ndarray
    unexplained: np.ndarray
    blob: np.ndarray
    votes: np.ndarray
    merged: np.ndarray
    merged_all: np.ndarray
    n_merged: np.ndarray
    mirrored: np.ndarray
    behind: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.X)

    def subset(self, keep: np.ndarray) -> "Points3D":
        """The points keep ((P,) bool) selects, every field alike."""
        return Points3D(self.X[keep], self.n_views[keep], self.error[keep], self.unexplained[keep],
                        self.blob[:, keep], self.votes[keep], self.merged[keep], self.merged_all[keep],
                        self.n_merged[keep], self.mirrored[keep], None if self.behind is None else self.behind[keep])

    @staticmethod
    def empty(n_cameras: int) -> "Points3D":
        return Points3D(np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64),
                        np.zeros((n_cameras, 0), np.int64), np.zeros((0, 8), np.int64), np.zeros(0, bool),
                        np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, bool))


def _nanmedian_columns(a: np.ndarray) -> np.ndarray:
    """np.nanmedian(a, axis=0) of a small (R, N) array (NaN where a column has no value), many
    times faster than numpy's general routine."""
    s = np.sort(a, axis=0)  # NaN last
    n = np.count_nonzero(np.isfinite(a), axis=0)
    cols = np.arange(a.shape[1])
    lo, hi = s[np.maximum(n - 1, 0) // 2, cols], s[n // 2, cols]
    return np.where(n > 0, 0.5 * (lo + hi), np.nan)


def _blob_capacity(blob: np.ndarray, views: list[ViewBlobs]) -> np.ndarray:
    """(C, P) markers the blob of each point in each view may stand for (0: no blob there)."""
    out = np.zeros(blob.shape, np.int64)
    for c, v in enumerate(views):
        has = blob[c] >= 0
        out[c, has] = v.capacity[blob[c, has]]
    return out


def _appended(arrays: tuple, X: np.ndarray, err: np.ndarray, n_views: np.ndarray, missing: np.ndarray,
              blob: np.ndarray, uv: np.ndarray) -> tuple:
    """New candidates appended to the candidate arrays (X (K, 3), err (K,), n_views (K,),
    missing (K,), blob (C, K), uv (C, K, 2), idx (P,)) and accepted: the grown arrays, in that
    order. X (n, 3), err, n_views, missing (n,), blob (C, n), uv (C, n, 2): the new ones."""
    X0, err0, nv0, miss0, blob0, uv0, idx = arrays
    K = len(X0)
    return (np.vstack([X0, X]), np.r_[err0, err], np.r_[nv0, n_views], np.r_[miss0, missing],
            np.hstack([blob0, blob]), np.concatenate([uv0, uv], axis=1), np.r_[idx, K + np.arange(len(X))])


#: penalty of a >= 3-view candidate far from the body that a view misses: it ranks with one view fewer
FAR_GHOST = 1000


def _rank(n_views: int, penalty: int) -> int:
    """The acceptance's first key of a candidate (smaller goes first): more views first, a far
    ghost's penalty (``FAR_GHOST``) counting one view fewer."""
    return -n_views + int(penalty >= FAR_GHOST)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def blob_uv(views: list[ViewBlobs], blob: np.ndarray) -> np.ndarray:
    """(C, K, 2) px: the blob positions of blob (C, K) (index per view, -1 = none: NaN)."""
    uv = np.full((*blob.shape, 2), np.nan)
    for c, v in enumerate(views):
        has = blob[c] >= 0
        uv[c, has] = v.uv[blob[c, has]]
    return uv


def blob_votes(views: list[ViewBlobs], blob: np.ndarray) -> np.ndarray:
    """(K, 8) int: per point of blob (C, K) (index per view, -1 = none), how many of its views'
    blobs the motes labelled as each marker."""
    votes = np.zeros((blob.shape[1], 8), np.int64)
    for c, v in enumerate(views):
        rows = np.flatnonzero(blob[c] >= 0)
        hint = v.hint[blob[c, rows]]
        lab = hint >= 0
        np.add.at(votes, (rows[lab], hint[lab]), 1)
    return votes


def _more_sure(keep: list[int], n_views: np.ndarray, err: np.ndarray, keep2: list[int], n2: np.ndarray,
               e2: np.ndarray) -> bool:
    """Whether the acceptance keep2 (candidate indices, with their n2 views and e2 errors, px) has
    more points seen by >= 3 views than keep (n_views, err), using as many of the views' blobs
    with them, and none of the points only it took is rougher than the roughest of those only
    keep took. Two shoulders with raised arms, each merged with a wrist in two views, made a
    4-view ghost of the one's blobs in two views and the other's in two (0.7-0.8 px), and 2-view
    ghosts of what it left; without it, both are 3-view points (0.04 and 0.6 px, the second
    through a merged blob). The ghosts' views outnumber theirs, so a count of all views used
    keeps the ghost."""
    only, only2 = sorted(set(keep) - set(keep2)), sorted(set(keep2) - set(keep))
    if not only or not only2:
        return False
    sure, sure2 = n_views[keep] >= 3, n2[keep2] >= 3
    rough = float(np.max(np.nan_to_num(err[only], nan=np.inf)))
    return (int(sure2.sum()) > int(sure.sum()) and int(n2[keep2][sure2].sum()) >= int(n_views[keep][sure].sum())
            and float(np.max(np.nan_to_num(e2[only2], nan=np.inf))) <= rough)


def _same_ghost(blob: np.ndarray, n_views: np.ndarray, s: int) -> np.ndarray:
    """(K,) bool: the candidates other than s seen by >= 3 views, all of them with s's blobs
    (blob (C, K), -1 = none; n_views (K,)): s less a view, which a split of s must not compete
    with. Two ankles each hidden from the two cameras that see the other made a 4-view ghost
    (0.66 px) and a 3-view one of three of its blobs (0.58 px); ranked first by its views, the
    3-view one took the blobs of the split's two points, and an ankle went unnamed for 0.3 s
    (006_11 seed 601)."""
    own = blob[:, s:s + 1]
    used = blob >= 0
    subset = (~used | (blob == own)).all(axis=0) & (n_views >= 3)
    subset[s] = False
    return subset


@njit(cache=True)
def _epipolar_matches(alg: np.ndarray, lb: np.ndarray, la: np.ndarray, fa: float, fb: float, tol_px: float,
                      extra_a: np.ndarray, extra_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The blob pairs of two views a, b within ``tol_px`` (plus each blob's extra, px) of each
    other's epipolar line, in both images: (jb, ia) indices, b's blob then a's, in row-major
    order of alg (Nb, Na) = x_b^T E x_a (NaN: no match). lb (Na, 3): a's blobs' lines in b; la
    (Nb, 3): b's blobs' lines in a; fa, fb: the views' focal lengths (px)."""
    Nb, Na = alg.shape
    hb = np.empty(Na)
    for i in range(Na):
        hb[i] = np.hypot(lb[i, 0], lb[i, 1])
    jb = np.empty(Nb * Na, np.int64)
    ia = np.empty(Nb * Na, np.int64)
    n = 0
    for j in range(Nb):
        ha = np.hypot(la[j, 0], la[j, 1])
        for i in range(Na):
            e = alg[j, i]
            if not np.isfinite(e):
                continue
            tol = tol_px + extra_a[i] + extra_b[j]
            if abs(e) / hb[i] * fb <= tol and abs(e) / ha * fa <= tol:  # NaN (0 / 0) fails, as np.maximum's NaN
                jb[n], ia[n] = j, i
                n += 1
    return jb[:n], ia[:n]


@njit(cache=True)
def _nearest_blobs(proj: np.ndarray, uv: np.ndarray, extra: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per view and projection proj (C, K, 2) px: the nearest of the view's n[c] blobs uv (C, N, 2)
    px by distance less the blob's extra tolerance (C, N) px, and that distance: (C, K) index
    (-1 for a view without blobs; the first of equals) and (C, K) px (inf where NaN)."""
    C, K = proj.shape[0], proj.shape[1]
    near = np.full((C, K), -1, np.int64)
    dist = np.full((C, K), np.inf)
    for c in range(C):
        if n[c] == 0:
            continue
        for k in range(K):
            best, arg = np.inf, 0
            for j in range(n[c]):
                du, dv = proj[c, k, 0] - uv[c, j, 0], proj[c, k, 1] - uv[c, j, 1]
                d = np.sqrt(du * du + dv * dv) - extra[c, j]
                if np.isfinite(d) and d < best:
                    best, arg = d, j
            near[c, k], dist[c, k] = arg, best
    return near, dist


def _too_close(kept: list[tuple[float, float, float]], x: float, y: float, z: float, min_m: float) -> bool:
    """Whether the nearest of the points kept (m) is nearer (x, y, z) than min_m: what
    ``np.min(np.linalg.norm(kept - X, axis=1)) < min_m`` gives (NaN distances included), at a
    fraction of its cost on the few points of one frame."""
    d = [math.sqrt((a - x) * (a - x) + (b - y) * (b - y) + (c - z) * (c - z)) for a, b, c in kept]
    return not any(v != v for v in d) and min(d) < min_m


class PointReconstructor:
    """3D points from unlabelled blobs for one rig (precomputes the pairwise geometry)."""

    def __init__(self, rig: CameraRig, triangulator: Triangulator, config: PointsConfig | None = None):
        self.rig = rig
        self.tri = triangulator
        self.config = config or PointsConfig()
        cams = rig.cameras
        self.C = len(cams)
        self.f = np.array([0.5 * (c.matrix[0, 0] + c.matrix[1, 1]) for c in cams])
        self.centres = np.stack([c.center for c in cams])  # (C, 3) world metres
        self.last_px = np.array([c.size for c in cams], float)[:, None, :] - 1.0  # (C, 1, 2) last pixel's u, v
        self.pairs: list[tuple[int, int, np.ndarray]] = []
        for a in range(self.C):
            for b in range(a + 1, self.C):
                R = cams[b].R @ cams[a].R.T
                t = np.asarray(cams[b].tvec, float) - R @ np.asarray(cams[a].tvec, float)
                self.pairs.append((a, b, _skew(t) @ R))  # x_b^T E x_a = 0 (normalised coordinates)
        # compile the kernels (the first run on a machine) or load them from disk now, not on the first live frame
        _epipolar_matches(np.zeros((1, 1)), np.ones((1, 3)), np.ones((1, 3)), 1.0, 1.0, 1.0, np.zeros(1), np.zeros(1))
        _nearest_blobs(np.zeros((1, 1, 2)), np.zeros((1, 1, 2)), np.zeros((1, 1)), np.ones(1, np.int64))

    @staticmethod
    def _offsets(views: list[ViewBlobs]) -> np.ndarray:
        """(C,) int: where each view's blobs start in the views' blobs concatenated."""
        return np.cumsum([0] + [len(v) for v in views[:-1]])

    def _padded(self, views: list[ViewBlobs], extra: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The views' blobs in arrays padded to the most blobs N of a view: positions (C, N, 2)
        px (NaN pad), extra tolerances (C, N) px (extra: per view, :meth:`_merged_extra`) and
        capacities (C, N) (0 pad)."""
        n = max(max((len(v) for v in views), default=0), 1)
        uv, ex, cap = np.full((self.C, n, 2), np.nan), np.zeros((self.C, n)), np.zeros((self.C, n), np.int64)
        for c, v in enumerate(views):
            uv[c, :len(v)], ex[c, :len(v)], cap[c, :len(v)] = v.uv, extra[c], v.capacity
        return uv, ex, cap

    def reconstruct(self, views: list[ViewBlobs], clutter: list[np.ndarray] | None = None) -> Points3D:
        """Points of one frame from per-view blobs (rig order; empty ViewBlobs for a missing view).
        clutter: per view (N,) bool, the blobs that are static reflections
        (:class:`~samba_server.labelling.clutter.StillBlobs`): candidates using one rank one
        view fewer."""
        cfg, C = self.config, self.C
        extra = [self._merged_extra(v) for v in views]
        pad_uv, pad_extra, pad_cap = self._padded(views, extra)
        pad_xy = self.tri.undistort_normalized(pad_uv)  # (C, N, 2) normalised coordinates
        xy = [pad_xy[c, :len(v)] for c, v in enumerate(views)]
        hom = [np.concatenate([x, np.ones((len(x), 1))], axis=1) for x in xy]
        cand_a: list[np.ndarray] = []
        cand_b: list[np.ndarray] = []
        cand_cams: list[tuple[int, int]] = []
        for a, b, E in self.pairs:
            if len(views[a]) == 0 or len(views[b]) == 0:
                continue
            ha, hb = hom[a], hom[b]
            lb = ha @ E.T          # (Na, 3) lines in b
            la = hb @ E            # (Nb, 3) lines in a
            alg = hb @ lb.T        # (Nb, Na) = x_b^T E x_a
            jb, ia = _epipolar_matches(alg, lb, la, self.f[a], self.f[b], cfg.epipolar_px, extra[a], extra[b])
            if len(ia):
                cand_a.append(ia)
                cand_b.append(jb)
                cand_cams += [(a, b)] * len(ia)
        if not cand_cams:
            return Points3D.empty(C)
        ia_all = np.concatenate(cand_a)
        jb_all = np.concatenate(cand_b)
        K = len(ia_all)
        cams_arr = np.array(cand_cams)
        uv = np.full((C, K, 2), np.nan)
        for c in range(C):
            sel = cams_arr[:, 0] == c
            if sel.any():
                uv[c, sel] = views[c].uv[ia_all[sel]]
            sel = cams_arr[:, 1] == c
            if sel.any():
                uv[c, sel] = views[c].uv[jb_all[sel]]
        pair = self.tri.triangulate(uv)
        ok = self.plausible(pair.points)
        if not ok.any():
            return Points3D.empty(C)
        X = pair_X = pair.points[ok]
        pair_err = pair.error[ok]
        K = len(X)
        pair_blob = np.full((C, len(ok)), -1, np.int64)  # each candidate's two blobs
        pair_blob[cams_arr[:, 0], np.arange(len(ok))] = ia_all
        pair_blob[cams_arr[:, 1], np.arange(len(ok))] = jb_all
        pair_blob = pair_blob[:, ok]
        blob = np.full((C, K), -1, np.int64)
        # the view's nearest blob is merged: if the triangulation drops it (its centroid lies
        # between two markers) it still explains the view, the marker is in it, not missing
        in_merged = np.zeros((C, K), bool)
        proj, depth = self.tri.project(X)  # (C, K, 2), (C, K)
        inside = self._inside(proj, depth)
        near, d = _nearest_blobs(proj, pad_uv, pad_extra, np.array([len(v) for v in views]))  # (C, K) nearest blob, px
        cg, kg = np.nonzero((near >= 0) & (d <= cfg.support_px) & (depth > 0.1))
        blob[cg, kg] = near[cg, kg]
        in_merged[cg, kg] = pad_cap[cg, near[cg, kg]] > 1
        # candidates from different camera pairs that took the same blobs are one point: keep
        # the first of each (the same views give the same triangulation)
        ids: dict[tuple, int] = {}  # blobs -> group, numbered in order of their first candidate
        group = np.array([ids.setdefault(tuple(r), len(ids)) for r in blob.T.tolist()], np.int64)
        _, first, counts = np.unique(group, return_index=True, return_counts=True)
        blob, in_merged = blob[:, first], in_merged[:, first]
        uv = blob_uv(views, blob)
        # a point on just its candidate's two blobs is that candidate's triangulation (most
        # ghosts): only the others are triangulated again
        X, err, used = X[first], pair.error[ok][first], blob >= 0
        again = np.flatnonzero((blob != pair_blob[:, first]).any(axis=0))
        if len(again):
            res = self.tri.triangulate(uv[:, again])
            X[again], err[again], used[:, again] = res.points, res.error, res.used
        used &= blob >= 0
        self._on_ends(X, err, used, blob, uv, pad_cap, views)
        blob = np.where(used, blob, -1)
        n_views = used.sum(axis=0)
        ok = (n_views >= 2) & self.plausible(X)
        # views in whose image a point falls with no blob (the fewest over the candidates that
        # make the point: their pair triangulations differ a little)
        missing = np.full(len(first), C, np.int64)
        np.minimum.at(missing, group, (inside & (blob[:, group] < 0) & ~in_merged[:, group]).sum(axis=0))
        X, err, n_views, blob, uv, missing, counts, ok = self._pairs_kept(
            X, err, n_views, blob, uv, missing, counts, ok, (pair_X, pair_err, pair_blob), group, inside, in_merged,
            ids, views)
        # a 2-view candidate far from the body (a distractor's blob with a marker's, where no
        # other camera looks) ranks as if two more views missed it: it stole a marker's blob
        far = np.zeros(len(X), bool)
        far_ghost = np.zeros(len(X), bool)
        away = np.zeros(len(X), bool)
        sure = ok & (n_views >= 3)
        if counts[sure].sum() >= 3:
            # the body's centre: median over the candidates (a point counts once per camera
            # pair that found it, so the points more views see weigh more)
            centre = median_rows(np.repeat(X[sure, :2], counts[sure], axis=0))
            away = np.linalg.norm(np.nan_to_num(X[:, :2]) - centre, axis=1) > cfg.body_radius_m
            far = (n_views < 3) & away
            # ... and one of more views that a view misses ranks as one view fewer: two
            # distractors' blobs and a knee's made a 3-view ghost 3 m from the body (0.5 px) that
            # went before the knee, left with 2 views by a hidden marker's point (003_01)
            far_ghost = (n_views >= 3) & (missing > 0) & away
        # greedy acceptance, best first
        penalty = missing + 2 * far + FAR_GHOST * (far_ghost | (on_clutter(blob, clutter) > 0) | self._outmatched(
            ok, X, n_views, err, blob, missing, far, views))
        fresh = (X.copy(), err.copy(), n_views.copy(), blob.copy())  # before acceptance reduces candidates
        keep, capl = self._accept(penalty, views, ok, X, err, n_views, blob, uv)
        keep, capl, X, err, n_views, blob, uv, missing = self._unghost(keep, capl, penalty, views, ok,
                                                                       (X, err, n_views, blob), fresh, uv, missing)
        if 2 <= len(keep) < cfg.max_points:
            # (a candidate two views miss is a ghost: most of those clutter makes near the body)
            keep = self._reclaim(keep, capl, views, ok & ~away & (missing[:len(ok)] <= 1), fresh,
                                 (X, err, n_views, blob), uv)
        cap = [np.array(c, np.int64) for c in capl]
        if not keep:
            return Points3D.empty(C)
        idx = np.array(keep)
        resolved, placed, new = self._to_ends(idx, X, err, n_views, blob, uv, views)
        self._unshare(idx, X, err, n_views, blob, uv, resolved)
        mirrored = self._mirror(idx, X, err, blob, uv, views, ~placed) | placed
        if new:
            blob_n = np.stack([n[2] for n in new], axis=1)
            X, err, n_views, missing, blob, uv, idx = _appended(
                (X, err, n_views, missing, blob, uv, idx), np.stack([n[0] for n in new]),
                np.array([n[1] for n in new]), (blob_n >= 0).sum(axis=0), np.zeros(len(new), missing.dtype),
                blob_n, np.stack([n[3] for n in new], axis=1))
            mirrored = np.r_[mirrored, np.ones(len(new), bool)]
        X, err, n_views, blob, uv, missing, idx, parted = self._part(idx, X, err, n_views, blob, uv, missing,
                                                                     views, xy, cap)
        mirrored = np.r_[mirrored, np.zeros(len(idx) - len(mirrored), bool)]
        blob = blob[:, idx]
        votes = blob_votes(views, blob)
        n_merged = np.zeros(len(idx), np.int64)
        size = np.full((C, len(idx)), np.nan)  # blob area x (depth / f)^2: m^2, the marker's apparent size
        proj, depth = self.tri.project(X[idx])  # (C, P, 2) px, (C, P) m
        for c in range(C):
            has = blob[c] >= 0
            if not has.any():
                continue
            rows = np.flatnonzero(has)
            n_merged[rows] += views[c].capacity[blob[c, has]] > 1
            size[c, rows] = np.pi * views[c].radius[blob[c, has]] ** 2 * (depth[c, rows] / self.f[c]) ** 2
        merged_all = np.zeros(len(idx), bool)
        solid = n_views[idx] >= 3  # the reference size comes from points that are surely markers
        if solid.sum() >= 4:
            med = _nanmedian_columns(size)
            ref = med[solid]
            ref = ref[np.isfinite(ref)]
            if ref.size:
                merged_all = med >= cfg.double_size_ratio * percentile(ref, 40.0)
        merged_all &= ~mirrored & ~parted
        missing = missing[idx].astype(np.int64)
        behind = self._behind(views, proj, depth, n_views[idx], blob, missing)
        return Points3D(X[idx], n_views[idx].astype(np.int64), err[idx], missing, blob,
                        votes, n_merged > 0, merged_all, n_merged, mirrored, behind)

    def _outmatched(self, ok: np.ndarray, X: np.ndarray, n_views: np.ndarray, err: np.ndarray, blob: np.ndarray,
                    missing: np.ndarray, far: np.ndarray, views: list[ViewBlobs]) -> np.ndarray:
        """(K,) candidates of >= 3 views that a view misses and whose views meet only roughly
        (above ``rough_px``) whose single-marker blobs 2-view candidates near the body that meet
        within ``rough_px`` and that no more views miss take (*claims*) so that the first one
        looks made of other markers' blobs: one claim seen in a view it misses that fewer views
        miss, or two claims with no blob in common, one of them seen in a view it misses. A
        claim that is a cross-pairing of its blobs with those of another such rough candidate
        that shares no single-marker blob with it (two markers side by side) does not count.
        They rank as one view fewer (``FAR_GHOST``), so that the claims go first.

        - A static distractor, a shoulders' merged blob and a still wrist's blob met at 0.7 px
          as a 3-view ghost 30 cm from the wrist, which camera 3 missed; it took the wrist's
          blob before the wrist's own 2-view point (0.0 px, seen by camera 3, out of the other
          two cameras' images), and the wrist was named on the ghost for 0.3 s (624 006_07).
        - Crossed knees merged in one view, each hidden behind the other in another, made two
          3-view ghosts between them (0.4 and 0.75 px) of the merged blob and one blob of each
          knee; they went before the knees' own 2-view points (0.0 and 0.02 px, one of them seen
          in the view each ghost missed), and tracking swapped the knees on them (625 005_17).
        - Not two ankles merged in one view and apart in two others, whose 3-view points (0.55
          and 0.7 px, the merged centroid between them) miss a fourth view: the two
          cross-pairings of their blobs in the two views (0.3 px) are no claims (ranked first,
          the climber's legs were named mirrored for 1.5 s: 3 001_14).
        - Not a knee hidden behind a wrist in one view, its 3-view point 0.6 px (one view
          merged), nor a climber's raised wrist (0.67 px, two views merged) hidden at the top of
          one view: one 2-view pairing of its one blob with another marker's in that view (0.2
          and 0.02 px) that as many views miss is one claim (ranked first, the knee was named
          16 cm off for 0.4 s: 3 002_10; the wrist's name was taken for 0.5 s: 624 001_14).
        - Not two knees whose 3-view points (0.46 and 0.64 px) share a merged blob and miss one
          view each (each hidden behind the other there): a pairing of one's blob with the
          other's (0.1 px) is a cross-pairing (ranked first, a dancer's knees were swapped: 3
          006_02).

        ok, n_views, err, missing, far (K,); X (K, 3) m; blob (C, K)."""
        cfg = self.config
        out = np.zeros(len(ok), bool)
        rough = np.flatnonzero(ok & (n_views >= 3) & (missing > 0) & (err > cfg.rough_px))
        whole = ok & (n_views == 2) & ~far & (err <= cfg.rough_px)
        if not len(rough) or not whole.any():
            return out
        proj, depth = self.tri.project(X[rough])
        missed = self._inside(proj, depth) & (blob[:, rough] < 0)  # (C, R) views in whose image each falls, no blob
        single = _blob_capacity(blob, views) == 1  # (C, K) the view's blob holds one marker
        for i, s in enumerate(rough.tolist()):
            seen_missed = (blob[missed[:, i]] >= 0).any(axis=0)  # (K,) seen in a view s misses
            # rough candidates that can stand beside s (they share no single marker's blob)
            mates = [r for r in rough.tolist() if r != s and not (single[:, s] & (blob[:, r] == blob[:, s])).any()]
            claims: list[int] = []  # 2-view candidates no more views miss, on s's single-marker blobs
            for q in np.flatnonzero(whole & (missing <= missing[s]) & (single & (blob == blob[:, [s]])).any(axis=0)):
                cs = np.flatnonzero(blob[:, q] >= 0)
                if not any(((blob[cs, q] == blob[cs, s]) | (blob[cs, q] == blob[cs, r])).all()
                           and (blob[cs, q] == blob[cs, r]).any() for r in mates):
                    claims.append(int(q))  # (not a cross-pairing of s's blobs with a mate's: two markers)
            # one seen where s is missed and fewer views miss it, or two on two of s's blobs
            # (no blob in common), one of them seen where s is missed: s mixes two markers
            out[s] = any(seen_missed[q] and missing[q] < missing[s] for q in claims) or any(
                (seen_missed[q1] or seen_missed[q2]) and not ((blob[:, q1] >= 0) & (blob[:, q1] == blob[:, q2])).any()
                for q1, q2 in itertools.combinations(claims, 2))
        return out

    def _on_ends(self, X: np.ndarray, err: np.ndarray, used: np.ndarray, blob: np.ndarray, uv: np.ndarray,
                 cap: np.ndarray, views: list[ViewBlobs]) -> None:
        """A candidate whose triangulation dropped a single marker's blob while it kept a merged
        blob: the merged blob's centroid lies between its two markers, and two such centroids
        meet there, between the markers, better than the marker's own blob does (two wrists
        merged in two views, apart in a third: the centroids met 9 cm from each wrist, the
        left wrist's own blob was dropped, it had no point and the dance was named with the
        wrists swapped, 005_14 seed 619). Triangulated again with every blob of the candidate,
        each merged blob by the end (:func:`~.elongation.blob_separation`) that meets the others
        best, and kept so when they all meet within ``rough_px`` (within ``epipolar_px``, two
        wrists on a sword hilt, each hidden from one view, made a 4-view ghost between them at
        0.7 px, 002_07 seed 602). Its uv then holds those ends, so later triangulations of it
        use them too (from the centroids a knee's point fell back between the knees when the
        acceptance cut a view, 005_02 seed 620). X (K, 3) m, err (K,) px, used (C, K), uv (C, K,
        2) px updated in place; blob (C, K) the candidates' blobs before the triangulation's
        choice; cap (C, N) the padded blob capacities."""
        has = blob >= 0
        capk = np.where(has, np.take_along_axis(cap, np.where(has, blob, 0), axis=1), 0)  # (C, K)
        for k in np.flatnonzero((has & ~used & (capk == 1)).any(axis=0) & (used & (capk > 1)).any(axis=0)).tolist():
            cs = np.flatnonzero(has[:, k])
            opts = []
            for c in cs.tolist():
                u = views[c].uv[blob[c, k]]
                sep = blob_separation(views[c].moments[blob[c, k]][None])[0] if capk[c, k] > 1 else np.full(2, np.nan)
                split = np.isfinite(sep).all() and np.hypot(sep[0], sep[1]) >= self.config.ends_min_px
                opts.append((u + 0.5 * sep, u - 0.5 * sep) if split else (u,))
            combos = list(itertools.product(*opts))
            sub = np.full((self.C, len(combos), 2), np.nan)
            for j, combo in enumerate(combos):
                sub[cs, j] = combo
            res = self.tri.triangulate(sub)
            e = np.where(res.n_views == len(cs), res.error, np.inf)
            j = int(np.argmin(e))
            if np.isfinite(e[j]) and e[j] <= self.config.rough_px and self.plausible(res.points[j:j + 1])[0]:
                X[k], err[k] = res.points[j], res.error[j]
                used[cs, k] = True
                uv[cs, k] = sub[cs, j]

    def _pairs_kept(self, X: np.ndarray, err: np.ndarray, n_views: np.ndarray, blob: np.ndarray, uv: np.ndarray,
                    missing: np.ndarray, counts: np.ndarray, ok: np.ndarray, pairs: tuple, group: np.ndarray,
                    inside: np.ndarray, in_merged: np.ndarray, ids: dict, views: list[ViewBlobs]) -> tuple:
        """A pair of blobs whose candidate, triangulated with its supporting views, dropped one of
        the pair's own two blobs also stays as that pair alone (a 2-view candidate on the pair's
        triangulation). A knee hidden from one view projected 1.7 px from the other knee's blob
        there and onto a merged blob in a third: with those two supports the triangulation
        dropped one of the knee's own views, moved 6.6 cm off and lost its blobs to the points
        that own them, and the knee, its own two blobs used by no point, went unnamed for 8
        frames (005_18, seed 602). Only pairs of two single markers' blobs that meet within
        ``rough_px``: a merged blob's centroid is no marker's (the knees passing in a walk, one
        blob each in the view where they part, merged in the others, are :meth:`_part`'s to
        split; a pair of a merged blob and a parting one took the free blob it needs).

        Candidate arrays X (K, 3) m, err (K,) px, n_views, missing, counts, ok (K,), blob (C, K),
        uv (C, K, 2) px, in_merged (C, K) (its nearest blob per view is merged); pairs: the pairs'
        triangulations X (Q, 3), err (Q,) and blobs (C, Q); group (Q,): each pair's candidate;
        inside (C, Q): the pair projects inside the image; ids: the blob rows the candidates were
        grouped by. Returns the arrays grown by the pairs kept."""
        pair_X, pair_err, seeds = pairs
        single = np.ones(seeds.shape[1], bool)
        for c, v in enumerate(views):
            has = seeds[c] >= 0
            single[has] &= v.capacity[seeds[c, has]] == 1
        lost = (ok[group] & single & (pair_err <= self.config.rough_px)
                & ((seeds >= 0) & (blob[:, group] != seeds)).any(axis=0))
        new: dict[tuple, int] = {}
        for q in np.flatnonzero(lost):
            new.setdefault(tuple(seeds[:, q].tolist()), q)
        q = np.array([q for key, q in new.items() if key not in ids], np.int64)
        if not q.size:
            return X, err, n_views, blob, uv, missing, counts, ok
        bn = seeds[:, q]
        un = blob_uv(views, bn)
        mn = (inside[:, q] & (bn < 0) & ~in_merged[:, group[q]]).sum(axis=0)
        n = len(q)
        return (np.vstack([X, pair_X[q]]), np.r_[err, pair_err[q]], np.r_[n_views, np.full(n, 2)],
                np.hstack([blob, bn]), np.concatenate([uv, un], axis=1), np.r_[missing, mn],
                np.r_[counts, np.ones(n, counts.dtype)], np.r_[ok, np.ones(n, bool)])

    def _behind(self, views: list[ViewBlobs], proj: np.ndarray, depth: np.ndarray, n_views: np.ndarray,
                blob: np.ndarray, missing: np.ndarray) -> np.ndarray:
        """(P,) per point of 2 views, of its ``missing`` (P,) views those where it is hidden
        behind a sure point (>= 3 views): not its own, but the blob of a sure point at least
        ``behind_m`` nearer that camera covers its projection (within the blob's radius plus
        ``support_px``): the far knee of a standard pose seen from the side. Explained, not
        missing; but a ghost may fall there too (two hands on a sword hilt), so only the
        standard pose's naming counts it. proj (C, P, 2) px, depth (C, P) m: the points in each
        view; n_views (P,); blob (C, P) each point's blob per view (-1: none)."""
        out = np.zeros(len(n_views), np.int64)
        sure = n_views >= 3
        if not sure.any() or not (~sure & (missing > 0)).any():  # most frames: nothing to explain
            return out
        for c, v in enumerate(views):
            front = np.flatnonzero(sure & (blob[c] >= 0))
            if not front.size:
                continue
            b = blob[c, front]
            d = np.linalg.norm(proj[c, :, None, :] - v.uv[b][None], axis=2)  # (P, front)
            hid = (d <= v.radius[b][None] + self.config.support_px) & \
                (depth[c, front][None] < depth[c][:, None] - self.config.behind_m)
            out += (~sure & (blob[c] < 0) & hid.any(axis=1) & (depth[c] > 0.1)).astype(np.int64)
        return np.minimum(out, missing)

    def _to_ends(self, idx: np.ndarray, X: np.ndarray, err: np.ndarray, n_views: np.ndarray, blob: np.ndarray,
                 uv: np.ndarray, views: list[ViewBlobs]) -> tuple[set[tuple[int, int]], np.ndarray, list]:
        """A merged blob's centroid lies between its two markers and pulls every point
        triangulated with it towards the other marker (feet at hip width: both ankle points
        4-6 cm inward). Where the mote sent the blob's second moments, its two markers sit at
        the centroid -+ half the separation they measure (:func:`~.elongation.blob_separation`).
        A blob counts as two markers here when it is merged (capacity 2) or, of a single
        marker's size, its moments part two by >= ``elongated_px`` (two overlapping markers).

        - A point with single-marker views takes, in each two-marker view, one end: with >= 2
          single views, the end nearest its projection from those (within ``support_px``;
          a two-marker blob whose ends and centroid all lie farther holds two other markers,
          the point's own hidden there: the point drops that view);
          with one, the combination of ends that triangulates best (>= 3 views, within
          ``epipolar_px``). An end is taken only where it fits better than the centroid (a
          single marker blurred by motion is elongated too, and its centroid is right). Two
          points on one blob take one end each (the nearer one keeps its choice). The point is
          triangulated again.
        - A point seen only in two-marker blobs (a marker hidden behind others wherever it is
          seen) takes the other end of each blob such a point took; from >= 2 of them it is
          triangulated again on those alone: a marker, no longer two markers' midpoint.
        - A point seen in >= 3 views, merged (capacity 2) in every one, none of whose blobs
          another point took an end of: two markers no view separates, split on the blobs'
          ends into the point and a new one (:meth:`_split_merged`).
        - The other marker of a point of the first kind, where no accepted point is (hidden in
          the views that do not merge it with that point), becomes a new point on the free ends
          of >= 2 views, when they meet within ``epipolar_px``.

        X, err, n_views, uv updated in place (candidate indices). Returns the (view, blob) pairs
        so resolved, (len(idx),) bool the points placed on ends that stand for one marker (the
        second kind, and the first kind on an end in every two-marker view), and the new points
        as (X (3,), error px, blob per view (C,), uv per view (C, 2))."""
        cfg = self.config
        placed = np.zeros(len(idx), bool)
        sub_blob = blob[:, idx]
        capb = _blob_capacity(sub_blob, views)
        # the accepted points' blobs (view c, blob b): whether each holds two markers, and its two ends
        cs, rs = np.nonzero(sub_blob >= 0)
        bs = sub_blob[cs, rs]
        sep = blob_separation(np.concatenate([v.moments for v in views])[self._offsets(views)[cs] + bs])  # (M, 2) px
        span = np.hypot(sep[:, 0], sep[:, 1])
        caps = capb[cs, rs]
        two = np.zeros(capb.shape, bool)  # (C, len(idx)) views where the point's blob holds two
        two[cs, rs] = (span >= cfg.ends_min_px) & ((caps > 1) | (span >= cfg.elongated_px))  # NaN moments: False
        sep_of = {(int(c), int(b)): sp for c, b, sp in zip(cs.tolist(), bs.tolist(), sep)}

        def ends(key: tuple[int, int]) -> np.ndarray:
            """(2, 2) px: the blob's centroid -+ half the separation."""
            return views[key[0]].uv[key[1]][None, :] + np.array([0.5, -0.5])[:, None] * sep_of[key][None, :]

        one = (capb == 1) & ~two
        # each point's choice of ends: (view, blob) -> (end, px from its projection)
        choice: dict[int, dict[tuple[int, int], tuple[int, float]]] = {}
        moved: set[int] = set()
        for r in np.flatnonzero(one.any(axis=0) & two.any(axis=0)):
            k = int(idx[r])
            keys = [(int(c), int(blob[c, k])) for c in np.flatnonzero(two[:, r])]
            got, alien = self._choose_ends(k, list(np.flatnonzero(one[:, r])), keys, uv, [ends(key) for key in keys])
            if got:
                choice[k] = got
            for c, _b in alien:  # a two-marker blob that holds two others: not this point's
                blob[c, k] = -1
                uv[c, k] = np.nan
                moved.add(k)
        # one end per point on a shared blob
        users: dict[tuple[int, int], list[int]] = {}
        for k, got in choice.items():
            for key in got:
                users.setdefault(key, []).append(k)
        free_end: dict[tuple[int, int], int] = {}
        done: set[tuple[int, int]] = set()
        for key, ks in users.items():
            if len(ks) > 2:
                continue
            ks = sorted(ks, key=lambda k: choice[k][key][1])
            j0 = choice[ks[0]][key][0]
            take = [(ks[0], j0)]
            if len(ks) == 2:
                if choice[ks[1]][key][0] == j0:
                    continue  # both want the same end: neither is sure
                take.append((ks[1], 1 - j0))
            else:
                free_end[key] = 1 - j0
            for k, j in take:
                uv[key[0], k] = ends(key)[j]
                moved.add(k)
            done.add(key)
        for r in np.flatnonzero(np.isin(idx, list(moved))) if moved else ():
            k = int(idx[r])
            res = self._triangulate_views(uv, k, list(np.flatnonzero(blob[:, k] >= 0)))
            if res.n_views[0] >= 2 and self.plausible(res.points)[0]:
                X[k], err[k], n_views[k] = res.points[0], res.error[0], res.n_views[0]
                # on an end in every two-marker view: one marker, whatever its blobs' size says
                placed[r] = all((int(c), int(blob[c, k])) in done for c in np.flatnonzero(two[:, r]))
        for r in np.flatnonzero(~one.any(axis=0) & two.any(axis=0)):
            k = int(idx[r])
            cs = [int(c) for c in np.flatnonzero(blob[:, k] >= 0) if (int(c), int(blob[c, k])) in free_end]
            if len(cs) < 2:
                continue
            sub = uv[:, k].copy()
            for c in cs:
                key = (c, int(blob[c, k]))
                sub[c] = ends(key)[free_end.pop(key)]
            res = self._triangulate_views(sub[:, None, :], 0, cs)
            if res.n_views[0] >= 2 and self.plausible(res.points)[0]:
                X[k], err[k], n_views[k] = res.points[0], res.error[0], res.n_views[0]
                uv[:, k] = sub
                placed[r] = True
        new: list[tuple[np.ndarray, float, np.ndarray, np.ndarray]] = []
        taken = set(users) | set(free_end)
        for r in np.flatnonzero((two.sum(axis=0) >= 3) & ~placed):
            k = int(idx[r])
            keys = [(int(c), int(blob[c, k])) for c in np.flatnonzero(blob[:, k] >= 0)]
            if any(key in taken or not two[key[0], r] or views[key[0]].capacity[key[1]] < 2 for key in keys):
                continue
            others = np.vstack([X[np.setdiff1d(idx, [k])]] + [n[0][None] for n in new])
            pair = self._split_merged(keys, [ends(key) for key in keys], others)
            if pair is None:
                continue
            (X[k], err[k], sub), (Y, err_y, sub_y) = pair
            uv[:, k] = sub
            placed[r] = True
            col = np.full(self.C, -1, np.int64)
            col[[c for c, _b in keys]] = [b for _c, b in keys]
            new.append((Y, err_y, col, sub_y))
        # the other marker of a point on ends, with no point of its own (hidden wherever it is
        # not merged with that point): a new point on the free ends of >= 2 views
        for r in np.flatnonzero(np.isin(idx, list(moved))) if moved else ():
            k = int(idx[r])
            cs = [int(c) for c in range(self.C) if blob[c, k] >= 0 and (int(c), int(blob[c, k])) in free_end]
            if len(cs) < 2:
                continue
            sub = np.full((self.C, 2), np.nan)
            col = np.full(self.C, -1, np.int64)
            for c in cs:
                key = (c, int(blob[c, k]))
                sub[c], col[c] = ends(key)[free_end[key]], key[1]
            res = self._triangulate_views(sub[:, None, :], 0, cs)
            Y = res.points[0]
            if res.n_views[0] < 2 or not self.plausible(res.points)[0] or res.error[0] > cfg.epipolar_px:
                continue
            others = np.vstack([X[idx]] + [n[0][None] for n in new])
            if np.min(np.linalg.norm(others - Y, axis=1)) < cfg.min_separation_m:
                continue  # the marker has a point already
            for c in cs:
                free_end.pop((c, int(blob[c, k])))
            new.append((Y, float(res.error[0]), col, sub))
        return done, placed, new

    def _split_merged(self, keys: list[tuple[int, int]], ends: list[np.ndarray], others: np.ndarray
                      ) -> tuple[tuple[np.ndarray, float, np.ndarray], tuple[np.ndarray, float, np.ndarray]] | None:
        """Two markers merged in every view that sees them (keys: >= 3 (view, blob), each blob
        holding two; ends: (2, 2) px each, :func:`~.elongation.blob_separation`): their point is
        the midpoint, named as one marker 9-10 cm off either (a dancer's knees 19 cm apart in
        depth, 3-5 px apart in all four views, 005_13 seed 623). The two markers are the one
        split of the ends into two sets, one end of each blob (2^(n-1) splits), that both
        triangulate on every view within ``epipolar_px`` (a wrong split meets only by dropping a
        view); they are ``min_separation_m`` apart, inside the volume, and neither lies within it of
        another point (others: (P, 3) m). Returns ((X (3,), error px, uv (C, 2)) for each
        marker) or None when no split, or more than one, holds."""
        cfg = self.config
        cams = [c for c, _b in keys]
        combos = np.array(list(itertools.product((0, 1), repeat=len(keys) - 1)))
        combos = np.concatenate([np.zeros((len(combos), 1), np.int64), combos], axis=1)  # (S, n): the first view fixed
        sub = np.full((self.C, 2 * len(combos), 2), np.nan)
        for i, (c, e) in enumerate(zip(cams, ends)):
            sub[c, :len(combos)] = e[combos[:, i]]
            sub[c, len(combos):] = e[1 - combos[:, i]]
        res = self.tri.triangulate(sub)
        S = len(combos)
        fits = (res.n_views == len(cams)) & (res.error <= cfg.epipolar_px) & self.plausible(res.points)
        good = np.flatnonzero(fits[:S] & fits[S:])
        if len(good) != 1:
            return None
        i = int(good[0])
        A, B = res.points[i], res.points[S + i]
        if np.linalg.norm(A - B) < cfg.min_separation_m:
            return None
        if len(others) and np.linalg.norm(others[:, None] - np.stack([A, B])[None], axis=2).min() < cfg.min_separation_m:
            return None
        return (A, float(res.error[i]), sub[:, i]), (B, float(res.error[S + i]), sub[:, S + i])

    def _choose_ends(self, k: int, singles: list[int], keys: list[tuple[int, int]], uv: np.ndarray,
                     ends: list[np.ndarray]) -> tuple[dict[tuple[int, int], tuple[int, float]], list[tuple[int, int]]]:
        """Which end of each of candidate k's two-marker blobs (keys: (view, blob); ends: (2, 2)
        px each) is its marker, given its single-marker views: {(view, blob): (end, px from the
        point's projection)}, empty when unclear (see :meth:`_to_ends`); and, with >= 2 single
        views, the two-marker blobs whose centroid and ends all lie more than ``support_px``
        from where those views put the marker: two other markers' blob (the marker hidden in
        that view), which pulled the point (a shoulder hidden behind two hands together there:
        10 cm off, 002_07 seed 601). uv: (C, K, 2) px."""
        cfg = self.config
        got: dict[tuple[int, int], tuple[int, float]] = {}
        alien: list[tuple[int, int]] = []
        if len(singles) >= 2:
            res = self._triangulate_views(uv, k, singles)
            if res.n_views[0] < 2:
                return got, alien
            proj = self.tri.project(res.points)[0][:, 0]  # (C, 2)
            for (c, b), e in zip(keys, ends):
                d = np.linalg.norm(e - proj[c], axis=1)
                j = int(np.argmin(d))
                centre = float(np.linalg.norm(e.mean(axis=0) - proj[c]))  # the blob's centroid
                if d[j] <= cfg.support_px and d[j] < centre:
                    got[(c, b)] = (j, float(d[j]))
                elif d[j] > cfg.support_px and centre > cfg.support_px:
                    alien.append((c, b))
        elif len(keys) >= 2:
            # one single view: the ends that meet best, every combination and the centroids in one call
            cams = singles + [c for c, _b in keys]
            combos = np.array(list(itertools.product((0, 1), repeat=len(keys))))  # (2^M, M)
            sub = np.full((self.C, len(combos) + 1, 2), np.nan)
            sub[cams] = uv[cams, k][:, None, :]
            for i, ((c, _b), e) in enumerate(zip(keys, ends)):
                sub[c, :-1] = e[combos[:, i]]
                sub[c, -1] = e.mean(axis=0)  # the centroid (uv may hold an end: :meth:`_on_ends`)
            res = self.tri.triangulate(sub)
            err = np.where(res.n_views[:-1] == len(cams), res.error[:-1], np.inf)
            i = int(np.argmin(err))
            # (centroids that meet only by dropping a view do not meet)
            if not (err[i] <= cfg.epipolar_px and (err[i] < res.error[-1] or res.n_views[-1] < len(cams))):
                return got, alien
            proj = self.tri.project(res.points[i:i + 1])[0][:, 0]
            for (c, b), e, j in zip(keys, ends, combos[i]):
                got[(c, b)] = (int(j), float(np.linalg.norm(e[j] - proj[c])))
        return got, alien

    def _unshare(self, idx: np.ndarray, X: np.ndarray, err: np.ndarray, n_views: np.ndarray, blob: np.ndarray,
                 uv: np.ndarray, resolved: set[tuple[int, int]] = frozenset()) -> None:
        """A blob used by two accepted points seen in >= 3 views each is two markers merged: its
        centroid lies between them and would pull both towards each other. Such points are
        triangulated again without it (the blob stays theirs for the naming stage), unless the
        blob's ends were already given to them (resolved: (view, blob) pairs, :meth:`_to_ends`)."""
        srt = np.sort(blob[:, idx], axis=1)
        for c in np.flatnonzero(((srt[:, 1:] == srt[:, :-1]) & (srt[:, 1:] >= 0)).any(axis=1)):
            b = blob[c, idx]
            vals, counts = np.unique(b[b >= 0], return_counts=True)
            for v in vals[counts > 1]:
                if (int(c), int(v)) in resolved:
                    continue
                sure = [k for k in idx[b == v] if n_views[k] >= 3]
                if len(sure) < 2:
                    continue  # shared with a 2-view point, which may be a ghost: keep the view
                for k in sure:
                    keep_blob = blob[:, k].copy()
                    if self._reduce(int(k), [c], X, err, n_views, blob, uv):
                        blob[:, k] = keep_blob

    def _mirror(self, idx: np.ndarray, X: np.ndarray, err: np.ndarray, blob: np.ndarray, uv: np.ndarray,
                views: list[ViewBlobs], todo: np.ndarray | None = None) -> np.ndarray:
        """A marker hidden behind another in every view that sees it (a wrist passing in front
        of its shoulder, a knee behind the other) makes an accepted point k seen only in merged
        blobs, each of which holds one other point j (j uses the blob or projects inside it).
        The merged centroids lie halfway between the two markers, so k sits at their midpoint,
        not on the hidden marker: 7-20 cm off. When j has >= 2 views of its own (unmerged
        blobs), j is triangulated from those and k reflected through the midpoint, 2 X_k - X_j
        (about 1 cm off on rendered takes). todo: (len(idx),) bool, the points it may move (None:
        all). X, err updated in place (candidate indices); returns (len(idx),) bool, the mirrored
        points."""
        out = np.zeros(len(idx), bool)
        proj: dict[int, np.ndarray] = {}
        capb = _blob_capacity(blob[:, idx], views)
        todo = np.ones(len(idx), bool) if todo is None else todo
        for r in np.flatnonzero((capb != 1).all(axis=0) & (capb > 1).any(axis=0) & todo):
            k = idx[r]
            cs = np.flatnonzero(blob[:, k] >= 0)
            inside = np.ones(len(idx), bool)
            inside[r] = False
            for c in cs:
                if c not in proj:
                    proj[c] = self.rig.cameras[c].project(X[idx])
                b = blob[c, k]
                near = np.linalg.norm(proj[c] - views[c].uv[b], axis=1) <= views[c].radius[b] + self.config.support_px
                inside &= (blob[c, idx] == b) | near
            if np.count_nonzero(inside) != 1:
                continue
            j = int(idx[np.flatnonzero(inside)[0]])
            own = [c for c in np.flatnonzero(blob[:, j] >= 0) if views[c].capacity[blob[c, j]] <= 1]
            if len(own) < 2:
                continue
            res = self._triangulate_views(uv, j, own)
            reflected = 2.0 * X[k] - res.points[0]
            if res.n_views[0] < 2 or not self.plausible(reflected[None])[0]:
                continue
            X[k] = reflected
            X[j], err[j] = res.points[0], res.error[0]
            out[r] = True
        return out

    def _part(self, idx: np.ndarray, X: np.ndarray, err: np.ndarray, n_views: np.ndarray, blob: np.ndarray,
              uv: np.ndarray, missing: np.ndarray, views: list[ViewBlobs], xy: list[np.ndarray],
              cap: list[np.ndarray]) -> tuple[np.ndarray, ...]:
        """Two markers merged in every view but one (knees passing in a walk) make one accepted
        point, from the merged blobs and one of the two separate blobs of the last view; the
        other separate blob stays unused and the point sits between the markers. When an
        accepted point is seen in merged blobs in >= 2 views and in one view by a single blob
        with a free single blob within ``part_px``, the two markers are placed on those two
        blobs' rays, each at its point nearest the merged views' point (the rays are nearly
        parallel, so their depths come from it), if they end up ``min_separation_m`` apart and
        both project inside every merged blob. The first replaces the point, the second is
        appended (candidate arrays grown, its index added to idx). Returns X, err, n_views,
        blob, uv, missing, idx and (len(idx),) bool, the points placed so."""
        cfg = self.config
        parted = np.zeros(len(idx), bool)
        new: list[tuple[int, np.ndarray, int, int]] = []  # (k, X of the second, view, its blob)
        capb = _blob_capacity(blob[:, idx], views)
        for r in np.flatnonzero(((capb > 1).sum(axis=0) >= 2) & ((capb == 1).sum(axis=0) == 1)):
            k = idx[r]
            merged = list(np.flatnonzero(capb[:, r] > 1))
            c = int(np.flatnonzero(capb[:, r] == 1)[0])
            v = views[c]
            d = np.linalg.norm(v.uv - v.uv[blob[c, k]], axis=1)
            free = np.flatnonzero((d > 0) & (d <= cfg.part_px) & (cap[c] > 0) & (v.capacity <= 1))
            if len(free) != 1:
                continue
            mid = self._triangulate_views(uv, k, merged).points[0]
            if not np.isfinite(mid).all():
                continue
            cam = self.rig.cameras[c]
            ends = []
            for b in (blob[c, k], free[0]):
                ray = cam.R.T @ np.array([xy[c][b, 0], xy[c][b, 1], 1.0])
                ends.append(cam.center + ray * float((mid - cam.center) @ ray) / float(ray @ ray))
            a, b2 = ends
            if np.linalg.norm(a - b2) < cfg.min_separation_m:
                continue
            inside = True
            for m in merged:
                vm, bm = views[m], blob[m, k]
                p = self.rig.cameras[m].project(np.stack([a, b2]))
                inside &= bool((np.linalg.norm(p - vm.uv[bm], axis=1) <= vm.radius[bm] + cfg.support_px).all())
            if not inside:
                continue
            X[k] = a
            parted[r] = True
            cap[c][free[0]] -= 1
            new.append((int(k), b2, int(c), int(free[0])))
        if not new:
            return X, err, n_views, blob, uv, missing, idx, parted
        src = [n[0] for n in new]
        blob_n, uv_n = blob[:, src], uv[:, src]  # the first point's views, but the parting view's free blob
        for j, (_k, _x, c, b) in enumerate(new):
            blob_n[c, j] = b
            uv_n[c, j] = views[c].uv[b]
        X, err, n_views, missing, blob, uv, idx = _appended(
            (X, err, n_views, missing, blob, uv, idx), np.stack([n[1] for n in new]), err[src], n_views[src],
            missing[src], blob_n, uv_n)
        return X, err, n_views, blob, uv, missing, idx, np.r_[parted, np.ones(len(new), bool)]

    def _accept(self, penalty: np.ndarray, views: list[ViewBlobs], ok: np.ndarray, X: np.ndarray, err: np.ndarray,
                n_views: np.ndarray, blob: np.ndarray, uv: np.ndarray) -> tuple[list[int], list[list[int]]]:
        """Greedy acceptance of the candidates, best first (more views, then a smaller
        ``penalty`` (K,): unexplained views, then a smaller error): a blob is used at most as
        many times as its capacity, two accepted points are never closer than
        ``min_separation_m``. A candidate some of whose blobs are taken is kept from its other
        views when >= 2 are left, and ranked again by what is left of it (ranked by all its
        views, a 3-view ghost of a knee's blob and the shoulders' merged blob, cut to 2 views,
        went before the 3-view knee, whose one blob it then took). Returns the accepted
        candidates and the capacity left per view and blob; X, err, n_views and blob of a
        candidate kept from its other views are updated in place."""
        cfg, C = self.config, self.C
        capl = [v.capacity.tolist() for v in views]  # markers each blob may still give
        rows = blob.T.tolist()  # plain lists: this loop visits every candidate
        # best first: more views (a far ghost one fewer), then fewer unexplained (penalty), then smaller error
        idx = np.flatnonzero(ok)
        heap = [(_rank(n, p), p, e, k) for n, p, e, k in zip(n_views[idx].tolist(), penalty[idx].tolist(),
                                                             np.nan_to_num(err[idx], nan=1e9).tolist(), idx.tolist())]
        heapq.heapify(heap)
        keep: list[int] = []
        kept: list[tuple[float, float, float]] = []  # their positions (m): accepted points are not moved again
        owner: dict[tuple[int, int], int] = {}  # (view, single-marker blob) -> the accepted point that took it
        while heap:
            k = heapq.heappop(heap)[3]
            row = rows[k]
            cs = [c for c in range(C) if row[c] >= 0]
            taken = [c for c in cs if capl[c][row[c]] <= 0]
            blend = self._blended(k, taken, row, owner, penalty, err, n_views, X[k], views)
            if blend is not None and not _too_close(kept, *X[k].tolist(), cfg.min_separation_m):
                for c in cs:
                    capl[c][row[c]] -= 1
                del owner[blend]  # shared once at most
                keep.append(k)
                kept.append(tuple(X[k].tolist()))
                continue
            if taken:
                # a hidden marker projects onto the blob of the marker in front of it: the
                # view is explained, but its blob is the other point's. Keep the point from
                # its own views when >= 2 are left, ranked again by what is left of it.
                if len(cs) - len(taken) < 2 or not self._reduce(k, taken, X, err, n_views, blob, uv):
                    continue
                rows[k] = blob[:, k].tolist()
                heapq.heappush(heap, (_rank(int(n_views[k]), int(penalty[k])), int(penalty[k]), float(err[k]), k))
                continue
            x, y, z = X[k].tolist()
            if kept and _too_close(kept, x, y, z, cfg.min_separation_m):
                continue
            for c in cs:
                capl[c][row[c]] -= 1
                if views[c].capacity[row[c]] == 1:
                    owner[(c, row[c])] = k
            keep.append(k)
            kept.append((x, y, z))
            if len(keep) >= cfg.max_points:
                break
        return keep, capl

    def _blended(self, k: int, taken: list[int], row: list[int], owner: dict[tuple[int, int], int],
                 penalty: np.ndarray, err: np.ndarray, n_views: np.ndarray, x: np.ndarray,
                 views: list[ViewBlobs]) -> tuple[int, int] | None:
        """Two markers about a pixel apart in one view make one blob of a single marker's size
        there (a dancer's knees, 1.0 px apart in camera 1): its centroid lies between them. The
        first marker's point, seen by 3 views, takes it and comes out rough (above
        ``rough_px``, 0.56 px); the second one's candidate, left with one view, was dropped, and a
        ghost of its other blob named it 15 cm off (seed 631 005_17). Candidate k (rows[k] = row,
        its blob per view) shares that blob when it is the only one taken, the point that took it
        is such a rough point, and k has >= 2 views, within ``blend_px``, that no view misses,
        its other blobs a single marker's (a 2-view ghost of a merged blob and a shoulder's,
        0.07 px, was named a wrist 27 cm off: seed 3 002_09), and a view it does not use sees it
        in a merged blob (camera 3 saw both knees in one; where only two cameras see the legs,
        ghosts pair up as precisely: a knee was named 20 cm off on one, seed 629 006_02). A rough
        point of >= 4 views is :meth:`_unghost`'s (a shoulder hidden behind the other in one view
        takes the other's blob there as its fourth view, and is cut from it). x (3,) m: k's
        position. Returns the shared (view, blob), or None."""
        cfg = self.config
        if len(taken) != 1 or penalty[k] != 0 or n_views[k] < 2 or not (0 < cfg.blend_px and err[k] <= cfg.blend_px):
            return None
        key = (taken[0], row[taken[0]])
        o = owner.get(key)
        if o is None or n_views[o] != 3 or not err[o] > cfg.rough_px:
            return None
        if any(views[c].capacity[row[c]] != 1 for c in range(self.C) if row[c] >= 0):
            return None
        # a third view sees it in a merged blob (two cameras alone pair up ghosts as precisely)
        proj, depth = self.tri.project(x[None])
        for c, v in enumerate(views):
            if row[c] >= 0 or not len(v) or not depth[c, 0] > 0.1:
                continue
            d = np.linalg.norm(v.uv - proj[c, 0], axis=1) - self._merged_extra(v)
            if ((v.capacity > 1) & (d <= cfg.support_px)).any():
                return key
        return None

    def _reclaim(self, keep: list[int], capl: list[list[int]], views: list[ViewBlobs], ok: np.ndarray,
                 fresh: tuple, accepted: tuple, uv: np.ndarray) -> list[int]:
        """Candidates left out because an accepted point took one of their blobs, given that blob
        back where they lie in front of that point in its view: a marker hidden behind another
        projects onto the other's blob, and its point (more views go first) took it, leaving the
        one in front with a single view of its own (a dancer's left knee's point took the right
        knee's blob in the one view that hid it behind the right knee, 2.3 cm off, and the right
        knee, seen apart by two cameras, had no point). A candidate (``fresh``: X, err, n_views,
        blob before the acceptance) is kept when, with the single-marker blobs it claims from
        points of >= 3 views at least ``behind_m`` farther from that camera (as it and they are
        triangulated), it has >= 2 views that triangulate within ``rough_px`` (one of them its
        own, still free), no other view misses it (:meth:`_unexplained`) and it lies
        ``min_separation_m`` from the accepted points, those it claims from included; the
        points that gave a blob up are triangulated again without it, within ``rough_px``
        (without the last two guards a child-sized swordplay lost a third of its frames: a
        ghost beside a shoulder, left with two views by the shoulder's claim, was named a
        wrist). Up to ``max_points`` points; ``ok`` (K,) leaves out the candidates far from the
        body or that two views miss. ``accepted``: X, err, n_views, blob after the acceptance
        (updated in place); capl in place; uv (C, K, 2) px. Returns keep, with the reclaimed
        candidates appended."""
        cfg = self.config
        X, err, n_views, blob = accepted
        fX, ferr, _fn, fblob = fresh
        K0 = len(fX)
        owner = {(c, int(blob[c, p])): p for p in keep for c in range(self.C) if blob[c, p] >= 0 and n_views[p] >= 3}
        # the candidates with a free blob of their own and one a sure point took
        has = fblob >= 0  # (C, K0)
        free = np.zeros_like(has)
        taken = np.zeros_like(has)
        for c in range(self.C):
            if not len(capl[c]):
                continue
            b = np.where(has[c], fblob[c], 0)
            free[c] = has[c] & (np.asarray(capl[c])[b] > 0)
            mine = np.zeros(len(capl[c]), bool)
            mine[[bb for cc, bb in owner if cc == c]] = True
            taken[c] = has[c] & mine[b]
        pick = ok[:K0] & (has.sum(axis=0) >= 2) & free.any(axis=0) & taken.any(axis=0)
        pick[[k for k in keep if k < K0]] = False
        rest = np.flatnonzero(pick).tolist()
        if not rest:
            return keep
        _pr, depth_q = self.tri.project(fX[rest])  # (C, R) m
        seen: tuple[dict[int, int], np.ndarray] | None = None  # accepted point -> column, depths (C, P) m

        def depth_of(p: int) -> np.ndarray:  # (C,) m, the accepted point p's depth in each view
            nonlocal seen
            if seen is None:  # until a point moves
                seen = ({k: j for j, k in enumerate(keep)}, self.tri.project(X[keep])[1])
            return seen[1][:, seen[0][p]]

        for i in np.argsort(ferr[rest]).tolist():
            q = rest[i]
            cams = np.flatnonzero(fblob[:, q] >= 0).tolist()
            own = [c for c in cams if capl[c][fblob[c, q]] > 0]
            claims: list[tuple[int, int]] = []
            for c in cams:
                p = owner.get((c, int(fblob[c, q])))
                if c in own or p is None or views[c].capacity[fblob[c, q]] != 1 or any(p == p2 for _c, p2 in claims):
                    continue
                if depth_q[c, i] < depth_of(p)[c] - cfg.behind_m:
                    claims.append((c, p))
            if not own or not claims:
                continue
            use = own + [c for c, _p in claims]
            res = self._triangulate_views(uv, q, use)
            if res.n_views[0] < len(use) or res.error[0] > cfg.rough_px or not self.plausible(res.points)[0]:
                continue
            # in front of each point it claims from and apart from it, as triangulated from the
            # views it keeps (the candidate's first triangulation may lie elsewhere)
            d_res = self.tri.project(res.points)[1][:, 0]
            if any(d_res[c] >= depth_of(p)[c] - cfg.behind_m or np.linalg.norm(res.points[0] - X[p]) < cfg.min_separation_m
                   for c, p in claims):
                continue
            bq = np.where(np.isin(np.arange(self.C), use), fblob[:, q], -1)
            sure = [k for k in keep if n_views[k] >= 3]
            if self._unexplained(res.points[0], bq, views, sure,
                                 np.stack([depth_of(k) for k in sure], axis=1) if sure else np.zeros((self.C, 0)), blob):
                continue
            given = [(c, p, self._triangulate_views(uv, p, [v for v in np.flatnonzero(blob[:, p] >= 0) if v != c]))
                     for c, p in claims]
            if any(r.n_views[0] < 2 or r.error[0] > cfg.rough_px or not self.plausible(r.points)[0]
                   for _c, _p, r in given):
                continue
            moved = {p for _c, p in claims}
            others = [X[k] for k in keep if k not in moved] + [r.points[0] for _c, _p, r in given]
            if np.min(np.linalg.norm(np.array(others) - res.points[0], axis=1)) < cfg.min_separation_m:
                continue
            for c, p, r in given:
                X[p], err[p], n_views[p] = r.points[0], r.error[0], r.n_views[0]
                blob[c, p] = -1
                blob[~r.used[:, 0], p] = -1
                if n_views[p] < 3:  # no longer sure: gives no more blobs
                    for key in [key for key, v in owner.items() if v == p]:
                        del owner[key]
            X[q], err[q], n_views[q], blob[:, q] = res.points[0], res.error[0], res.n_views[0], bq
            seen = None
            for c in own:
                capl[c][fblob[c, q]] -= 1
            for c, _p in claims:
                owner.pop((c, int(fblob[c, q])), None)
            keep = keep + [q]
            if len(keep) >= cfg.max_points:
                break
        return keep

    def _unexplained(self, x: np.ndarray, bq: np.ndarray, views: list[ViewBlobs], sure: list[int],
                     depth_sure: np.ndarray, blob: np.ndarray) -> bool:
        """Whether a view misses point x (3,) m whose blobs are bq (C,) (-1: none): x falls inside
        its image with no blob within ``support_px`` (a merged blob's extra tolerance added) and
        not behind one of the sure points (indices into blob (C, K); depth_sure (C, len(sure))
        m, theirs in each view): on its blob (within the blob's radius plus ``support_px``) and
        at least ``behind_m`` nearer."""
        cfg = self.config
        proj, depth = self.tri.project(x[None])
        inside = self._inside(proj, depth)[:, 0]
        for c, v in enumerate(views):
            if not inside[c] or bq[c] >= 0:
                continue
            if len(v) and (np.linalg.norm(v.uv - proj[c, 0], axis=1) - self._merged_extra(v)).min() <= cfg.support_px:
                continue
            seen = [i for i, k in enumerate(sure) if blob[c, k] >= 0]
            if seen:
                b = blob[c, [sure[i] for i in seen]]
                near = np.linalg.norm(v.uv[b] - proj[c, 0], axis=1) <= v.radius[b] + cfg.support_px
                if (near & (depth_sure[c, seen] < depth[c, 0] - cfg.behind_m)).any():
                    continue
            return True
        return False

    def _unghost(self, keep: list[int], capl: list[list[int]], penalty: np.ndarray, views: list[ViewBlobs],
                 ok: np.ndarray, accepted: tuple, fresh: tuple, uv: np.ndarray, missing: np.ndarray) -> tuple:
        """Accepted points seen by >= 4 views with an error above ``rough_px`` may be ghosts: two
        wrists, each hidden from one view and lined up in another, made a 4-view point between
        them from one wrist's blobs in two views and the other's in two (0.9 px, against 0.1 for
        the wrists), which the greedy order (more views first) took before the two 3-view
        wrists. Without each such point the acceptance is run again (from the candidates as
        they were before it, ``fresh``: X, err, n_views, blob); the other outcome is taken when
        it leaves no more views unexplained and either uses as many blobs with errors summing
        at least ``rough_px`` less, or has more points seen by >= 3 views (:func:`_more_sure`).
        When that fails, the acceptance is run again with the point replaced by the two points
        of its views' split (:meth:`_split_rough`): two markers, each hidden from the views that
        see the other, have no candidate of their own (each one's pair of views is supported by
        the other's blobs and grows into the rough point); that run leaves out the point less a
        view (:func:`_same_ghost`) and does not count the views the split's points leave
        unexplained (each marker's hiding). Then with the point less one view
        whose blob another marker needs (:meth:`_less_view`), taken when it keeps as many points,
        as many of them seen by >= 3 views, and leaves fewer views unexplained.
        ``accepted``: X, err, n_views, blob after the first acceptance; uv (C, K, 2), missing
        (K,): the candidates' blobs and unexplained views. Returns keep, capl, X, err, n_views,
        blob, uv, missing (the last four with the split's candidates appended when one was taken)."""
        cfg = self.config
        X, err, n_views, blob = accepted
        for s in sorted((k for k in keep if n_views[k] >= 4 and err[k] > cfg.rough_px), key=lambda k: -err[k]):
            if s not in keep:
                continue
            for cand, ok2, penalty2, uv2, missing2, kind in self._without(s, fresh, ok, penalty, uv, missing, views):
                trial = tuple(a.copy() for a in cand)
                without = ok2.copy()
                without[s] = False
                keep2, capl2 = self._accept(penalty2, views, without, *trial, uv2)
                n2, e2 = trial[2], trial[1]
                fewer_errors = (n2[keep2].sum() >= n_views[keep].sum()
                                and e2[keep2].sum() <= err[keep].sum() - cfg.rough_px)
                # s less a view: as many points, as many of them sure, fewer views unexplained
                explains = kind == "less" and len(keep2) >= len(keep) and missing2[keep2].sum() < missing[keep].sum() \
                    and np.count_nonzero(n2[keep2] >= 3) >= np.count_nonzero(n_views[keep] >= 3)
                # a split's two markers are each hidden from views that see the other: the views
                # its points leave unexplained are that hiding, not a ghost's
                hidden = int(sum(missing2[k] for k in keep2 if k >= len(fresh[0]))) if kind == "split" else 0
                if missing2[keep2].sum() - hidden <= missing[keep].sum() \
                        and (fewer_errors or explains or _more_sure(keep, n_views, err, keep2, n2, e2)):
                    keep, capl, ok, penalty, uv, missing, fresh = keep2, capl2, without, penalty2, uv2, missing2, cand
                    X, err, n_views, blob = trial
                    break
        return keep, capl, X, err, n_views, blob, uv, missing

    def _without(self, s: int, fresh: tuple, ok: np.ndarray, penalty: np.ndarray, uv: np.ndarray,
                 missing: np.ndarray, views: list[ViewBlobs]):
        """The candidate sets to run the acceptance again on for the rough point s (its own
        candidate left out by the caller): the candidates as they are, then (only asked for when
        that outcome was not taken) with the two points of its split appended
        (:meth:`_split_rough`), then, for each view where s took a single marker's blob that
        another candidate uses too, with s less that view appended (:meth:`_less_view`). Yields
        (X, err, n_views, blob), ok, penalty, uv, missing, and the kind of set ("plain", "split" or "less")."""
        def grown(new: tuple, kind: str, base: np.ndarray) -> tuple:
            """The candidates with new ones appended (X, err, n_views, blob, uv, unexplained views),
            those of base (K,) bool allowed."""
            Xn, en, nn, bn, uvn, mn = new
            return ((np.vstack([fresh[0], Xn]), np.r_[fresh[1], en], np.r_[fresh[2], nn], np.hstack([fresh[3], bn])),
                    np.r_[base, np.ones(len(Xn), bool)], np.r_[penalty, mn], np.concatenate([uv, uvn], axis=1),
                    np.r_[missing, mn], kind)

        yield fresh, ok, penalty, uv, missing, "plain"
        split = self._split_rough(s, fresh, uv, views)
        if split is not None:
            yield grown(split, "split", ok & ~_same_ghost(fresh[3], fresh[2], s))
        for less in self._less_view(s, fresh, ok, uv, missing, views):
            yield grown(less, "less", ok)

    def _less_view(self, s: int, fresh: tuple, ok: np.ndarray, uv: np.ndarray, missing: np.ndarray,
                   views: list[ViewBlobs]):
        """Candidate s (>= 4 views) less one view, for each view whose blob is a single marker's
        that another candidate (ok) leaving no view unexplained (missing (K,) 0) uses too,
        triangulated again on the >= 3 others: a marker hidden in that view behind another
        projects onto the other's blob and takes it (more views go first), leaving the one in
        front without a point. A sword hilt by the left shoulder: the right shoulder, hidden
        behind the left one from one camera, made a 4-view point (0.61 px) with the left
        shoulder's blob there, and the left shoulder, seen apart in two views, went unnamed for
        12 frames (002_08 seed 602). The other candidate must explain every view: a ghost of the
        knees' merged blob that claimed a knee's own blob cut that knee from its view and named
        the other knee on the ghost (005_17 seed 3). fresh: X, err, n_views, blob of the
        candidates; uv (C, K, 2) px. Yields per such view X (1, 3), err (1,), n_views (1,), blob
        (C, 1), uv (C, 1, 2) and unexplained views (1,)."""
        blob = fresh[3]
        cams = np.flatnonzero(blob[:, s] >= 0)
        others = ok.copy()
        others[s] = False
        for c in cams:
            b = blob[c, s]
            if views[c].capacity[b] > 1 or not (others & (blob[c] == b) & (missing == 0)).any():
                continue
            res = self._triangulate_views(uv, s, [int(v) for v in cams if v != c])
            if res.n_views[0] < 3 or not self.plausible(res.points)[0]:
                continue
            bn = np.where(res.used[:, :1], blob[:, s:s + 1], -1)
            uvn = np.where((bn >= 0)[..., None], uv[:, s:s + 1], np.nan)
            yield res.points[:1], res.error[:1], res.n_views[:1], bn, uvn, self.missed(res.points[:1], views, bn)

    def _inside(self, proj: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """(C, K) bool: projections proj (C, K, 2) px at depth (C, K) m more than 0.1 m in front of
        their camera and inside its image."""
        return (depth > 0.1) & (proj >= 0).all(axis=2) & (proj <= self.last_px).all(axis=2)

    def _merged_extra(self, view: ViewBlobs) -> np.ndarray:
        """(N,) px: the extra matching tolerance of each blob of view, ``merged_px_per_radius``
        times its radius for a merged one (its centroid lies between two markers), 0 otherwise."""
        return np.where(view.capacity > 1, self.config.merged_px_per_radius * view.radius, 0.0)

    def _split_rough(self, s: int, fresh: tuple, uv: np.ndarray, views: list[ViewBlobs]) -> tuple | None:
        """Two candidates for the rough candidate s (>= 4 views): the split of its views into two
        sets of >= 2 whose triangulations fit within ``rough_px`` together (the best such split)
        and lie ``min_separation_m`` apart, when no view left out makes the rest fit within
        ``rough_px`` and ``split_fit_ratio`` of its error (one marker with one bad view is not two
        markers: its other views fit within noise, a shoulder whose blob a wrist skewed in one
        view 0.52 -> 0.11 px, where two ankles 4.5 cm apart went 0.40 -> 0.18 px and the right
        one had no point for 11 frames, 006_10 seed 602), its blobs are all single
        markers' and it has at most 6 views (at most 25 splits). Two ankles 7 cm apart,
        each hidden by the other leg from the two cameras that see the other, project within
        1-1.5 px of each other everywhere: the four views made one 4-view point between them
        (0.66 px) and one ankle went unnamed for 0.7 s. fresh: X, err, n_views, blob of the
        candidates; uv (C, K, 2) px. Returns the two candidates' X (2, 3), err (2,), n_views
        (2,), blob (C, 2), uv (C, 2, 2) and unexplained views (2,), or None."""
        cfg = self.config
        blob = fresh[3]
        cams = np.flatnonzero(blob[:, s] >= 0).tolist()
        n = len(cams)
        # merged blobs are _to_ends' and _unshare's; past 6 views the splits grow as 2^n (and so many
        # views of two markers each hidden from half of them are unlikely)
        if not 4 <= n <= 6 or any(views[c].capacity[blob[c, s]] > 1 for c in cams):
            return None
        for c in cams:
            rest = self._triangulate_views(uv, s, [x for x in cams if x != c])
            if rest.n_views[0] == n - 1 and rest.error[0] <= min(cfg.rough_px, cfg.split_fit_ratio * fresh[1][s]):
                return None
        best = None
        for size in range(2, n - 1):
            for a in itertools.combinations(cams, size):
                if a[0] != cams[0]:  # each split once
                    continue
                b = [c for c in cams if c not in a]
                ra, rb = self._triangulate_views(uv, s, list(a)), self._triangulate_views(uv, s, b)
                if ra.n_views[0] != len(a) or rb.n_views[0] != len(b):
                    continue
                P = np.vstack([ra.points, rb.points])
                e = float(ra.error[0] + rb.error[0])
                if e <= cfg.rough_px and self.plausible(P).all() \
                        and np.linalg.norm(P[0] - P[1]) >= cfg.min_separation_m and (best is None or e < best[0]):
                    best = (e, P, np.array([ra.error[0], rb.error[0]]), (list(a), b))
        if best is None:
            return None
        _, P, e2, sets = best
        C = self.C
        bn = np.full((C, 2), -1, np.int64)
        uvn = np.full((C, 2, 2), np.nan)
        for i, own in enumerate(sets):
            bn[own, i] = blob[own, s]
            uvn[own, i] = uv[own, s]
        mn = self.missed(P, views, bn)
        return P, e2, np.array([len(sets[0]), len(sets[1])], np.int64), bn, uvn, mn

    def _triangulate_views(self, uv: np.ndarray, k: int, cams: list[int]) -> TriangulationResult:
        """Candidate k triangulated from the views ``cams`` only (uv: (C, K, 2) px of the
        candidates' blobs): the triangulator's result for one point."""
        sub = np.full((self.C, 1, 2), np.nan)
        sub[cams, 0] = uv[cams, k]
        return self.tri.triangulate(sub)

    def _reduce(self, k: int, drop: list[int], X: np.ndarray, err: np.ndarray, n_views: np.ndarray,
                blob: np.ndarray, uv: np.ndarray) -> bool:
        """Triangulate candidate k again without the views ``drop``; update X, err, n_views and
        blob in place. False when the rest does not make a point (fewer than 2 views left after the
        triangulator's outlier test, or outside the capture volume)."""
        res = self._triangulate_views(uv, k, [c for c in np.flatnonzero(blob[:, k] >= 0) if c not in drop])
        if res.n_views[0] < 2 or not self.plausible(res.points)[0]:
            return False
        X[k], err[k], n_views[k] = res.points[0], res.error[0], res.n_views[0]
        blob[drop, k] = -1
        blob[~res.used[:, 0], k] = -1
        return True

    def missed(self, X: np.ndarray, views: list[ViewBlobs], blob: np.ndarray) -> np.ndarray:
        """(N,) int: views in whose image each point of X (N, 3) m falls with no blob within
        ``support_px`` (a merged blob's extra tolerance added) other than its own (blob (C, N),
        -1 = none): the points' unexplained views, as :meth:`reconstruct` counts them (for
        points it makes later: a split's, a re-pairing's)."""
        proj, depth = self.tri.project(X)
        out = np.zeros(len(X), np.int64)
        inside = self._inside(proj, depth)
        for c, v in enumerate(views):
            look = inside[c] & (blob[c] < 0)
            if not look.any():
                continue
            if not len(v):
                out += look
                continue
            d = (np.linalg.norm(proj[c, :, None, :] - v.uv[None], axis=2) - self._merged_extra(v)[None]).min(axis=1)
            out += look & ~(d <= self.config.support_px)
        return out

    def plausible(self, X: np.ndarray) -> np.ndarray:
        """(N,) bool: points X (N, 3) m (NaN rows: False) inside the capture volume (``z_min``
        to ``z_max`` high, within ``max_range_m`` of a camera)."""
        cfg = self.config
        fin = np.isfinite(X).all(axis=1)
        Xs = np.where(fin[:, None], X, 0.0)
        ok = fin & (Xs[:, 2] >= cfg.z_min) & (Xs[:, 2] <= cfg.z_max)
        dist = np.linalg.norm(Xs[:, None, :] - self.centres[None], axis=2).min(axis=1)
        return ok & (dist <= cfg.max_range_m)
