"""Uncertainty of a bundle adjustment: covariance of the camera parameters, camera centres, scale.

The covariance is the Gauss-Newton one at the solution, ``s^2 (J^T J)^-1``, with ``s^2`` the
per-axis pixel noise estimated from the residuals (sum of squares / degrees of freedom) and
the intrinsic priors included as rows of ``J``. The structure (wand positions or points, one
small block each) is eliminated with the Schur complement, so only the camera block
(6 per free camera + intrinsics) is ever inverted densely.

Camera centres are reported *gauge-free*: the adjustment fixes one camera's pose and the
world frame is set later (floor), so what the data determine is the shape of the rig. The
centre covariance is projected onto the complement of the rigid motions of the rig (the
linearised best rigid alignment), which is how centre errors are measured against a
reference. The scale is the rms distance of the centres from their centroid; its relative
standard deviation is rigid-motion invariant.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from samba_common.calib import Camera
from samba_server.calibrate.bundle import BundleResult, rotate

#: samples drawn to find the 95 % radius of a (possibly elongated) 3D Gaussian
_MC_SAMPLES = 20000


@dataclass
class RigUncertainty:
    """Reported uncertainties of a calibration (from the adjustment's covariance).

    centre_95_m: (C,) radius (m) that holds each camera's centre error (gauge-free, i.e. after
    the best rigid alignment to the truth) with 95 % probability; centre_sigma_m: (C,) rms
    3D centre error expected (m); scale_sigma: relative standard deviation of the rig's scale
    (0.001 = 0.1 %), not counting the error of the wand length itself; focal_sigma_px: (C,)
    standard deviation of fx after the adjustment (NaN when f was not refined); sigma_px:
    per-axis pixel noise estimated from the residuals; rotation_95_deg: (C,) angle (deg) that
    holds each camera's rotation error after the same alignment with 95 % probability (the
    principal point trades against it: 0.25 px at f = 140 px is 0.1 deg)."""

    centre_95_m: np.ndarray
    centre_sigma_m: np.ndarray
    scale_sigma: float
    focal_sigma_px: np.ndarray
    sigma_px: float
    rotation_95_deg: np.ndarray | None = None


def camera_covariance(res: BundleResult) -> tuple[np.ndarray, float]:
    """Covariance (n_cam, n_cam) of the camera columns of ``res.jac`` (free poses, then
    intrinsics) with the structure marginalised, and the estimated per-axis pixel sigma."""
    if res.jac is None:
        raise ValueError("the bundle result has no Jacobian")
    J = sparse.csr_matrix(res.jac)
    n = J.shape[1]
    ncam = 6 * len(res.free) + len(res.cameras) * res.n_intr
    bs = res.block_size
    r = res.residuals
    dof = max(res.n_pixel_rows - n, 1)
    sigma2 = float(np.sum(r * r)) / dof
    Jc, Js = J[:, :ncam].tocsc(), J[:, ncam:].tocsc()
    U = (Jc.T @ Jc).toarray()
    W = (Jc.T @ Js).tocsr()
    nS = n - ncam
    nB = nS // bs
    V = (Js.T @ Js).tocoo()
    blocks = np.zeros((nB, bs, bs))
    same = V.row // bs == V.col // bs
    np.add.at(blocks, (V.row[same] // bs, V.row[same] % bs, V.col[same] % bs), V.data[same])
    # tiny ridge: a block seen by too few views must not make the inverse blow up
    ridge = 1e-12 * np.maximum(np.trace(blocks, axis1=1, axis2=2), 1e-30)
    blocks += ridge[:, None, None] * np.eye(bs)
    Vinv = sparse.bsr_matrix((np.linalg.inv(blocks), np.arange(nB), np.arange(nB + 1)), shape=(nS, nS))
    S = U - (W @ Vinv @ W.T).toarray()
    cov = sigma2 * np.linalg.inv(0.5 * (S + S.T))
    return cov, float(np.sqrt(sigma2))


def _centre(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """Camera centre (3,) = -R^T t for a Rodrigues vector rvec (3,) and translation tvec (3,)."""
    return -rotate(-rvec[None], tvec[None])[0]


def _rotmat(rvec: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a Rodrigues vector rvec (3,)."""
    return rotate(np.repeat(rvec[None], 3, axis=0), np.eye(3)).T


def _so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of a rotation matrix R (3, 3) near the identity."""
    return 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])


def _rigid_motions(centres: np.ndarray) -> np.ndarray:
    """(3 C, 6) centre perturbations of a rigid motion of the rig with centres (C, 3): unit
    translations along x, y, z (columns 0-2), then small rotations about x, y, z through the
    centres' mean (columns 3-5, per radian)."""
    d = centres - centres.mean(axis=0)
    B = np.zeros((3 * len(centres), 6))
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        B[:, k] = np.tile(e, len(centres))
        B[:, 3 + k] = np.cross(e, d).ravel()
    return B


def _radius_95(S: np.ndarray, z: np.ndarray) -> float:
    """95 % quantile of the norm of a zero-mean Gaussian with covariance S (3, 3), from the
    standard normal samples z (N, 3)."""
    w, v = np.linalg.eigh(0.5 * (S + S.T))
    e = (z * np.sqrt(np.clip(w, 0, None))) @ v.T
    return float(np.quantile(np.linalg.norm(e, axis=1), 0.95))


def rig_uncertainty(res: BundleResult, seed: int = 0) -> RigUncertainty:
    """Centre, scale and focal-length uncertainties of the adjusted cameras ``res.cameras``."""
    cov, sigma = camera_covariance(res)
    cams: list[Camera] = res.cameras
    C = len(cams)
    ncam = cov.shape[0]
    centres = np.stack([c.center for c in cams])
    G = np.zeros((3 * C, ncam))
    eps = 1e-7
    for slot, c in enumerate(res.free):
        x = np.concatenate([cams[c].rvec, cams[c].tvec])
        for k in range(6):
            xp, xm = x.copy(), x.copy()
            xp[k] += eps
            xm[k] -= eps
            G[3 * c:3 * c + 3, 6 * slot + k] = (_centre(xp[:3], xp[3:]) - _centre(xm[:3], xm[3:])) / (2 * eps)
    Sc = G @ cov @ G.T
    Q, _ = np.linalg.qr(_rigid_motions(centres))  # orthonormal basis of the rigid motions
    Pn = np.eye(3 * C) - Q @ Q.T
    Sa = Pn @ Sc @ Pn.T
    rng = np.random.default_rng(seed)
    z = rng.standard_normal((_MC_SAMPLES, 3))
    r95, rms = np.zeros(C), np.zeros(C)
    for c in range(C):
        S3 = Sa[3 * c:3 * c + 3, 3 * c:3 * c + 3]
        r95[c] = _radius_95(S3, z)
        rms[c] = float(np.sqrt(max(np.trace(S3), 0.0)))
    rot95 = _rotation_95(res, cov, G, centres, z)
    d = centres - centres.mean(axis=0)
    s = float(np.sqrt(np.mean(np.sum(d * d, axis=1))))
    g = (d / (C * s)).ravel()  # ds / dc
    scale_sigma = float(np.sqrt(max(g @ Sc @ g, 0.0))) / s
    focal = np.full(C, np.nan)
    if "f" in res.intrinsics:
        base = 6 * len(res.free) + res.intrinsics.index("f")
        focal = np.sqrt(np.clip(np.diag(cov)[base::res.n_intr][:C], 0, None))
    return RigUncertainty(r95, rms, scale_sigma, focal, sigma, rot95)


def _rotation_95(res: BundleResult, cov: np.ndarray, G: np.ndarray, centres: np.ndarray,
                 z: np.ndarray) -> np.ndarray:
    """(C,) 95 % radius (deg) of each camera's rotation error after the best rigid alignment
    of the centres (how ``simwand.pose_errors`` measures it). Linearised: the error rotation
    (camera frame, rad) is the camera's own rotation change minus the alignment's rotation
    (the rotational part of the least-squares rigid fit of the centre changes ``G dp``).
    cov: (n, n) camera covariance; G: (3 C, n) centre Jacobian; z: (S, 3) standard normals."""
    cams: list[Camera] = res.cameras
    C = len(cams)
    Lrot = np.linalg.pinv(_rigid_motions(centres))[3:]  # (3, 3 C): alignment rotation from centre changes
    Omega = Lrot @ G  # (3, n) world-frame rotation of the alignment per parameter
    out = np.zeros(C)
    eps = 1e-7
    for c in range(C):
        # R_est = exp([a]) R; a rigid motion exp([w]) of the whole rig gives a = -R w and
        # centre changes w x d, so the aligned error is a + R Omega (camera frame, rad)
        H = cams[c].R @ Omega
        if c in res.free:
            slot = res.free.index(c)
            R0 = _rotmat(cams[c].rvec)
            for k in range(3):
                rp, rm = cams[c].rvec.copy(), cams[c].rvec.copy()
                rp[k] += eps
                rm[k] -= eps
                dR = (_so3_log(_rotmat(rp) @ R0.T) - _so3_log(_rotmat(rm) @ R0.T)) / (2 * eps)
                H[:, 6 * slot + k] += dR
        out[c] = float(np.degrees(_radius_95(H @ cov @ H.T, z)))
    return out


def rig_scale(centres: np.ndarray) -> float:
    """The rig's scale as the uncertainty uses it: rms distance (m) of the centres (C, 3)
    from their centroid."""
    d = centres - centres.mean(axis=0)
    return float(np.sqrt(np.mean(np.sum(d * d, axis=1))))


__all__ = ["RigUncertainty", "camera_covariance", "rig_scale", "rig_uncertainty"]
