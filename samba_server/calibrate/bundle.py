"""Bundle adjustment of camera poses and structure (wand or free points), scipy least_squares.

Each free camera has 6 pose parameters (Rodrigues vector, translation). Optionally
(``intrinsics``) every camera also refines the intrinsics a wand can see - focal length (fx
and fy together, aspect kept), principal point, k1 (and k2) - each held by a Gaussian prior
around its starting value (the board step's estimate and standard deviation), so the problem
stays well-posed however the wand was waved; the other coefficients stay fixed. Structure comes in *blocks*: a wand block (5 parameters: centre (3) and a
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

from samba_common.calib import Camera, distort, rotation_to_rvec

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
    xd, yd = distort(x, y, *dist.T)
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


#: intrinsic parameters the adjustment can refine, in their order within a camera's block
INTRINSIC_PARAMS = ("f", "cx", "cy", "k1", "k2")


@dataclass
class BundleResult:
    cameras: list[Camera]
    points: np.ndarray  #: (P, 3) structure points (wand markers: frame-major, K per frame)
    residuals: np.ndarray  #: (M, 2) reprojection residuals px
    cost: float
    nfev: int
    success: bool
    message: str
    #: Jacobian (2 M + priors, n) at the solution (sparse), for covariances; columns: free
    #: cameras' poses (6 each, order of ``free``), then intrinsics (``n_intr`` per camera, all
    #: cameras), then structure blocks (``block_size`` each)
    jac: object = None
    free: tuple[int, ...] = ()
    n_intr: int = 0
    block_size: int = 0
    n_pixel_rows: int = 0  #: the first rows of ``jac`` are pixel residuals; the rest priors
    intrinsics: tuple[str, ...] = ()  #: names of the refined intrinsics (INTRINSIC_PARAMS order)


def bundle_adjust(
    cameras: list[Camera],
    obs: Observations,
    points0: np.ndarray,
    wand_offsets: np.ndarray | None = None,
    fixed: tuple[int, ...] = (0,),
    loss: str = "soft_l1",
    f_scale: float = 1.0,
    max_nfev: int = 200,
    intrinsics: tuple[str, ...] = (),
    prior_sigma: np.ndarray | None = None,
    sigma_px: float = 0.3,
    prior_cov: np.ndarray | None = None,
) -> BundleResult:
    """Refine camera poses (except ``fixed``) and structure to minimise reprojection error.

    points0: (P, 3) initial points. With ``wand_offsets`` (K,) metres along the wand (e.g.
    [0, 0.5]), points are grouped K per block (P = B * K) and constrained to a rigid wand;
    otherwise every point is a free 3D point. ``intrinsics``: names from
    :data:`INTRINSIC_PARAMS` refined for every camera (``f`` in px moves fx and fy together),
    each with a Gaussian prior: ``prior_sigma`` (C, len(intrinsics)) standard deviations (px
    for f, cx, cy; unitless for k1, k2) around the cameras' current values, or ``prior_cov``
    (C, ni, ni) full covariances (same units; the board step's k1 and k2 are strongly
    correlated); ``sigma_px`` is the expected per-axis pixel noise that weighs the priors
    against the reprojection residuals. Returns refined cameras (copies) and points.
    """
    C = len(cameras)
    free = [c for c in range(C) if c not in set(fixed)]
    cam_slot = {c: i for i, c in enumerate(free)}
    K_all = np.stack([c.matrix for c in cameras]).astype(float)
    D_all = np.stack([np.pad(c.dist[:5], (0, max(0, 5 - len(c.dist)))) for c in cameras]).astype(float)
    r0 = np.stack([c.rvec for c in cameras])
    t0 = np.stack([c.tvec for c in cameras])
    P = len(points0)
    bad = [n for n in intrinsics if n not in INTRINSIC_PARAMS]
    if bad:
        raise ValueError(f"unknown intrinsic parameters {bad}; expected some of {INTRINSIC_PARAMS}")
    intr = [INTRINSIC_PARAMS.index(n) for n in intrinsics]  # prior_sigma columns follow this order
    ni = len(intr)
    if ni:
        if prior_cov is None:
            ps = np.asarray(prior_sigma, dtype=float) if prior_sigma is not None else None
            if ps is None or ps.shape != (C, ni) or not np.all(ps > 0):
                raise ValueError(f"prior_sigma must be ({C}, {ni}) positive standard deviations")
            prior_cov = np.einsum("ci,ij->cij", ps ** 2, np.eye(ni))
        pc = np.asarray(prior_cov, dtype=float)
        if pc.shape != (C, ni, ni):
            raise ValueError(f"prior_cov must be ({C}, {ni}, {ni})")
        try:  # whitening: prior residual = sigma_px * Wc (p - p0), Wc^T Wc = cov_c^-1
            prior_W = sigma_px * np.linalg.cholesky(np.linalg.inv(0.5 * (pc + pc.transpose(0, 2, 1)))).transpose(0, 2, 1)
        except np.linalg.LinAlgError:
            raise ValueError("prior_cov must be positive definite") from None
        # current values per camera, (C, 5) in INTRINSIC_PARAMS order
        i0 = np.stack([K_all[:, 0, 0], K_all[:, 0, 2], K_all[:, 1, 2], D_all[:, 0], D_all[:, 1]], axis=1)[:, intr]
        aspect = K_all[:, 1, 1] / K_all[:, 0, 0]

    def intrinsics_of(ip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(C, ni) intrinsic parameters -> K (C, 3, 3), dist (C, 5)."""
        Kc, Dc = K_all.copy(), D_all.copy()
        for j, k in enumerate(intr):
            if k == 0:
                Kc[:, 0, 0] = ip[:, j]
                Kc[:, 1, 1] = ip[:, j] * aspect
            elif k == 1:
                Kc[:, 0, 2] = ip[:, j]
            elif k == 2:
                Kc[:, 1, 2] = ip[:, j]
            else:
                Dc[:, k - 3] = ip[:, j]
        return Kc, Dc

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
    nci = nc + C * ni  # camera columns: poses, then intrinsics
    x0 = np.concatenate([np.hstack([r0[free], t0[free]]).ravel(), i0.ravel() if ni else np.zeros(0),
                         block0.ravel()])

    def unpack(x: np.ndarray):
        rv, tv = r0.copy(), t0.copy()
        if free:
            cp = x[:nc].reshape(-1, 6)
            rv[free] = cp[:, :3]
            tv[free] = cp[:, 3:]
        ip = x[nc:nci].reshape(C, ni)
        return rv, tv, ip, structure(x[nci:].reshape(B, bs))

    def fun(x: np.ndarray) -> np.ndarray:
        rv, tv, ip, X = unpack(x)
        Kc, Dc = intrinsics_of(ip) if ni else (K_all, D_all)
        r = (project_obs(rv[obs.cam], tv[obs.cam], Kc[obs.cam], Dc[obs.cam], X[obs.point]) - obs.uv).ravel()
        if ni:
            r = np.concatenate([r, np.einsum("cij,cj->ci", prior_W, ip - i0).ravel()])
        return r

    M = len(obs)
    rr, cc = [], []
    rows = np.arange(M)
    slot = np.array([cam_slot.get(c, -1) for c in range(C)])[obs.cam]
    has_cam = slot >= 0
    for k in range(6):
        for j in (0, 1):
            rr.append(2 * rows[has_cam] + j)
            cc.append(6 * slot[has_cam] + k)
    for k in range(ni):
        for j in (0, 1):
            rr.append(2 * rows + j)
            cc.append(nc + ni * obs.cam + k)
    blk = block_of_point[obs.point]
    for k in range(bs):
        for j in (0, 1):
            rr.append(2 * rows + j)
            cc.append(nci + bs * blk + k)
    if ni:  # prior rows: ni per camera, each on all of that camera's intrinsics
        ci_, ji_, ki_ = np.meshgrid(np.arange(C), np.arange(ni), np.arange(ni), indexing="ij")
        rr.append((2 * M + ci_ * ni + ji_).ravel())
        cc.append((nc + ci_ * ni + ki_).ravel())
    rr_a, cc_a = np.concatenate(rr), np.concatenate(cc)
    S = coo_matrix((np.ones(len(rr_a), dtype=np.int8), (rr_a, cc_a)),
                   shape=(2 * M + C * ni, len(x0))).tocsr()
    if ni:
        # camera columns: the k-th column of every camera forms one finite-difference group
        # (cameras share no residual rows); structure: the k-th parameter of every block
        group = np.empty(len(x0), dtype=int)
        group[:nc] = np.tile(np.arange(6), len(free))
        group[nc:nci] = 6 + np.tile(np.arange(ni), C)
        group[nci:] = 6 + ni + np.tile(np.arange(bs), B)
        res = _lm_schur(fun, x0, S, group, nci, bs, 2 * M, loss, f_scale, max(max_nfev // 4, 30))
    else:
        res = least_squares(fun, x0, jac_sparsity=S, method="trf", loss=loss, f_scale=f_scale,
                            x_scale="jac", max_nfev=max_nfev, xtol=1e-10, ftol=1e-10)
    rv, tv, ip, X = unpack(res.x)
    Kc, Dc = intrinsics_of(ip) if ni else (K_all, D_all)
    out = []
    for i, c in enumerate(cameras):
        dist = c.dist.copy()
        dist[:min(5, len(dist))] = Dc[i, :min(5, len(dist))]
        out.append(Camera(c.name, c.size, Kc[i].copy(), dist, rv[i].copy(), tv[i].copy()))
    r = res.fun[:2 * M].reshape(-1, 2)
    log.info("bundle adjustment: %d observations, %d parameters (%d intrinsics), rms %.3f px, %d evaluations (%s)",
             M, len(x0), C * ni, float(np.sqrt(np.mean(np.sum(r * r, axis=1)))), res.nfev, res.message)
    return BundleResult(out, X, r, float(res.cost), int(res.nfev), bool(res.success), str(res.message),
                        res.jac, tuple(free), ni, bs, 2 * M,
                        tuple(INTRINSIC_PARAMS[k] for k in intr))


@dataclass
class _LMResult:
    x: np.ndarray
    fun: np.ndarray
    jac: object
    cost: float
    nfev: int
    success: bool
    message: str


def _fd_jacobian(fun, x: np.ndarray, f0: np.ndarray, S, group: np.ndarray) -> tuple[object, int]:
    """Sparse central-difference Jacobian with the pattern S (m, n); columns of one ``group``
    share no rows and are perturbed together. Returns (csr Jacobian, function evaluations)."""
    Sc = S.tocoo()
    h = 1e-6 * np.maximum(1.0, np.abs(x))
    ng = int(group.max()) + 1
    D = np.empty((ng, len(f0)))
    for g in range(ng):
        cols = group == g
        xp, xm = x.copy(), x.copy()
        xp[cols] += h[cols]
        xm[cols] -= h[cols]
        D[g] = fun(xp) - fun(xm)
    data = D[group[Sc.col], Sc.row] / (2 * h[Sc.col])
    return coo_matrix((data, (Sc.row, Sc.col)), shape=S.shape).tocsr(), 2 * ng


def _schur_solve(J, r: np.ndarray, nci: int, bs: int, lam: float) -> np.ndarray:
    """Levenberg-Marquardt step -(J^T J + lam diag)^-1 J^T r, with the block-diagonal
    structure part (blocks of ``bs`` columns after the first ``nci``) eliminated (Schur)."""
    from scipy import sparse

    Jc, Js = J[:, :nci], J[:, nci:]
    U = (Jc.T @ Jc).toarray()
    W = (Jc.T @ Js).tocsr()
    V = (Js.T @ Js).tocoo()
    nS = J.shape[1] - nci
    nB = nS // bs
    blocks = np.zeros((nB, bs, bs))
    same = V.row // bs == V.col // bs
    np.add.at(blocks, (V.row[same] // bs, V.row[same] % bs, V.col[same] % bs), V.data[same])
    gc, gs = Jc.T @ r, Js.T @ r
    U[np.diag_indices(nci)] *= 1.0 + lam
    U[np.diag_indices(nci)] += 1e-12
    idx = np.arange(bs)
    blocks[:, idx, idx] = blocks[:, idx, idx] * (1.0 + lam) + 1e-12
    Vinv = np.linalg.inv(blocks)
    Vi = sparse.bsr_matrix((Vinv, np.arange(nB), np.arange(nB + 1)), shape=(nS, nS))
    WVi = W @ Vi
    Sm = U - (WVi @ W.T).toarray()
    dc = np.linalg.solve(Sm, gc - WVi @ gs)
    ds = Vi @ (gs - W.T @ dc)
    return -np.concatenate([dc, ds])


def _lm_schur(fun, x0: np.ndarray, S, group: np.ndarray, nci: int, bs: int, n_pix: int, loss: str,
              f_scale: float, max_iter: int) -> _LMResult:
    """Levenberg-Marquardt with exact Schur-complement steps and iteratively reweighted
    robust loss (``soft_l1`` or ``linear``) on the first ``n_pix`` (pixel) residuals. Used
    when intrinsics are refined: their near-degeneracy with the camera distances makes the
    inexact (LSMR) steps of scipy's ``trf`` crawl."""

    def weights(r: np.ndarray) -> np.ndarray:
        w = np.ones_like(r)
        if loss == "soft_l1":
            z = (r[:n_pix] / f_scale) ** 2
            # pixel residuals come in (u, v) pairs: one weight per observation
            zz = np.repeat(z.reshape(-1, 2).sum(axis=1), 2)
            w[:n_pix] = 1.0 / np.sqrt(1.0 + zz)
        return w

    def cost(r: np.ndarray) -> float:
        if loss == "soft_l1":
            z = (r[:n_pix].reshape(-1, 2) ** 2).sum(axis=1) / f_scale ** 2
            return float(f_scale ** 2 * np.sum(np.sqrt(1.0 + z) - 1.0) + 0.5 * np.sum(r[n_pix:] ** 2))
        return float(0.5 * np.sum(r * r))

    x = x0.copy()
    r = fun(x)
    c = cost(r)
    nfev, lam, msg, ok = 1, 1e-3, "maximum iterations reached", False
    J = None
    for _ in range(max_iter):
        J, n = _fd_jacobian(fun, x, r, S, group)
        nfev += n
        sw = np.sqrt(weights(r))
        Jw = J.multiply(sw[:, None]).tocsr()
        improved = False
        for _ in range(10):
            step = _schur_solve(Jw, sw * r, nci, bs, lam)
            xn = x + step
            rn = fun(xn)
            nfev += 1
            cn = cost(rn)
            if np.isfinite(cn) and cn < c:
                improved = True
                break
            lam *= 4.0
        if not improved:
            msg, ok = "no further decrease", True
            break
        rel = (c - cn) / max(c, 1e-300)
        x, r, c = xn, rn, cn
        lam = max(lam / 3.0, 1e-9)
        if rel < 1e-10 or np.max(np.abs(step) / np.maximum(1.0, np.abs(x))) < 1e-10:
            msg, ok = "converged", True
            break
    J, n = _fd_jacobian(fun, x, r, S, group)
    nfev += n
    return _LMResult(x, r, J, c, nfev, ok, msg)


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


__all__ = ["INTRINSIC_PARAMS", "Observations", "BundleResult", "bundle_adjust", "project_obs", "rotate", "transform_rig",
           "camera_from_pose"]
