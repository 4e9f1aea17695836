"""Multi-view triangulation: undistort, linear solve, Gauss-Newton refinement, outlier views.

All arrays are vectorised over points (the server calls this once per frame for 8 markers
from 2-4 cameras). Pixels are raw camera pixels (with lens distortion); NaN means "not seen".

Pipeline per frame:
1. undistort every view to ideal normalised coordinates (Newton, vectorised over cameras);
2. linear least squares (the inhomogeneous form of DLT) from all views of each point;
3. Gauss-Newton on the reprojection error in pixels (analytic Jacobian, 3x3 normal
   equations per point);
4. for points seen by >= 3 views whose worst view is off by more than ``max_error_px``,
   re-solve leaving each view out in turn and keep the best subset (repeated while >= 3
   views remain), so one merged or mislabelled blob does not drag the point.

A point seen by fewer than 2 views is NaN. Reprojection errors are measured in ideal
(undistorted) pixels, which equal raw pixels to first order for the mild distortion of the
Samba lenses.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from samba_common.calib import CameraRig

log = logging.getLogger(__name__)

__all__ = ["TriangulateConfig", "TriangulationResult", "Triangulator", "triangulate"]


@dataclass(frozen=True)
class TriangulateConfig:
    """Settings (TOML table ``[triangulate]``).

    max_error_px: a view whose reprojection error exceeds this (ideal pixels) is an outlier
    candidate when the point has >= 3 views; iterations: Gauss-Newton steps (stops early);
    min_views: views needed for a point (>= 2).
    """

    max_error_px: float = 2.0
    iterations: int = 2
    min_views: int = 2
    refine: bool = True

    def __post_init__(self) -> None:
        if not self.max_error_px > 0:
            raise ValueError(f"max_error_px must be > 0, got {self.max_error_px}")
        if self.min_views < 2:
            raise ValueError(f"min_views must be >= 2, got {self.min_views}")
        if self.iterations < 0:
            raise ValueError(f"iterations must be >= 0, got {self.iterations}")


@dataclass
class TriangulationResult:
    """points: (N, 3) world metres, NaN where fewer than ``min_views`` usable views;
    error: (N,) rms reprojection error over the used views, pixels (NaN if unsolved);
    n_views: (N,) int number of views used (0 if unsolved);
    used: (C, N) bool, which view contributed to each point."""

    points: np.ndarray
    error: np.ndarray
    n_views: np.ndarray
    used: np.ndarray


class Triangulator:
    """Triangulation for one rig, with the rig's arrays precomputed (use this per frame)."""

    def __init__(self, rig: CameraRig, config: TriangulateConfig | None = None):
        self.rig = rig
        self.config = config or TriangulateConfig()
        cams = rig.cameras
        self.C = len(cams)
        self.K = np.stack([c.matrix for c in cams])  # (C,3,3)
        self.dist = np.stack([c.dist[:5] for c in cams])  # (C,5)
        self.R = np.stack([c.R for c in cams])  # (C,3,3)
        self.t = np.stack([c.tvec for c in cams])  # (C,3)
        self.f = np.stack([self.K[:, 0, 0], self.K[:, 1, 1]], axis=-1)  # (C,2)
        self.has_dist = bool(np.any(self.dist != 0))
        self.has_tangential = bool(np.any(self.dist[:, 2:4] != 0))
        self._dist_cols = tuple(self.dist[:, i, None] for i in range(5))
        self._eps3 = 1e-12 * np.eye(3)

    # ------------------------------------------------------------------ pieces
    def undistort_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels (C, N, 2) -> ideal normalised coordinates (C, N, 2); NaN stays NaN.

        One fixed-point step then three Newton steps (no data-dependent branching: exact to
        ~1e-15 for |k1| < 0.3 inside the image)."""
        K = self.K
        yd = (uv[..., 1] - K[:, 1, 2, None]) / K[:, 1, 1, None]
        xd = (uv[..., 0] - K[:, 0, 2, None] - K[:, 0, 1, None] * yd) / K[:, 0, 0, None]
        if not self.has_dist:
            return np.stack([xd, yd], axis=-1)
        k1, k2, p1, p2, k3 = self._dist_cols
        # fixed-point start: divide out the radial factor at the distorted radius
        r2 = xd * xd + yd * yd
        s = 1.0 / (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        x, y = xd * s, yd * s
        for _ in range(3):
            xx, yy, xy = x * x, y * y, x * y
            r2 = xx + yy
            rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))
            if self.has_tangential:
                fx = x * rad + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx) - xd
                fy = y * rad + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy - yd
                a = rad + xx * drad + 2.0 * p1 * y + 6.0 * p2 * x
                b = xy * drad + 2.0 * p1 * x + 2.0 * p2 * y
                d = rad + yy * drad + 6.0 * p1 * y + 2.0 * p2 * x
            else:
                fx = x * rad - xd
                fy = y * rad - yd
                a = rad + xx * drad
                b = xy * drad
                d = rad + yy * drad
            idet = 1.0 / (a * d - b * b)
            x = x - (d * fx - b * fy) * idet
            y = y - (a * fy - b * fx) * idet
        return np.stack([x, y], axis=-1)

    def _linear(self, x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:
        """x, y (C, M) normalised (0 where unseen), w (C, M) 1/0 -> (M, 3) least-squares points."""
        R, t = self.R, self.t
        # rows: (x r3 - r1) X = t1 - x t3 ; (y r3 - r2) X = t2 - y t3, weighted by w
        xw, yw = x * w, y * w
        a1 = xw[..., None] * R[:, None, 2, :] - w[..., None] * R[:, None, 0, :]  # (C,M,3)
        a2 = yw[..., None] * R[:, None, 2, :] - w[..., None] * R[:, None, 1, :]
        b1 = w * t[:, 0, None] - xw * t[:, 2, None]
        b2 = w * t[:, 1, None] - yw * t[:, 2, None]
        A = np.concatenate([a1, a2], axis=0).transpose(1, 0, 2)  # (M, 2C, 3)
        b = np.concatenate([b1, b2], axis=0).T[..., None]  # (M, 2C, 1)
        At = A.transpose(0, 2, 1)
        return np.linalg.solve(At @ A + self._eps3, At @ b)[..., 0]

    def _project(self, X: np.ndarray):
        """X (M, 3) -> normalised projections u, v (C, M) and depth z (C, M)."""
        Xc = self.R @ X.T + self.t[:, :, None]  # (C,3,M)
        z = Xc[:, 2]
        iz = 1.0 / z
        return Xc[:, 0] * iz, Xc[:, 1] * iz, z, iz

    def _refine(self, X: np.ndarray, x: np.ndarray, y: np.ndarray, w: np.ndarray, iterations: int) -> np.ndarray:
        """Gauss-Newton on the pixel reprojection error, analytic Jacobian. X (M, 3) -> (M, 3)."""
        R2 = self.R[:, None, 2, :]
        R0 = self.R[:, None, 0, :]
        R1 = self.R[:, None, 1, :]
        fx, fy = self.f[:, 0, None], self.f[:, 1, None]
        for _ in range(iterations):
            u, v, _, iz = self._project(X)
            su = fx * iz * w
            sv = fy * iz * w
            # d(f u)/dX = f/z (r1 - u r3), d(f v)/dX = f/z (r2 - v r3)
            J0 = su[..., None] * (R0 - u[..., None] * R2)
            J1 = sv[..., None] * (R1 - v[..., None] * R2)
            ru = (u - x) * fx * w
            rv = (v - y) * fy * w
            J = np.concatenate([J0, J1], axis=0).transpose(1, 0, 2)  # (M, 2C, 3)
            r = np.concatenate([ru, rv], axis=0).T[..., None]  # (M, 2C, 1)
            Jt = J.transpose(0, 2, 1)
            X = X - np.linalg.solve(Jt @ J + self._eps3, Jt @ r)[..., 0]
        return X

    def _solve(self, x: np.ndarray, y: np.ndarray, w: np.ndarray):
        """Solve points from the views with w = 1. Returns X (M,3), per-view err (C,M) px, rms (M,)."""
        X = self._linear(x, y, w)
        if self.config.refine and self.config.iterations:
            X = self._refine(X, x, y, w, self.config.iterations)
        u, v, z, _ = self._project(X)
        e2 = ((u - x) * self.f[:, 0, None]) ** 2 + ((v - y) * self.f[:, 1, None]) ** 2
        e2 = np.where(z > 0, e2, np.inf) * w  # behind a camera that saw it: reject
        e2 = np.nan_to_num(e2, nan=0.0, posinf=np.inf)
        n = w.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            rms = np.sqrt(e2.sum(axis=0) / n)
        return X, np.sqrt(e2), rms

    # ------------------------------------------------------------------ public
    def triangulate(self, uv: np.ndarray) -> TriangulationResult:
        """uv: (C, N, 2) raw pixels, NaN = unseen -> TriangulationResult (see class)."""
        uv = np.asarray(uv, dtype=float)
        if uv.ndim != 3 or uv.shape[0] != self.C or uv.shape[2] != 2:
            raise ValueError(f"uv must have shape ({self.C}, N, 2), got {uv.shape}")
        N = uv.shape[1]
        cfg = self.config
        C = self.C
        xy = self.undistort_normalized(uv)
        mask = np.isfinite(xy[..., 0]) & np.isfinite(xy[..., 1])  # (C,N)
        points = np.full((N, 3), np.nan)
        error = np.full(N, np.nan)
        n_used = np.zeros(N, dtype=int)
        used = np.zeros_like(mask)
        ok = mask.sum(axis=0) >= cfg.min_views
        if not ok.any():
            return TriangulationResult(points, error, n_used, used)
        if ok.all():
            m = mask
            xs = xy
        else:
            idx = np.flatnonzero(ok)
            m = mask[:, idx]
            xs = xy[:, idx]
        w = m.astype(float)
        x = np.where(m, xs[..., 0], 0.0)
        y = np.where(m, xs[..., 1], 0.0)
        X, e, rms = self._solve(x, y, w)
        # outlier views: leave-one-out while >= 3 views and the worst view is too far off
        for _ in range(C - 2):
            bad = (e.max(axis=0) > cfg.max_error_px) & (w.sum(axis=0) > max(2, cfg.min_views))
            if not bad.any():
                break
            b = np.flatnonzero(bad)
            nb = len(b)
            cw = np.repeat(w[:, b][None], C, axis=0)  # (C_drop, C, nb)
            cw[np.arange(C), np.arange(C), :] = 0.0
            cw = cw.transpose(1, 0, 2).reshape(C, C * nb)
            cX, ce, crms = self._solve(np.tile(x[:, b], (1, C)), np.tile(y[:, b], (1, C)), cw)
            valid = w[:, b] > 0  # (C_drop, nb): dropping a view only counts if it was used
            crms = np.where(valid.ravel(), crms, np.inf).reshape(C, nb)
            best = np.argmin(crms, axis=0)
            cols = np.arange(nb)
            improve = crms[best, cols] < rms[b]
            if not improve.any():
                break
            bi = b[improve]
            si = (best * nb + cols)[improve]
            X[bi] = cX[si]
            e[:, bi] = ce[:, si]
            rms[bi] = crms[best[improve], cols[improve]]
            w[:, bi] = cw[:, si]
        good = np.isfinite(rms)
        if ok.all() and good.all():
            return TriangulationResult(X, rms, w.sum(axis=0).astype(int), w > 0)
        out_idx = np.flatnonzero(ok)[good]
        points[out_idx] = X[good]
        error[out_idx] = rms[good]
        n_used[out_idx] = w[:, good].sum(axis=0).astype(int)
        used[:, out_idx] = w[:, good] > 0
        return TriangulationResult(points, error, n_used, used)


def triangulate(
    rig: CameraRig | Triangulator,
    uv: np.ndarray,
    config: TriangulateConfig | None = None,
) -> TriangulationResult:
    """Triangulate points from all views.

    rig: the calibrated cameras (or a prepared :class:`Triangulator`, faster per frame);
    uv: (C, N, 2) raw pixels, NaN = unseen. Returns points (N, 3) world metres (NaN where
    < 2 usable views), error (N,) rms reprojection px, n_views (N,) views used.
    """
    tri = rig if isinstance(rig, Triangulator) else Triangulator(rig, config)
    return tri.triangulate(uv)
