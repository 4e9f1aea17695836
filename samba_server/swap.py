"""Detect and repair a label swap in one mote's view using the other views.

A mote's tracker can exchange two labels (knees crossing, a wrist passing the other). The
other views disagree with it: with >= 2 other views the markers triangulated *without* the
suspect view reproject far from its labelled blobs (3D evidence); with a single other view
the blobs sit far from the epipolar lines of their namesakes (epipolar evidence). Per view,
an optimal assignment (Hungarian) between its blobs and the evidence tells whether another
labelling fits much better; the single most convincing view is relabelled.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from samba_common.calib import Camera, CameraRig

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SwapConfig:
    """``[swap]`` settings: a relabelling must cut the summed pixel error by ``min_gain_px``
    and by the factor ``min_ratio``."""

    enabled: bool = True
    min_gain_px: float = 4.0
    min_ratio: float = 3.0
    gate_px: float = 1.5  #: only look for swaps when some point's error exceeds this


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def fundamental(a: Camera, b: Camera) -> np.ndarray:
    """(3, 3) F with ``x_b^T F x_a = 0`` for ideal (undistorted) pixels of cameras a and b."""
    R = b.R @ a.R.T
    t = np.asarray(b.tvec, float) - R @ np.asarray(a.tvec, float)
    return np.linalg.inv(b.matrix).T @ _skew(t) @ R @ np.linalg.inv(a.matrix)


def _epipolar_cost(F: np.ndarray, xa: np.ndarray, xb: np.ndarray) -> np.ndarray:
    """(N, N) distance (px) of point i of view b to the epipolar line of point j of view a."""
    ha = np.c_[xa, np.ones(len(xa))]
    lines = ha @ F.T  # (N, 3) lines in b
    hb = np.c_[xb, np.ones(len(xb))]
    num = np.abs(hb @ lines.T)  # (N_b, N_a)
    return num / np.hypot(lines[:, 0], lines[:, 1])[None, :]


def _ideal(cam: Camera, uv: np.ndarray) -> np.ndarray:
    """Undistorted pixels of the seen rows of uv (N, 2); NaN rows stay NaN."""
    out = np.full_like(uv, np.nan, dtype=float)
    ok = np.isfinite(uv).all(axis=1)
    if ok.any():
        out[ok] = cam.undistort(uv[ok])
    return out


def _best_relabel(cost: np.ndarray, cfg: SwapConfig) -> tuple[np.ndarray, float] | None:
    """cost (K, K) with rows = observed labels, cols = evidence labels. Returns (perm, gain)."""
    finite = np.isfinite(cost)
    keep = finite.any(axis=1) & np.isfinite(np.diag(cost))
    idx = np.flatnonzero(keep)
    if len(idx) < 2:
        return None
    sub = np.where(np.isfinite(cost[np.ix_(idx, idx)]), cost[np.ix_(idx, idx)], 1e6)
    rows, cols = linear_sum_assignment(sub)
    if np.array_equal(rows, cols):
        return None
    changed = rows != cols
    old = float(np.trace(sub[np.ix_(rows[changed], rows[changed])]))
    new = float(sub[rows[changed], cols[changed]].sum())
    if old - new < cfg.min_gain_px or old < cfg.min_ratio * new:
        return None
    perm = np.arange(cost.shape[0])
    perm[idx[rows[changed]]] = idx[cols[changed]]
    return perm, old - new


def repair_one_swap(rig: CameraRig, uv: np.ndarray, triangulate_fn, config: SwapConfig | None = None
                    ) -> tuple[np.ndarray, int | None]:
    """uv: (C, 8, 2) raw pixels by label, NaN = unseen; triangulate_fn(uv) -> (8, 3) points.

    Returns (uv with the labels of at most one view permuted, index of that view or None).
    """
    cfg = config or SwapConfig()
    C, N = uv.shape[:2]
    seen = np.isfinite(uv).all(axis=2)  # (C, N)
    best: tuple[float, int, np.ndarray] | None = None
    for c in range(C):
        if seen[c].sum() < 2:
            continue
        others = [o for o in range(C) if o != c and seen[o].sum() >= 2]
        if len(others) >= 2:
            sub = uv.copy()
            sub[c] = np.nan
            X = triangulate_fn(sub)
            pred = rig.cameras[c].project(np.where(np.isfinite(X), X, 0.0))
            pred[~np.isfinite(X).all(axis=1)] = np.nan
            cost = np.linalg.norm(uv[c][:, None, :] - pred[None, :, :], axis=2)
        elif len(others) == 1 and c > others[0]:  # 2 usable views: check the pair once
            o = others[0]
            F = fundamental(rig.cameras[o], rig.cameras[c])
            cost = _epipolar_cost(F, _ideal(rig.cameras[o], uv[o]), _ideal(rig.cameras[c], uv[c]))
        else:
            continue
        found = _best_relabel(cost, cfg)
        if found is not None and (best is None or found[1] > best[0]):
            best = (found[1], c, found[0])
    if best is None:
        return uv, None
    gain, c, perm = best
    out = uv.copy()
    moved = np.flatnonzero(perm != np.arange(N))
    out[c, perm[moved]] = uv[c, moved]
    # a label that moved away and was not replaced becomes unseen
    vacated = set(moved) - set(perm[moved])
    for lab in vacated:
        out[c, lab] = np.nan
    log.debug("relabelled view %d (%s): gain %.1f px", c, {int(m): int(perm[m]) for m in moved}, gain)
    return out, c
