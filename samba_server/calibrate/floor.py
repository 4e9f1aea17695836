"""World frame (origin, Z up, heading) from an L-frame or from a subject in the standard pose.

Both return the similarity of the world ``x_new = A @ x_old + b`` and apply it to a rig with
:func:`samba_server.calibrate.bundle.transform_rig`.

* L-frame: three markers, a corner and two arms at a right angle; the corner is the origin,
  the **short arm points to +X, the long arm to +Y**, Z = X x Y is up; the markers' centres sit
  ``height`` metres above the floor.
* Standard pose (FORMATS.md): subject standing upright facing +Y, arms out; +X points from the
  subject's left to right wrist/shoulder, Z along the body axis, origin between the ankles on
  the floor (ankle markers ``ankle_height`` above it).
"""

from __future__ import annotations

import itertools
import logging

import numpy as np

from samba_common.body import ANKLE_HEIGHT
from samba_common.calib import CameraRig
from samba_common.skeleton import M
from samba_server.calibrate.bundle import transform_rig
from samba_server.calibrate.wand import CalibrateError
from samba_server.triangulate import Triangulator

log = logging.getLogger(__name__)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def frame_from_axes(origin: np.ndarray, x_dir: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World change (A (3, 3), b (3,)) putting ``origin`` at 0, ``up`` on +Z and ``x_dir``
    (made orthogonal to up) on +X."""
    z = _unit(np.asarray(up, float))
    x = _unit(np.asarray(x_dir, float) - (np.asarray(x_dir, float) @ z) * z)
    y = np.cross(z, x)
    A = np.stack([x, y, z])
    return A, -A @ np.asarray(origin, float)


def match_views(rig: CameraRig, uv: np.ndarray) -> np.ndarray:
    """Label unlabelled blobs consistently across views.

    uv: (F, C, K, 2) raw pixels, any order per view, NaN = view missing. Every combination
    of orders over the views is tried per frame (K!^(C-1) triangulations, fine for the
    3-marker L-frame and <= 5 cameras); the one with the smallest reprojection error wins.
    Returns the reordered array (orders consistent across views, arbitrary across frames)."""
    from samba_server.calibrate.wand import _resolve

    K = uv.shape[2]
    perms = list(itertools.permutations(range(K)))
    if len(perms) ** (len(rig) - 1) > 5000:
        raise CalibrateError(f"too many cameras ({len(rig)}) to match {K} unlabelled markers exhaustively")
    out, _, _ = _resolve(list(rig.cameras), uv, perms=perms)
    return out


def triangulate_static(rig: CameraRig, uv: np.ndarray) -> np.ndarray:
    """Median 3D positions (K, 3) of a static unlabelled object seen in uv (F, C, K, 2); the
    labels follow the first camera's order and are only consistent if it sees every frame,
    so points are sorted per frame by a canonical order (distance to the centroid)."""
    m = match_views(rig, uv)
    F, C, K, _ = uv.shape
    res = Triangulator(rig).triangulate(m.transpose(1, 0, 2, 3).reshape(C, F * K, 2))
    P = res.points.reshape(F, K, 3)
    ok = np.all(np.isfinite(P), axis=(1, 2))
    if not ok.any():
        raise CalibrateError("the static object was not seen by two cameras at once")
    P = P[ok]
    # canonical order per frame: by distance from the centroid (L-frame: corner nearest)
    d = np.linalg.norm(P - P.mean(axis=1, keepdims=True), axis=2)
    P = np.take_along_axis(P, np.argsort(d, axis=1)[..., None], axis=1)
    return np.median(P, axis=0)


def lframe_transform(points: np.ndarray, height: float = 0.0,
                     arms: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World change from three L-frame marker positions (3, 3) in any order (see module doc).

    With the arm lengths ``arms`` (short, long) known, the rigid L-frame model is fitted to
    all three markers (least squares), which spreads their errors instead of trusting the
    corner and the short arm alone."""
    P = np.asarray(points, float)
    if P.shape != (3, 3) or not np.all(np.isfinite(P)):
        raise CalibrateError("the L-frame needs three triangulated markers")
    best, corner = np.inf, 0
    for k in range(3):
        a, b = [P[j] - P[k] for j in range(3) if j != k]
        cosang = abs(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b))
        if cosang < best:
            best, corner = cosang, k
    if best > np.cos(np.radians(75)):
        raise CalibrateError(f"the three markers do not form a right angle (best {np.degrees(np.arccos(best)):.0f} deg)")
    vecs = [P[j] - P[corner] for j in range(3) if j != corner]
    vecs.sort(key=np.linalg.norm)
    x_arm, y_arm = vecs
    if abs(np.linalg.norm(y_arm) - np.linalg.norm(x_arm)) < 0.02:
        raise CalibrateError("L-frame arms have nearly equal length: cannot tell X from Y")
    z = _unit(np.cross(x_arm, y_arm))
    origin = P[corner] - height * z
    A, b = frame_from_axes(origin, x_arm, z)
    if arms is None:
        return A, b
    # refine: rigid fit of the model (world coordinates) to the measured markers
    others = [j for j in range(3) if j != corner]
    others.sort(key=lambda j: np.linalg.norm(P[j] - P[corner]))
    meas = P[[corner] + others]
    model = np.array([[0.0, 0.0, height], [arms[0], 0.0, height], [0.0, arms[1], height]])
    mm, pm = model.mean(axis=0), meas.mean(axis=0)
    U, _, Vt = np.linalg.svd((meas - pm).T @ (model - mm))
    R = Vt.T @ np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))]) @ U.T  # measured -> model
    res = np.linalg.norm((meas - pm) @ R.T + mm - model, axis=1)
    if res.max() > 0.05:
        raise CalibrateError(f"L-frame markers are {1000 * res.max():.0f} mm off the given arms {arms}: check --lframe")
    return R, mm - R @ pm


def standard_pose_transform(markers: np.ndarray, ankle_height: float = ANKLE_HEIGHT) -> tuple[np.ndarray, np.ndarray]:
    """World change from labelled markers (F, 8, 3) of a subject standing in the standard pose
    (use the first second of a take): the median over frames is used."""
    m = np.nanmedian(np.asarray(markers, float), axis=0)
    need = ["left_shoulder", "right_shoulder", "left_ankle", "right_ankle"]
    if not all(np.all(np.isfinite(m[M[n]])) for n in need):
        raise CalibrateError(f"standard pose: markers {need} must all be triangulated")
    x = m[M["right_shoulder"]] - m[M["left_shoulder"]]
    if np.all(np.isfinite(m[[M["left_wrist"], M["right_wrist"]]])):
        x = x + m[M["right_wrist"]] - m[M["left_wrist"]]
    ankles = 0.5 * (m[M["left_ankle"]] + m[M["right_ankle"]])
    up = 0.5 * (m[M["left_shoulder"]] + m[M["right_shoulder"]]) - ankles
    z = _unit(up - (up @ _unit(x)) * _unit(x))
    return frame_from_axes(ankles - ankle_height * z, x, z)


def apply_transform(rig: CameraRig, A: np.ndarray, b: np.ndarray) -> CameraRig:
    """The rig in the new world ``x_new = A @ x_old + b``."""
    return CameraRig(transform_rig(rig.cameras, A, b), dict(rig.metadata))
