"""Multi-view triangulation: undistort, linear solve, Gauss-Newton refinement, outlier views.

The server calls this several times per frame (the labelling stage's candidate points, a few
dozen from 2-4 cameras), so each step runs compiled (numba): 67 us for 88 points in 4 views,
of which 15 us is the fixed cost of a call (AMD EPYC, 2026-12-04; 105 and 34 us when only steps
2-4 were compiled). :meth:`Triangulator.project`, the rig's lens model the other way, is
compiled too. Pixels are raw camera pixels (with lens distortion); NaN means "not seen".

Pipeline per frame:
1. undistort every view to ideal normalised coordinates (a bilinear table per camera);
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
import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from samba_common.calib import CameraRig

log = logging.getLogger(__name__)

__all__ = ["TriangulateConfig", "TriangulationResult", "Triangulator", "triangulate"]


@dataclass(frozen=True)
class TriangulateConfig:
    """Settings (TOML table ``[triangulate]``).

    max_error_px: a view whose reprojection error exceeds this (ideal pixels) is an outlier
    candidate when the point has >= 3 views; iterations: Gauss-Newton steps after the
    linear solve (one step lands within ~3 um of the converged optimum at 0.2 px noise,
    about 1e-3 of the noise-induced error, so 1 is the per-frame default);
    min_views: views needed for a point (>= 2).
    """

    max_error_px: float = 2.0
    iterations: int = 1
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

    _LUT_PAD = 8  # pixels of table beyond each image border

    def __init__(self, rig: CameraRig, config: TriangulateConfig | None = None):
        self.rig = rig
        self.config = config or TriangulateConfig()
        cams = rig.cameras
        if not cams:
            raise ValueError("triangulation needs at least one camera")
        self.C = len(cams)
        self.K = np.stack([c.matrix for c in cams])  # (C,3,3)
        self.dist = np.ascontiguousarray(np.stack([c.dist[:5] for c in cams]), dtype=float)  # (C,5)
        self.R = np.stack([c.R for c in cams])  # (C,3,3)
        self.t = np.stack([c.tvec for c in cams])  # (C,3)
        self.has_dist = bool(np.any(self.dist != 0))
        self._fxy = np.ascontiguousarray(np.stack([self.K[:, 0, 0], self.K[:, 1, 1]], axis=1))  # (C, 2) px
        if self.has_dist:
            self._build_lut()
        # compile the solver and the lens model (the first run on a machine) or load them from
        # disk now, not on the first live frame
        _triangulate_points(np.zeros((1, self.C, 2)), np.ones((1, self.C), bool), self.R, self.t, self._fxy, 1.0, 1, 2)
        self.project(np.zeros((1, 3)))
        self.undistort_normalized(np.zeros((self.C, 1, 2)))

    # ------------------------------------------------------------------ undistortion
    def undistort_normalized_exact(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels (C, N, 2) -> ideal normalised coordinates (C, N, 2); NaN stays NaN.

        One fixed-point step then four Newton steps (no data-dependent branching: exact to
        ~1e-15 for the mild distortion of real lenses inside the image)."""
        K = self.K
        yd = (uv[..., 1] - K[:, 1, 2, None]) / K[:, 1, 1, None]
        xd = (uv[..., 0] - K[:, 0, 2, None] - K[:, 0, 1, None] * yd) / K[:, 0, 0, None]
        if not self.has_dist:
            return np.stack([xd, yd], axis=-1)
        k1, k2, p1, p2, k3 = (self.dist[:, i, None] for i in range(5))
        r2 = xd * xd + yd * yd
        s = 1.0 / (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        x, y = xd * s, yd * s
        for _ in range(4):
            xx, yy, xy = x * x, y * y, x * y
            r2 = xx + yy
            rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))
            fx = x * rad + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx) - xd
            fy = y * rad + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy - yd
            a = rad + xx * drad + 2.0 * p1 * y + 6.0 * p2 * x
            b = xy * drad + 2.0 * p1 * x + 2.0 * p2 * y
            d = rad + yy * drad + 6.0 * p1 * y + 2.0 * p2 * x
            idet = 1.0 / (a * d - b * b)
            x = x - (d * fx - b * fy) * idet
            y = y - (a * fy - b * fx) * idet
        return np.stack([x, y], axis=-1)

    def _build_lut(self) -> None:
        """Undistortion table: bilinear patch coefficients on a 1 px grid covering every
        image plus a margin, stacked over cameras, shape (C*H*W, 4, 2)."""
        pad = self._LUT_PAD
        W = max(c.size[0] for c in self.rig.cameras) + 2 * pad + 2
        H = max(c.size[1] for c in self.rig.cameras) + 2 * pad + 2
        jj, ii = np.meshgrid(np.arange(W + 1, dtype=float) - pad, np.arange(H + 1, dtype=float) - pad)
        grid = np.stack([jj, ii], axis=-1)  # (H+1, W+1, 2)
        uv = np.broadcast_to(grid.reshape(-1, 2), (self.C, grid[..., 0].size, 2))
        val = self.undistort_normalized_exact(uv).reshape(self.C, H + 1, W + 1, 2)
        p00, p01 = val[:, :-1, :-1], val[:, :-1, 1:]
        p10, p11 = val[:, 1:, :-1], val[:, 1:, 1:]
        coef = np.stack([p00, p01 - p00, p10 - p00, p11 - p10 - p01 + p00], axis=-2)  # (C,H,W,4,2)
        self._lut = coef.reshape(-1, 4, 2)
        self._lut_W = W
        self._lut_hi = np.array([W - 1e-9, H - 1e-9])
        self._lut_base = np.arange(self.C) * H * W  # (C,) first row of each camera's table

    def undistort_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels (C, N, 2) -> ideal normalised coordinates (C, N, 2); NaN stays NaN.

        Bilinear lookup in a per-camera table (error ~1e-4 px with the default lenses, far
        below centroid noise). Observations more than ``_LUT_PAD`` px outside the image
        (which no camera can report) come back NaN, i.e. unseen."""
        if not self.has_dist:
            return self.undistort_normalized_exact(uv)
        return _undistort_lut(np.ascontiguousarray(uv, dtype=float), float(self._LUT_PAD), self._lut_hi, self._lut_W,
                              self._lut_base, self._lut)

    def project(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (N, 3) m -> pixels (C, N, 2) in every camera, with distortion (NaN
        behind a camera), and depth (C, N) m: :meth:`Camera.project` for the whole rig at once."""
        Xc = np.matmul(X, self.R.transpose(0, 2, 1)) + self.t[:, None, :]  # (C, N, 3)
        return _to_pixels(Xc, self.K, self.dist, self.has_dist), Xc[..., 2]

    # ------------------------------------------------------------------ public
    def triangulate(self, uv: np.ndarray) -> TriangulationResult:
        """uv: (C, N, 2) raw pixels, NaN = unseen -> TriangulationResult (see class)."""
        uv = np.asarray(uv, dtype=float)
        if uv.ndim != 3 or uv.shape[0] != self.C or uv.shape[2] != 2:
            raise ValueError(f"uv must have shape ({self.C}, N, 2), got {uv.shape}")
        N = uv.shape[1]
        cfg = self.config
        C = self.C
        xyn = self.undistort_normalized(uv).transpose(2, 0, 1)  # (2,C,N)
        mask = xyn[0] == xyn[0]  # (C,N) False for NaN
        nseen = mask.sum(axis=0)
        all_ok = N > 0 and nseen.min() >= cfg.min_views
        if all_ok:
            ok = None
        else:
            ok = nseen >= cfg.min_views
            if not ok.any():
                return TriangulationResult(np.full((N, 3), np.nan), np.full(N, np.nan),
                                           np.zeros(N, dtype=int), np.zeros_like(mask))
            idx = np.flatnonzero(ok)
            mask, xyn, nseen = mask[:, idx], xyn[:, :, idx], nseen[idx]
        xy = np.ascontiguousarray(np.where(mask, xyn, 0.0).transpose(2, 1, 0))  # (M, C, 2)
        w = np.ascontiguousarray(mask.T)  # (M, C)
        X, rms = _triangulate_points(xy, w, self.R, self.t, self._fxy, float(cfg.max_error_px),
                                     int(cfg.iterations) if cfg.refine else 0, max(2, int(cfg.min_views)))
        w, n = w.T, w.sum(axis=1)
        if all_ok and rms.max() < np.inf:
            return TriangulationResult(X, rms, n.astype(int), w > 0)
        good = rms < np.inf
        points = np.full((N, 3), np.nan)
        error = np.full(N, np.nan)
        n_used = np.zeros(N, dtype=int)
        used = np.zeros((C, N), dtype=bool)
        out_idx = (np.arange(N) if ok is None else np.flatnonzero(ok))[good]
        points[out_idx] = X[good]
        error[out_idx] = rms[good]
        n_used[out_idx] = n[good].astype(int)
        used[:, out_idx] = w[:, good] > 0
        return TriangulationResult(points, error, n_used, used)


# --------------------------------------------------------------------------- compiled lens model
@njit(cache=True, error_model="numpy")  # IEEE results (inf, NaN), not exceptions
def _undistort_lut(uv: np.ndarray, pad: float, hi: np.ndarray, W: int, base: np.ndarray,
                   lut: np.ndarray) -> np.ndarray:
    """Bilinear table lookup of :meth:`Triangulator.undistort_normalized`: raw pixels uv (C, N, 2)
    -> normalised coordinates (C, N, 2), NaN outside the table (or for NaN). hi (2,): the table's
    u, v extent (px, padded); W: its row length; base (C,): each camera's first row; lut
    (C*H*W, 4, 2): the patch coefficients (1, a_u, a_v, a_u a_v)."""
    C, N = uv.shape[0], uv.shape[1]
    out = np.empty((C, N, 2))
    for c in range(C):
        for n in range(N):
            q0, q1 = uv[c, n, 0] + pad, uv[c, n, 1] + pad
            if not (q0 >= 0.0 and q0 < hi[0] and q1 >= 0.0 and q1 < hi[1]):  # False for NaN
                out[c, n, 0] = np.nan
                out[c, n, 1] = np.nan
                continue
            i0, i1 = int(q0), int(q1)
            a0, a1 = q0 - i0, q1 - i1
            a01 = a0 * a1
            k = base[c] + i1 * W + i0
            for d in range(2):
                out[c, n, d] = ((lut[k, 0, d] + a0 * lut[k, 1, d]) + a1 * lut[k, 2, d]) + a01 * lut[k, 3, d]
    return out


@njit(cache=True, error_model="numpy")  # IEEE results (inf, NaN), not exceptions
def _to_pixels(Xc: np.ndarray, K: np.ndarray, dist: np.ndarray, has_dist: bool) -> np.ndarray:
    """Camera-frame points Xc (C, N, 3) m -> raw pixels (C, N, 2) through each camera's lens
    (:func:`samba_common.calib.distort`, dist (C, 5)) and intrinsics K (C, 3, 3); NaN behind the
    camera (depth <= 1e-9 m or NaN)."""
    C, N = Xc.shape[0], Xc.shape[1]
    uv = np.empty((C, N, 2))
    for c in range(C):
        k1, k2, p1, p2, k3 = dist[c, 0], dist[c, 1], dist[c, 2], dist[c, 3], dist[c, 4]
        for n in range(N):
            z = Xc[c, n, 2]
            if z > 1e-9:
                x, y = Xc[c, n, 0] / z, Xc[c, n, 1] / z
            else:
                x, y = np.nan, np.nan
            if has_dist:
                r2 = x * x + y * y
                rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
                x, y = (x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                        y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)
            uv[c, n, 0] = K[c, 0, 0] * x + K[c, 0, 1] * y + K[c, 0, 2]
            uv[c, n, 1] = K[c, 1, 1] * y + K[c, 1, 2]
    return uv


# --------------------------------------------------------------------------- compiled solver
@njit(cache=True, error_model="numpy")  # IEEE results (inf, NaN), not exceptions
def _add_row(A: np.ndarray, b: np.ndarray, row: np.ndarray, rhs: float) -> None:
    """Add one least-squares row (row (3,) . X = rhs) to the normal equations A (3, 3), b (3,)."""
    for i in range(3):
        b[i] += row[i] * rhs
        for j in range(3):
            A[i, j] += row[i] * row[j]


@njit(cache=True, error_model="numpy")  # IEEE results (inf, NaN), not exceptions
def _solve_sym3(A: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """out (3,) = (A + 1e-12 I)^-1 b for a symmetric positive semi-definite A (3, 3) (adjugate /
    determinant; the 1e-12 keeps a singular system finite where it can). A is modified."""
    for i in range(3):
        A[i, i] += 1e-12
    c00 = A[1, 1] * A[2, 2] - A[1, 2] * A[1, 2]
    c01 = A[0, 2] * A[1, 2] - A[0, 1] * A[2, 2]
    c02 = A[0, 1] * A[1, 2] - A[0, 2] * A[1, 1]
    c11 = A[0, 0] * A[2, 2] - A[0, 2] * A[0, 2]
    c12 = A[0, 1] * A[0, 2] - A[0, 0] * A[1, 2]
    c22 = A[0, 0] * A[1, 1] - A[0, 1] * A[0, 1]
    idet = 1.0 / (A[0, 0] * c00 + A[0, 1] * c01 + A[0, 2] * c02)
    out[0] = (c00 * b[0] + c01 * b[1] + c02 * b[2]) * idet
    out[1] = (c01 * b[0] + c11 * b[1] + c12 * b[2]) * idet
    out[2] = (c02 * b[0] + c12 * b[1] + c22 * b[2]) * idet


@njit(cache=True, error_model="numpy")  # IEEE results (inf, NaN), not exceptions
def _solve_views(xy: np.ndarray, w: np.ndarray, R: np.ndarray, t: np.ndarray, f: np.ndarray, iterations: int,
                 X: np.ndarray, e: np.ndarray) -> float:
    """One point from the views with w True: xy (C, 2) ideal normalised coordinates; R (C, 3, 3),
    t (C, 3) world -> camera; f (C, 2) focal lengths px. Linear least squares (rows
    (x r3 - r1) X = t1 - x t3 and the same in y: the DLT with the homogeneous coordinate fixed
    to 1), then ``iterations`` Gauss-Newton steps on the pixel error with the analytic
    Jacobian. Writes X (3,) world m and e (C,) px per view (0 unused, inf behind a camera that
    saw it); returns the rms px over the used views."""
    C = xy.shape[0]
    A = np.zeros((3, 3))
    b = np.zeros(3)
    row = np.zeros(3)
    for c in range(C):
        if not w[c]:
            continue
        for k in range(2):
            rhs = t[c, k] - xy[c, k] * t[c, 2]
            for i in range(3):
                row[i] = xy[c, k] * R[c, 2, i] - R[c, k, i]
            _add_row(A, b, row, rhs)
    _solve_sym3(A, b, X)
    step = np.zeros(3)
    for _ in range(iterations):
        A[:] = 0.0
        b[:] = 0.0
        for c in range(C):
            if not w[c]:
                continue
            zc = R[c, 2, 0] * X[0] + R[c, 2, 1] * X[1] + R[c, 2, 2] * X[2] + t[c, 2]
            iz = 1.0 / zc
            for k in range(2):
                p = (R[c, k, 0] * X[0] + R[c, k, 1] * X[1] + R[c, k, 2] * X[2] + t[c, k]) * iz
                r = (p - xy[c, k]) * f[c, k]
                for i in range(3):
                    row[i] = (R[c, k, i] - p * R[c, 2, i]) * f[c, k] * iz
                _add_row(A, b, row, r)
        _solve_sym3(A, b, step)
        for i in range(3):
            X[i] -= step[i]
    total, n = 0.0, 0
    for c in range(C):
        e[c] = 0.0
        if not w[c]:
            continue
        n += 1
        zc = R[c, 2, 0] * X[0] + R[c, 2, 1] * X[1] + R[c, 2, 2] * X[2] + t[c, 2]
        if not zc > 0.0:
            e[c] = np.inf
        else:
            e2 = 0.0
            for k in range(2):
                p = (R[c, k, 0] * X[0] + R[c, k, 1] * X[1] + R[c, k, 2] * X[2] + t[c, k]) / zc
                r = (p - xy[c, k]) * f[c, k]
                e2 += r * r
            e[c] = math.sqrt(e2)
        total += e[c] * e[c]
    return math.sqrt(total / n)


@njit(cache=True, error_model="numpy")  # IEEE results (inf, NaN), not exceptions
def _triangulate_points(xy: np.ndarray, w: np.ndarray, R: np.ndarray, t: np.ndarray, f: np.ndarray,
                        max_error_px: float, iterations: int, min_drop: int) -> tuple[np.ndarray, np.ndarray]:
    """Points from xy (M, C, 2) ideal normalised coordinates seen where w (M, C) bool (>= 2
    views each; w is updated to the views used). A point with more than ``min_drop`` views whose
    worst view is off by more than ``max_error_px`` is solved again without each view in turn;
    the best subset is kept when its rms is lower, repeated while that holds. Returns X (M, 3)
    world m and rms (M,) px (inf: behind a camera that saw it)."""
    M, C = w.shape
    X = np.empty((M, 3))
    rms = np.empty(M)
    e = np.empty(C)
    cX = np.empty(3)
    ce = np.empty(C)
    for m in range(M):
        rms[m] = _solve_views(xy[m], w[m], R, t, f, iterations, X[m], e)
        n = 0
        for c in range(C):
            n += w[m, c]
        for _ in range(C - 2):
            worst = 0.0
            for c in range(C):
                worst = max(worst, e[c])
            if n <= min_drop or not worst > max_error_px:
                break
            best, best_rms = -1, np.inf
            for d in range(C):
                if not w[m, d]:
                    continue
                w[m, d] = False
                r = _solve_views(xy[m], w[m], R, t, f, iterations, cX, ce)
                w[m, d] = True
                if r < best_rms:
                    best, best_rms = d, r
            if best < 0 or not best_rms < rms[m]:
                break
            w[m, best] = False
            n -= 1
            rms[m] = _solve_views(xy[m], w[m], R, t, f, iterations, X[m], e)
    return X, rms


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
