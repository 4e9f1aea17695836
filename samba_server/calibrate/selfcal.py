"""Self-calibration from an ordinary take of the subject's 8 labelled markers.

Two modes:

* **full**: every camera pose from scratch (essential matrix for the best pair, PnP for the
  others, bundle adjustment over poses and all marker positions); metric scale from the
  subject's tibia length (knee-to-ankle marker distance) or height; world frame from the
  standard pose at the start of the take (facing +Y, feet on the floor);
* **repair** (``repair=[names]``): a bumped camera gets a new pose against the others, which
  keep theirs (and so keep the scale and world frame); needs >= 2 untouched cameras.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from samba_common.body import ANKLE_HEIGHT
from samba_common.calib import Camera, CameraRig
from samba_common.skeleton import M
from samba_server.calibrate.bundle import Observations, bundle_adjust, camera_from_pose, transform_rig
from samba_server.calibrate.floor import standard_pose_transform
from samba_server.calibrate.wand import CalibrateError, normalized
from samba_server.triangulate import TriangulateConfig, Triangulator

log = logging.getLogger(__name__)

#: shoulder-to-ankle marker distance as a fraction of standing height (Drillis & Contini
#: segment table: shoulder 0.818 H, ankle 0.039 H)
SHOULDER_ANKLE_PER_HEIGHT = 0.779


@dataclass
class SelfCalReport:
    rms_px: dict[str, float]
    n_obs: dict[str, int]
    n_frames: int
    scale_source: str

    def lines(self) -> list[str]:
        out = [f"frames used: {self.n_frames}; scale from {self.scale_source}"]
        out += [f"  {k}: {self.rms_px[k]:.3f} px over {self.n_obs[k]} observations" for k in self.rms_px]
        return out


def _triangulate(cams: list[Camera], uv: np.ndarray) -> np.ndarray:
    """uv (F, C, 8, 2) -> points (F, 8, 3) (outlier views rejected)."""
    F, C, K, _ = uv.shape
    res = Triangulator(CameraRig(cams), TriangulateConfig(max_error_px=3.0, iterations=2)).triangulate(
        uv.transpose(1, 0, 2, 3).reshape(C, F * K, 2))
    return res.points.reshape(F, K, 3)


def _pnp(cam: Camera, pts: np.ndarray, uv: np.ndarray) -> Camera:
    """Pose of ``cam`` from 3D points (N, 3) and its raw pixels (N, 2) (RANSAC + refinement)."""
    ok = np.all(np.isfinite(pts), axis=1) & np.all(np.isfinite(uv), axis=1)
    if ok.sum() < 12:
        raise CalibrateError(f"camera {cam.name}: only {int(ok.sum())} markers shared with the calibrated cameras")
    obj, img = pts[ok], normalized(cam, uv[ok])
    f = cam.matrix[0, 0]
    good, rv, tv, inl = cv2.solvePnPRansac(obj, img, np.eye(3), None, iterationsCount=1000,
                                           reprojectionError=3.0 / f, confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not good or inl is None or len(inl) < 8:
        raise CalibrateError(f"camera {cam.name}: no consistent pose from the shared markers")
    inl = inl.ravel()
    _, rv, tv = cv2.solvePnP(obj[inl], img[inl], np.eye(3), None, rv, tv, True, cv2.SOLVEPNP_ITERATIVE)
    return Camera(cam.name, cam.size, cam.matrix.copy(), cam.dist.copy(), rv.ravel(), tv.ravel())


#: marker order with left and right exchanged (MARKER_NAMES come in left/right pairs)
LR_SWAP = [1, 0, 3, 2, 5, 4, 7, 6]


def _epipolar_inliers(a: Camera, b: Camera, ua: np.ndarray, ub: np.ndarray) -> int:
    """Essential-matrix RANSAC inliers between labelled observations ua, ub (N, 2) raw px."""
    ok = np.all(np.isfinite(ua), axis=1) & np.all(np.isfinite(ub), axis=1)
    if ok.sum() < 20:
        return -1
    f = 0.5 * (a.matrix[0, 0] + b.matrix[0, 0])
    E, mask = cv2.findEssentialMat(normalized(a, ua[ok]), normalized(b, ub[ok]), np.eye(3), method=cv2.RANSAC,
                                   prob=0.999, threshold=1.0 / f)
    return -1 if E is None else int(mask.sum())


def fix_mirrored_cameras(cams: list[Camera], uv: np.ndarray) -> np.ndarray:
    """Undo a whole-take left/right label swap in a camera (a mote that labelled the T-pose
    as seen from the wrong side): against the camera with most observations, keep for every
    other camera the labelling (as is, or left<->right) with more epipolar inliers.
    uv: (F, C, 8, 2) -> corrected copy."""
    F, C, K, _ = uv.shape
    uv = uv.copy()
    counts = np.isfinite(uv[..., 0]).sum(axis=(0, 2))
    ref = int(np.argmax(counts))
    for c in range(C):
        if c == ref:
            continue
        ua = uv[:, ref].reshape(-1, 2)
        keep = _epipolar_inliers(cams[ref], cams[c], ua, uv[:, c].reshape(-1, 2))
        swap = _epipolar_inliers(cams[ref], cams[c], ua, uv[:, c][:, LR_SWAP].reshape(-1, 2))
        if swap > keep:
            log.info("camera %s: left/right labels swapped against %s (%d vs %d inliers): corrected",
                     cams[c].name, cams[ref].name, swap, keep)
            uv[:, c] = uv[:, c][:, LR_SWAP]
    return uv


def _subsample(uv: np.ndarray, max_frames: int) -> np.ndarray:
    step = max(1, int(np.ceil(len(uv) / max_frames)))
    return uv[::step]


def self_calibrate(
    rig: CameraRig,
    uv: np.ndarray,
    tibia: float | None = None,
    height: float | None = None,
    repair: list[str] | None = None,
    fps: float = 60.0,
    max_frames: int = 150,
    ankle_height: float = ANKLE_HEIGHT,
) -> tuple[CameraRig, SelfCalReport]:
    """Calibrate extrinsics from labelled markers uv (F, C, 8, 2) raw px (NaN = unseen).

    Full mode needs ``tibia`` (m, knee-to-ankle marker distance) or ``height`` (m); the
    take must start with ~1 s of the standard pose. ``repair``: names of cameras to re-pose
    against the others (no scale needed)."""
    cams0 = rig.cameras
    F, C, K, _ = uv.shape
    if C != len(cams0) or K != 8:
        raise ValueError("uv must be (F, C, 8, 2) for the rig's cameras")
    if repair:
        return _repair(rig, uv, repair, max_frames)
    if (tibia is None) == (height is None):
        raise ValueError("give exactly one of tibia or height for the metric scale")
    seen = np.isfinite(uv[..., 0])  # (F, C, 8)
    for c in range(C):
        if seen[:, c].sum() < 20:
            raise CalibrateError(f"camera {cams0[c].name} saw only {int(seen[:, c].sum())} labelled markers")
    uv = fix_mirrored_cameras(cams0, uv)
    n_pose = max(1, int(round(fps)))
    pose_uv = uv[:n_pose]
    sub = _subsample(uv, max_frames)
    co = np.array([[np.sum(seen[:, a] & seen[:, b]) if a != b else 0 for b in range(C)] for a in range(C)])
    pairs = sorted(((co[a, b], a, b) for a in range(C) for b in range(a + 1, C)), reverse=True)
    best, errors = None, []
    for n, i, j in pairs[:3]:
        try:
            cams, rms, nobs = _initialise(cams0, uv, sub, seen, int(i), int(j), max_frames)
        except CalibrateError as exc:
            errors.append(str(exc))
            continue
        total = float(np.sqrt(np.mean([v ** 2 for v in rms.values()])))
        log.info("self-calibration from %s-%s: rms %.3f px", cams0[i].name, cams0[j].name, total)
        if best is None or total < best[0]:
            best = (total, cams, rms, nobs)
        if total < 1.0:
            break
    if best is None or best[0] > 3.0:
        raise CalibrateError("self-calibration did not converge: " + ("; ".join(errors) or "large reprojection errors"))
    _, cams, rms, nobs = best
    # metric scale
    allP = _triangulate(cams, uv)
    if tibia is not None:
        d = np.concatenate([np.linalg.norm(allP[:, M["left_knee"]] - allP[:, M["left_ankle"]], axis=1),
                            np.linalg.norm(allP[:, M["right_knee"]] - allP[:, M["right_ankle"]], axis=1)])
        d = d[np.isfinite(d)]
        if not len(d):
            raise CalibrateError("no frame with knee and ankle markers triangulated: cannot scale by tibia")
        s, source = tibia / float(np.median(d)), f"tibia {tibia:.3f} m"
    else:
        sh = 0.5 * (allP[:n_pose, M["left_shoulder"]] + allP[:n_pose, M["right_shoulder"]])
        an = 0.5 * (allP[:n_pose, M["left_ankle"]] + allP[:n_pose, M["right_ankle"]])
        d = np.linalg.norm(sh - an, axis=1)
        d = d[np.isfinite(d)]
        if not len(d):
            raise CalibrateError("standard pose: shoulders and ankles not triangulated: cannot scale by height")
        s, source = SHOULDER_ANKLE_PER_HEIGHT * height / float(np.median(d)), f"height {height:.2f} m"
    cams = transform_rig(cams, np.eye(3), np.zeros(3), s)
    A, b = standard_pose_transform(_triangulate(cams, pose_uv), ankle_height)
    cams = transform_rig(cams, A, b)
    fwd = knee_forward(_triangulate(cams, sub))
    if fwd < 0:
        # every camera's left/right labels were mirrored (motes labelled without knowing where
        # they stand): the subject faced -Y. Turn the world half a turn about Z.
        log.info("knees bend towards -Y (%.3f m): labels were mirrored, world turned by 180 deg", fwd)
        cams = transform_rig(cams, np.diag([-1.0, -1.0, 1.0]), np.zeros(3))
    return CameraRig(cams, dict(rig.metadata)), SelfCalReport(rms, nobs, len(sub), source)


def knee_forward(markers: np.ndarray) -> float:
    """Mean offset (m) along +Y of the knees from the shoulder-ankle line of the same side,
    over the frames where it exceeds 3 cm: knees bend forwards, so a subject labelled and
    framed correctly (facing +Y) gives a positive value. markers: (F, 8, 3)."""
    d = []
    for side in ("left", "right"):
        s, k, a = (markers[:, M[f"{side}_{j}"]] for j in ("shoulder", "knee", "ankle"))
        u = s - a
        t = np.sum((k - a) * u, axis=1) / np.maximum(np.sum(u * u, axis=1), 1e-9)
        off = k - (a + t[:, None] * u)
        d.append(off[:, 1])
    d = np.concatenate(d)
    d = d[np.isfinite(d) & (np.abs(np.nan_to_num(d)) > 0.03)]
    return float(np.mean(d)) if len(d) else 0.0


def _initialise(cams0, uv, sub, seen, i, j, max_frames):
    """Poses from pair (i, j) (essential matrix) and PnP for the others, then adjustment."""
    C = len(cams0)
    F = len(uv)
    both = seen[:, i] & seen[:, j]
    if both.sum() < 30:
        raise CalibrateError(f"camera pair {cams0[i].name}-{cams0[j].name} shares only {int(both.sum())} markers")
    p1 = normalized(cams0[i], uv[:, i][both])
    p2 = normalized(cams0[j], uv[:, j][both])
    f = 0.5 * (cams0[i].matrix[0, 0] + cams0[j].matrix[0, 0])
    E, mask = cv2.findEssentialMat(p1, p2, np.eye(3), method=cv2.RANSAC, prob=0.9999, threshold=0.7 / f)
    if E is None or E.shape[0] < 3:
        raise CalibrateError("no essential matrix: the subject did not move enough")
    inl = mask.ravel().astype(bool)
    _, R, t, _ = cv2.recoverPose(E[:3], p1[inl], p2[inl], np.eye(3))
    posed: list[Camera | None] = [None] * C
    posed[i] = camera_from_pose(cams0[i], np.eye(3), np.zeros(3))
    posed[j] = camera_from_pose(cams0[j], R, t.ravel())
    step = max(1, int(np.ceil(F / max_frames)))
    while any(p is None for p in posed):
        idx = [c for c in range(C) if posed[c] is not None]
        P = _triangulate([posed[c] for c in idx], sub[:, idx])
        cand = [(int(np.sum(np.isfinite(P[..., 0]) & seen[::step, c][: len(P)])), c) for c in range(C) if posed[c] is None]
        _, c = max(cand)
        posed[c] = _pnp(cams0[c], P.reshape(-1, 3), sub[:, c].reshape(-1, 2))
    return _adjust([p for p in posed if p is not None], sub, fixed=(i,))


def _adjust(cams: list[Camera], uv: np.ndarray, fixed: tuple[int, ...], max_error_px: float = 3.0):
    """Bundle adjustment over free points; second pass without outliers. uv (F, C, 8, 2)."""
    F, C, K, _ = uv.shape
    uv = uv.copy()
    for it in range(2):
        P = _triangulate(cams, uv).reshape(-1, 3)
        okp = np.all(np.isfinite(P), axis=1)
        remap = -np.ones(len(P), dtype=int)
        remap[okp] = np.arange(okp.sum())
        f_, c_, k_ = np.nonzero(np.isfinite(uv[..., 0]))
        pid = remap[f_ * K + k_]
        keep = pid >= 0
        obs = Observations(c_[keep], pid[keep], uv[f_[keep], c_[keep], k_[keep]])
        res = bundle_adjust(cams, obs, P[okp], fixed=fixed, f_scale=1.0)
        cams = res.cameras
        err = np.linalg.norm(res.residuals, axis=1)
        bad = err > max_error_px
        if it == 0 and bad.any():
            uv[f_[keep][bad], c_[keep][bad], k_[keep][bad]] = np.nan
        else:
            break
    names = [c.name for c in cams]
    e2 = np.sum(res.residuals ** 2, axis=1)
    rms = {n: float(np.sqrt(np.mean(e2[obs.cam == c]))) for c, n in enumerate(names) if np.any(obs.cam == c)}
    nobs = {n: int(np.sum(obs.cam == c)) for c, n in enumerate(names)}
    return cams, rms, nobs


def _repair(rig: CameraRig, uv: np.ndarray, repair: list[str], max_frames: int):
    names = rig.names
    bad = [names.index(n) for n in repair if n in names]
    unknown = [n for n in repair if n not in names]
    if unknown:
        raise ValueError(f"unknown camera(s) {unknown}; cameras: {names}")
    good = [c for c in range(len(names)) if c not in bad]
    if len(good) < 2:
        raise CalibrateError("repair needs at least 2 cameras whose calibration is still good")
    sub = _subsample(uv, max_frames)
    P = _triangulate([rig.cameras[c] for c in good], sub[:, good])
    cams = list(rig.cameras)
    for c in bad:
        cams[c] = _pnp(rig.cameras[c], P.reshape(-1, 3), sub[:, c].reshape(-1, 2))
    cams, rms, nobs = _adjust(cams, sub, fixed=tuple(good))
    return CameraRig(cams, dict(rig.metadata)), SelfCalReport(rms, nobs, len(sub), "the untouched cameras")
