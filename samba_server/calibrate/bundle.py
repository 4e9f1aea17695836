"""Bundle adjustment of camera poses and structure (wand or free points), scipy least_squares.

Intrinsics (K, distortion) stay fixed; each free camera has 6 parameters (Rodrigues vector,
translation). Structure comes in *blocks*: a wand block (5 parameters: centre (3) and a
2-parameter direction update in the tangent plane of the current direction) places ``K``
markers at known offsets along a line of known length, so the wand length fixes the metric
scale; a point block (3 parameters) is one free 3D point. The Jacobian is sparse: every
residual depends on one camera and one block, passed to ``least_squares`` as
``jac_sparsity`` (finite differences grouped by scipy, so the cost is ~(6 C + 5) residual
evaluations per Jacobian, independent of the number of wand positions).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from samba_common.calib import Camera, rotation_to_rvec

log = logging.getLogger(__name__)


def rotate(rvecs: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Rotate X (M, 3) by the Rodrigues vectors rvecs (M, 3) (vectorised Rodrigues formula)."""
    theta = np.linalg.norm(rvecs, axis=1)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(theta > 1e-12, rvecs / theta, 0.0)
    c, s = np.cos(theta), np.sin(theta)
    kx = np.cross(k, X)
    kd = np.sum(k * X, axis=1, keepdims=True)
    return X * c + kx * s + k * kd * (1.0 - c)


def project_obs(rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray, dist: np.ndarray, X: np.ndarray) -> np.ndarray:
    """Per-observation projection with OpenCV distortion.

    rvec, tvec (M, 3); K (M, 3, 3); dist (M, 5); X (M, 3) world -> (M, 2) pixels."""
    Xc = rotate(rvec, X) + tvec
    z = Xc[:, 2:3]
    z = np.where(np.abs(z) < 1e-9, 1e-9, z)
    xy = Xc[:, :2] / z
    x, y = xy[:, 0], xy[:, 1]
    k1, k2, p1, p2, k3 = dist.T
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    u = K[:, 0, 0] * xd + K[:, 0, 1] * yd + K[:, 0, 2]
    v = K[:, 1, 1] * yd + K[:, 1, 2]
    return np.stack([u, v], axis=1)


def tangent_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (B, 3) orthogonal to unit directions d (B, 3) and to each other."""
    a = np.where(np.abs(d[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(d, e1)
    return e1, e2


@dataclass
class Observations:
    """2D observations for bundle adjustment: cam (M,) int camera index, point (M,) int index
    into the structure points, uv (M, 2) raw pixels."""

    cam: np.ndarray
    point: np.ndarray
    uv: np.ndarray

    def __len__(self) -> int:
        return len(self.cam)


@dataclass
class BundleResult:
    cameras: list[Camera]
    points: np.ndarray  #: (P, 3) structure points (wand markers: frame-major, K per frame)
    residuals: np.ndarray  #: (M, 2) reprojection residuals px
    cost: float
    nfev: int
    success: bool
    message: str


def bundle_adjust(
    cameras: list[Camera],
    obs: Observations,
    points0: np.ndarray,
    wand_offsets: np.ndarray | None = None,
    fixed: tuple[int, ...] = (0,),
    loss: str = "soft_l1",
    f_scale: float = 1.0,
    max_nfev: int = 200,
) -> BundleResult:
    """Refine camera poses (except ``fixed``) and structure to minimise reprojection error.

    points0: (P, 3) initial points. With ``wand_offsets`` (K,) metres along the wand (e.g.
    [0, 0.5]), points are grouped K per block (P = B * K) and constrained to a rigid wand;
    otherwise every point is a free 3D point. Returns refined cameras (copies) and points.
    """
    C = len(cameras)
    free = [c for c in range(C) if c not in set(fixed)]
    cam_slot = {c: i for i, c in enumerate(free)}
    K_all = np.stack([c.matrix for c in cameras])
    D_all = np.stack([c.dist[:5] for c in cameras])
    r0 = np.stack([c.rvec for c in cameras])
    t0 = np.stack([c.tvec for c in cameras])
    Ko, Do = K_all[obs.cam], D_all[obs.cam]
    P = len(points0)

    if wand_offsets is not None:
        off = np.asarray(wand_offsets, dtype=float)
        Kw = len(off)
        B = P // Kw
        if B * Kw != P:
            raise ValueError("points0 must hold K points per wand position")
        ends = points0.reshape(B, Kw, 3)
        d0 = ends[:, -1] - ends[:, 0]
        d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
        mid = off.mean()
        c0 = ends.mean(axis=1) - (off.mean() - mid) * d0
        e1, e2 = tangent_basis(d0)
        bs = 5
        block0 = np.hstack([c0, np.zeros((B, 2))])

        def structure(bp: np.ndarray) -> np.ndarray:
            d = d0 + bp[:, 3:4] * e1 + bp[:, 4:5] * e2
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            return (bp[:, None, :3] + (off - mid)[None, :, None] * d[:, None, :]).reshape(-1, 3)

        block_of_point = np.arange(P) // Kw
    else:
        B, bs = P, 3
        block0 = np.asarray(points0, dtype=float).copy()

        def structure(bp: np.ndarray) -> np.ndarray:
            return bp

        block_of_point = np.arange(P)

    nc = 6 * len(free)
    x0 = np.concatenate([np.hstack([r0[free], t0[free]]).ravel(), block0.ravel()])

    def unpack(x: np.ndarray):
        rv, tv = r0.copy(), t0.copy()
        if free:
            cp = x[:nc].reshape(-1, 6)
            rv[free] = cp[:, :3]
            tv[free] = cp[:, 3:]
        return rv, tv, structure(x[nc:].reshape(B, bs))

    def fun(x: np.ndarray) -> np.ndarray:
        rv, tv, X = unpack(x)
        return (project_obs(rv[obs.cam], tv[obs.cam], Ko, Do, X[obs.point]) - obs.uv).ravel()

    M = len(obs)
    rr, cc = [], []
    rows = np.arange(M)
    slot = np.array([cam_slot.get(c, -1) for c in range(C)])[obs.cam]
    has_cam = slot >= 0
    for k in range(6):
        for j in (0, 1):
            rr.append(2 * rows[has_cam] + j)
            cc.append(6 * slot[has_cam] + k)
    blk = block_of_point[obs.point]
    for k in range(bs):
        for j in (0, 1):
            rr.append(2 * rows + j)
            cc.append(nc + bs * blk + k)
    rr_a, cc_a = np.concatenate(rr), np.concatenate(cc)
    S = coo_matrix((np.ones(len(rr_a), dtype=np.int8), (rr_a, cc_a)), shape=(2 * M, len(x0))).tocsr()
    res = least_squares(fun, x0, jac_sparsity=S, method="trf", loss=loss, f_scale=f_scale,
                        x_scale="jac", max_nfev=max_nfev, xtol=1e-10, ftol=1e-10)
    rv, tv, X = unpack(res.x)
    out = [Camera(c.name, c.size, c.matrix.copy(), c.dist.copy(), rv[i].copy(), tv[i].copy())
           for i, c in enumerate(cameras)]
    r = res.fun.reshape(-1, 2)
    log.info("bundle adjustment: %d observations, %d parameters, rms %.3f px, %d evaluations (%s)",
             M, len(x0), float(np.sqrt(np.mean(np.sum(r * r, axis=1)))), res.nfev, res.message)
    return BundleResult(out, X, r, float(res.cost), int(res.nfev), bool(res.success), str(res.message))


def camera_from_pose(cam: Camera, R: np.ndarray, t: np.ndarray) -> Camera:
    """Copy of ``cam`` with world->camera rotation R (3, 3) and translation t (3,)."""
    return Camera(cam.name, cam.size, cam.matrix.copy(), cam.dist.copy(), rotation_to_rvec(R), np.asarray(t, float).copy())


def transform_rig(cameras: list[Camera], A: np.ndarray, b: np.ndarray, s: float = 1.0) -> list[Camera]:
    """Cameras after the world change x_new = s * A @ x_old + b (A rotation (3, 3), s > 0)."""
    out = []
    for c in cameras:
        R = c.R @ A.T
        t = s * c.tvec - R @ b
        out.append(camera_from_pose(c, R, t))
    return out


__all__ = ["Observations", "BundleResult", "bundle_adjust", "project_obs", "rotate", "transform_rig",
           "camera_from_pose"]
