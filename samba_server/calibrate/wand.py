"""Extrinsics from a wand take: essential matrix, incremental PnP, label resolution, bundle adjustment.

Input: the cameras' intrinsics (poses ignored) and unlabelled 2D observations of a wand with
``K`` collinear markers (2, optionally 3) at known offsets, as an array ``uv`` (F, C, K, 2)
raw pixels: for each frame and camera the K blobs in any order, NaN where the camera did not
see exactly K blobs. Steps:

1. the camera pair sharing most frames: essential matrix (RANSAC) from both possible matchings
   of the wand ends per frame (the wrong one is an outlier), relative pose, metric scale from
   the median wand length;
2. every other camera, in order of shared frames: PnP (RANSAC, both matchings) against the
   triangulated wand ends;
3. per frame, the labelling of the ends in every view that minimises reprojection error;
4. bundle adjustment over all camera poses, the intrinsics a wand can see (focal length,
   principal point, k1, k2; each held by a prior from the board step) and all wand positions
   (rigid wand of the given length = metric scale), robust loss, one more pass without outlier
   observations with the priors weighed by the measured pixel noise;
5. uncertainties of the camera centres and of the scale from the adjustment's covariance
   (:mod:`samba_server.calibrate.uncertainty`);
6. world frame: provisional (Z up from the mean camera "up", origin under the wand centroid,
   floor at the lowest wand marker) until ``floor`` sets it properly.
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from samba_common.calib import Camera, CameraRig
from samba_server.calibrate.bundle import Observations, bundle_adjust, camera_from_pose, transform_rig
from samba_server.calibrate.uncertainty import RigUncertainty, rig_uncertainty
from samba_server.triangulate import TriangulateConfig, Triangulator

log = logging.getLogger(__name__)


class CalibrateError(RuntimeError):
    """The data cannot determine the calibration (too few shared views, unseen cameras...)."""


#: intrinsics the wand adjustment refines by default (names of ``bundle.INTRINSIC_PARAMS``)
REFINE_INTRINSICS = ("f", "cx", "cy", "k1", "k2")

#: metadata key prefix of a camera's intrinsic standard deviations from the board step:
#: ``intrinsics_std_<camera> = [fx, fy, cx, cy, k1, k2, p1, p2, k3]`` (px, px, px, px, 1...)
STD_KEY = "intrinsics_std_"

#: metadata key prefix of the board step's covariance (9 x 9, same parameters and order as
#: ``STD_KEY``; written by ``samba-calibrate intrinsics``); preferred to ``STD_KEY`` as prior
COV_KEY = "intrinsics_cov_"


def board_priors(camera: str, std: np.ndarray, cov: np.ndarray) -> dict[str, list]:
    """The calibration ``[metadata]`` entries that carry one camera's board-step
    uncertainties to the wand step: std (9,) and cov (9, 9) in ``STD_KEY`` order."""
    return {STD_KEY + camera: [float(v) for v in np.ravel(std)[:9]],
            COV_KEY + camera: [[float(v) for v in row] for row in np.asarray(cov, float)]}


#: positions of f (fx), cx, cy, k1, k2 in the board step's 9 parameters
_BOARD_INDEX = (0, 2, 3, 4, 5)


#: lower bound of a board-step prior, as a fraction of :func:`default_prior_sigma`. It was 0.1,
#: which replaced the board's principal-point sigma (about 0.2 px) by 0.48 px and its focal
#: length sigma by 0.28 px: the wand then pulled the principal point 0.3-0.5 px off (0.1-0.2
#: deg of camera rotation). 0.01 (0.05 px for cx, cy) only guards against a zero.
PRIOR_FLOOR = 0.01
#: the board step's covariance (OpenCV's, from the corner residuals) is scaled by this squared:
#: measured on rendered boards, its k1/k2 errors are 1.5-3x the sigma it reports, and a prior
#: tighter than the truth pins the wand to biased intrinsics (rotations 1.6x their reported
#: 95 % angle, centres outside their radius).
BOARD_SIGMA_SCALE = 2.0


def default_prior_sigma(cam: Camera) -> np.ndarray:
    """Prior standard deviations (5,) for f, cx, cy, k1, k2 when the board step gave none:
    2 % of the focal length, 3 % of the image width for the principal point, 0.05 for k1, k2."""
    w = float(cam.size[0])
    return np.array([0.02 * cam.matrix[0, 0], 0.03 * w, 0.03 * w, 0.05, 0.05])


def prior_sigma(rig: CameraRig, names: tuple[str, ...]) -> np.ndarray:
    """(C, len(names)) prior standard deviations of the intrinsics ``names`` for every camera:
    the board step's (``metadata[intrinsics_std_<camera>]``, as measured: OpenCV's estimate
    is honest on rendered boards, see docs/calibration.md; floored only at
    :data:`PRIOR_FLOOR` of :func:`default_prior_sigma` so a degenerate zero never freezes a
    parameter). Units: px for f, cx, cy; unitless for k1, k2. A camera without them
    (intrinsics from elsewhere, whose accuracy is unknown) keeps its intrinsics: its priors
    are 1e-6 of the defaults."""
    from samba_server.calibrate.bundle import INTRINSIC_PARAMS

    out = []
    for cam in rig.cameras:
        d = default_prior_sigma(cam)
        std = rig.metadata.get(STD_KEY + cam.name)
        board = None
        if isinstance(std, (list, tuple)) and len(std) >= 6:
            sd = np.asarray(std[:6], dtype=float)
            board = np.array([0.5 * (sd[0] + sd[1]), sd[2], sd[3], sd[4], sd[5]])
            if not (np.all(np.isfinite(board)) and np.all(board > 0)):
                board = None
        if board is None:
            log.info("%s: no board-step uncertainties in the calibration file: intrinsics kept as given", cam.name)
            d = 1e-6 * d
        else:
            d = np.maximum(BOARD_SIGMA_SCALE * board, PRIOR_FLOOR * d)
        out.append([d[INTRINSIC_PARAMS.index(n)] for n in names])
    return np.array(out, dtype=float).reshape(len(rig), len(names))


def prior_covariance(rig: CameraRig, names: tuple[str, ...]) -> np.ndarray:
    """(C, n, n) prior covariances of the intrinsics ``names`` (n = len(names)) for every
    camera: the board step's full covariance (``metadata[intrinsics_cov_<camera>]``, its f
    is fx's) when present, else the diagonal of :func:`prior_sigma`. Each diagonal gets
    (:data:`PRIOR_FLOOR` x :func:`default_prior_sigma`)^2 added, so a degenerate zero never
    freezes a parameter. Units: px^2 for f, cx, cy; 1 for k1, k2."""
    from samba_server.calibrate.bundle import INTRINSIC_PARAMS

    diag = prior_sigma(rig, names)
    out = np.einsum("ci,ij->cij", diag ** 2, np.eye(len(names)))
    for c, cam in enumerate(rig.cameras):
        cov = rig.metadata.get(COV_KEY + cam.name)
        if cov is None or (STD_KEY + cam.name) not in rig.metadata:
            continue
        try:
            full = np.asarray(cov, dtype=float).reshape(9, 9)
        except ValueError:
            log.warning("%s: %s%s is not 9 x 9: using the standard deviations", cam.name, COV_KEY, cam.name)
            continue
        idx = [_BOARD_INDEX[INTRINSIC_PARAMS.index(n)] for n in names]
        sub = BOARD_SIGMA_SCALE ** 2 * full[np.ix_(idx, idx)]
        floor = PRIOR_FLOOR * default_prior_sigma(cam)[[INTRINSIC_PARAMS.index(n) for n in names]]
        sub = 0.5 * (sub + sub.T) + np.diag(floor ** 2)
        if np.all(np.isfinite(sub)) and np.all(np.linalg.eigvalsh(sub) > 0):
            out[c] = sub
        else:
            log.warning("%s: the board covariance is not positive definite: using the standard deviations", cam.name)
    return out


@dataclass
class WandReport:
    """Quality figures of a wand calibration."""

    rms_px: dict[str, float]  #: reprojection rms per camera (px), bundle adjustment residuals
    n_obs: dict[str, int]  #: observations per camera used in the final adjustment
    wand_mean_m: float  #: mean free-triangulated wand length (m)
    wand_sigma_m: float  #: its standard deviation (m)
    n_frames: int  #: wand positions used
    coverage: dict[str, float] = field(default_factory=dict)  #: "camA-camB" -> fraction of volume cells
    pair_frames: dict[str, int] = field(default_factory=dict)  #: "camA-camB" -> frames seen by both
    uncertainty: RigUncertainty | None = None  #: centre / scale uncertainties (covariance)
    intrinsics_change: dict[str, str] = field(default_factory=dict)  #: camera -> "fx +0.62 px ..." line

    @property
    def rms_total(self) -> float:
        n = sum(self.n_obs.values())
        return float(np.sqrt(sum(self.rms_px[k] ** 2 * self.n_obs[k] for k in self.n_obs) / max(n, 1)))

    def lines(self) -> list[str]:
        out = [f"wand positions used: {self.n_frames}",
               f"wand length: mean {self.wand_mean_m * 1000:.2f} mm, sigma {self.wand_sigma_m * 1000:.2f} mm",
               f"reprojection rms: {self.rms_total:.3f} px overall"]
        out += [f"  {k}: {self.rms_px[k]:.3f} px over {self.n_obs[k]} observations" for k in self.rms_px]
        u = self.uncertainty
        if u is not None:
            out.append(f"uncertainty (95 %, from the adjustment's covariance, pixel noise {u.sigma_px:.3f} px per axis):")
            out.append(f"  scale: +-{196 * u.scale_sigma:.3f} % (plus the error of the wand length itself)")
            for k, name in enumerate(self.rms_px):
                f = "" if not np.isfinite(u.focal_sigma_px[k]) else f", focal length +-{1.96 * u.focal_sigma_px[k]:.2f} px"
                r = "" if u.rotation_95_deg is None else f", rotation within {u.rotation_95_deg[k]:.2f} deg"
                out.append(f"  {name}: centre within {1000 * u.centre_95_m[k]:.1f} mm{r}{f}")
        if self.intrinsics_change:
            out.append("intrinsics refined by the wand (change from the input):")
            out += [f"  {k}: {v}" for k, v in self.intrinsics_change.items()]
        out.append("coverage per camera pair (shared frames, fraction of the 4x4x2 m volume in 0.5 m cells):")
        out += [f"  {k}: {self.pair_frames.get(k, 0)} frames, {v * 100:.0f} %" for k, v in self.coverage.items()]
        return out


def normalized(cam: Camera, uv: np.ndarray) -> np.ndarray:
    """Raw pixels (..., 2) -> undistorted normalised coordinates (..., 2)."""
    shp = uv.shape
    return cam.undistort_normalized(uv.reshape(-1, 2)).reshape(shp)


def _order_collinear(uv: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Sort K >= 3 blobs of each view (F, C, K, 2) along the wand line (end to end)."""
    c = np.mean(uv, axis=2, keepdims=True)  # NaN views stay NaN and are sorted arbitrarily
    d = uv - c
    # principal direction per view
    cov = np.einsum("fcki,fckj->fcij", np.nan_to_num(d), np.nan_to_num(d))
    _, vecs = np.linalg.eigh(cov)
    axis = vecs[..., :, -1]
    s = np.einsum("fcki,fci->fck", np.nan_to_num(d), axis)
    order = np.argsort(s, axis=2)
    out = np.take_along_axis(uv, order[..., None], axis=2)
    # put the end nearer to the middle marker's offset side first, like ``offsets``
    mid_off = (offsets[1] - offsets[0]) / (offsets[-1] - offsets[0])
    with np.errstate(invalid="ignore", divide="ignore"):
        seg = np.linalg.norm(out[:, :, 1] - out[:, :, 0], axis=-1) / np.linalg.norm(out[:, :, -1] - out[:, :, 0], axis=-1)
    flip = np.abs(seg - mid_off) > np.abs((1 - seg) - mid_off)
    out[flip] = out[flip][:, ::-1]
    return out


def _triangulator(cams: list[Camera]) -> Triangulator:
    return Triangulator(CameraRig(cams), TriangulateConfig(max_error_px=1e9, iterations=2))


def _resolve(cams: list[Camera | None], uv: np.ndarray,
             perms: list[tuple[int, ...]] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Choose per frame the marker order in each posed view that fits best.

    cams: (C,) posed cameras or None; uv (F, C, K, 2). ``perms``: candidate orders of the K
    blobs of a view (default: as is and reversed, i.e. the two ends of a wand); every
    combination over the posed views is tried (the first posed view keeps its order).
    Returns uv with the chosen orders, points (F, K, 3) (NaN where < 2 posed views) and
    rms (F,) px."""
    F, C, Kw, _ = uv.shape
    if perms is None:
        perms = [tuple(range(Kw)), tuple(range(Kw))[::-1]]
    posed = [c for c in range(C) if cams[c] is not None]
    tri = _triangulator([cams[c] for c in posed])
    sub = uv[:, posed]
    best_cost = np.full(F, np.inf)
    best = np.zeros((F, len(posed)), dtype=int)
    best_pts = np.full((F, Kw, 3), np.nan)
    best_rms = np.full(F, np.nan)
    for combo in itertools.product(range(len(perms)), repeat=len(posed) - 1):
        choice = (0,) + combo
        u = np.stack([sub[:, j][:, list(perms[k])] for j, k in enumerate(choice)], axis=1)
        res = tri.triangulate(u.transpose(1, 0, 2, 3).reshape(len(posed), F * Kw, 2))
        rms = res.error.reshape(F, Kw)
        fin = np.all(np.isfinite(rms), axis=1)
        cost = np.full(F, np.inf)
        cost[fin] = np.mean(rms[fin] ** 2, axis=1)
        better = cost < best_cost
        best_cost[better] = cost[better]
        best[better] = choice
        best_pts[better] = res.points.reshape(F, Kw, 3)[better]
        best_rms[better] = np.sqrt(cost[better])
    out = uv.copy()
    for j, c in enumerate(posed):
        for k, p in enumerate(perms):
            f = best[:, j] == k
            if k and f.any():
                out[f, c] = uv[f, c][:, list(p)]
    return out, best_pts, best_rms


def _initial_pair(cams: list[Camera], xy: np.ndarray, seen: np.ndarray, i: int, j: int, min_frames: int):
    """Relative pose of camera j w.r.t. camera i (i at the origin), unit baseline."""
    both = np.flatnonzero(seen[:, i] & seen[:, j])
    if len(both) < min_frames:
        raise CalibrateError(f"cameras {cams[i].name} and {cams[j].name} share only {len(both)} wand frames "
                             f"(need >= {min_frames}): wave the wand where both cameras see it")
    a = xy[both, i]  # (n, K, 2)
    b = xy[both, j]
    p1 = np.concatenate([a.reshape(-1, 2), a.reshape(-1, 2)])
    p2 = np.concatenate([b.reshape(-1, 2), b[:, ::-1].reshape(-1, 2)])
    f = 0.5 * (cams[i].matrix[0, 0] + cams[j].matrix[0, 0])
    E, mask = cv2.findEssentialMat(p1, p2, np.eye(3), method=cv2.RANSAC, prob=0.9999, threshold=1.5 / f)
    if E is None or E.shape != (3, 3):
        raise CalibrateError(f"no essential matrix between {cams[i].name} and {cams[j].name}: degenerate wand motion")
    # keep per frame the matching of the ends with the smaller epipolar error, then re-fit E
    # on those correspondences only (no label outliers left)
    n, Kw = len(both), a.shape[1]
    h1 = np.concatenate([p1, np.ones((len(p1), 1))], axis=1)
    h2 = np.concatenate([p2, np.ones((len(p2), 1))], axis=1)
    Ex1, Etx2 = h1 @ E.T, h2 @ E
    num = np.sum(h2 * Ex1, axis=1) ** 2
    samp = num / (Ex1[:, 0] ** 2 + Ex1[:, 1] ** 2 + Etx2[:, 0] ** 2 + Etx2[:, 1] ** 2)
    cost = samp.reshape(2, n, Kw).sum(axis=2)
    pick = cost[1] < cost[0]
    q2 = np.where(pick[:, None, None], b[:, ::-1], b)
    p1, p2 = a.reshape(-1, 2), q2.reshape(-1, 2)
    E, mask = cv2.findEssentialMat(p1, p2, np.eye(3), method=cv2.RANSAC, prob=0.9999, threshold=1.0 / f)
    if E is None or E.shape != (3, 3):
        raise CalibrateError(f"no essential matrix between {cams[i].name} and {cams[j].name}: degenerate wand motion")
    E = E[:3]
    inl = mask.ravel().astype(bool)
    ok, R, t, _ = cv2.recoverPose(E, p1[inl], p2[inl], np.eye(3))
    log.info("pair %s-%s: %d frames, essential matrix inliers %d/%d", cams[i].name, cams[j].name,
             len(both), inl.sum(), len(inl))
    if inl.sum() < 0.6 * len(inl):
        raise CalibrateError(f"pair {cams[i].name}-{cams[j].name}: inconsistent epipolar geometry")
    return R, t.ravel()


def _scale_and_world(cams: list[Camera], points: np.ndarray, up_from_cameras: bool = True) -> list[Camera]:
    """Provisional world frame: Z up from the cameras' mean up, origin under the centroid of
    ``points`` (N, 3) with the floor at their lowest height."""
    up = -np.mean([c.R[1] for c in cams], axis=0)
    up /= np.linalg.norm(up)
    x = cams[0].R[0] - (cams[0].R[0] @ up) * up
    x /= np.linalg.norm(x)
    y = np.cross(up, x)
    A = np.stack([x, y, up])
    P = points @ A.T
    b = -np.array([np.mean(P[:, 0]), np.mean(P[:, 1]), np.min(P[:, 2])])
    return transform_rig(cams, A, b)


def calibrate_wand(
    rig: CameraRig,
    uv: np.ndarray,
    offsets: np.ndarray,
    min_frames: int = 20,
    max_error_px: float = 3.0,
    max_tries: int = 4,
    max_frames: int = 3000,
    refine: tuple[str, ...] = REFINE_INTRINSICS,
) -> tuple[CameraRig, WandReport]:
    """Extrinsics of all cameras of ``rig`` from wand observations, refining the intrinsics
    ``refine`` (names of ``bundle.INTRINSIC_PARAMS``; ``()`` keeps them) around their input
    values with priors from ``rig.metadata`` (:func:`prior_sigma`).

    uv: (F, C, K, 2) raw pixels, unlabelled per view, NaN where not seen; offsets: (K,)
    metres of the markers along the wand (e.g. [0, 0.5]); at most ``max_frames`` frames seen
    by >= 2 cameras are used (evenly spread). Returns the calibrated rig in a
    provisional world frame (see module doc) and the report. Raises CalibrateError when the
    data cannot determine the answer.
    """
    cams0 = rig.cameras
    F, C, Kw, _ = uv.shape
    offsets = np.asarray(offsets, dtype=float)
    if refine and not any(STD_KEY + c.name in rig.metadata for c in cams0):
        log.info("no board-step uncertainties in the calibration file: intrinsics kept as given")
        refine = ()
    if C != len(cams0) or len(offsets) != Kw or Kw < 2:
        raise ValueError("uv must be (F, C, K, 2) with C cameras and K = len(offsets) >= 2")
    L = float(offsets[-1] - offsets[0])
    uv = np.array(uv, dtype=float)
    seen = np.all(np.isfinite(uv), axis=(2, 3))
    multi = np.flatnonzero(seen.sum(axis=1) >= 2)
    if len(multi) > max_frames:  # bound the adjustment's size: keep evenly spread frames
        keep = np.union1d(multi[np.linspace(0, len(multi) - 1, max_frames).round().astype(int)],
                          np.flatnonzero(seen.sum(axis=1) < 2))
        uv, seen = uv[keep], seen[keep]
        log.info("using %d of %d multi-view wand frames", max_frames, len(multi))
    for c in range(C):
        if not seen[:, c].any():
            raise CalibrateError(f"camera {cams0[c].name} never saw the wand ({Kw} markers)")
    if Kw >= 3:
        uv = _order_collinear(uv, offsets)
    xy = np.stack([normalized(cams0[c], uv[:, c]) for c in range(C)], axis=1)
    co = np.array([[np.sum(seen[:, a] & seen[:, b]) if a != b else 0 for b in range(C)] for a in range(C)])
    pairs = sorted(((co[a, b], a, b) for a in range(C) for b in range(a + 1, C)), reverse=True)
    if pairs[0][0] < min_frames:
        a, b = pairs[0][1:]
        raise CalibrateError(f"the best camera pair {cams0[a].name}-{cams0[b].name} shares only {pairs[0][0]} "
                             f"wand frames (need >= {min_frames}): wave the wand where several cameras see it")
    best = None
    errors = []
    for n, i, j in pairs[:max_tries]:
        if n < min_frames:
            break
        try:
            cams, uv_i, pts, rms = _initialise(cams0, uv, xy, seen, i, j, L, min_frames, max_error_px)
            cams, pts, rep = _adjust(cams, uv_i, pts, rms, offsets, i, max_error_px, refine,
                                     prior_covariance(rig, refine) if refine else None)
        except CalibrateError as exc:
            errors.append(str(exc))
            log.info("initialisation from %s-%s failed: %s", cams0[i].name, cams0[j].name, exc)
            continue
        r = rep["residuals"]
        total = float(np.sqrt(np.mean(np.sum(r * r, axis=1)))) if len(r) else np.inf
        nobs = len(r)
        log.info("initialisation from %s-%s: rms %.3f px over %d observations", cams0[i].name, cams0[j].name,
                 total, nobs)
        key = (total > max_error_px / 3, -nobs, total)
        if best is None or key < best[0]:
            best = (key, cams, pts, rep, uv_i)
        if total < max_error_px / 3 and nobs >= 0.8 * int(np.sum(seen)) * Kw:
            break
    if best is None or best[0][0]:
        raise CalibrateError("no consistent calibration: " + ("; ".join(errors) or "reprojection errors stay large"))
    _, cams, pts, rep, uv = best
    cams = _scale_and_world(cams, pts[np.all(np.isfinite(pts), axis=2)].reshape(-1, 3))
    out = CameraRig(cams, dict(rig.metadata))
    report = _report(out, uv, offsets, rep)
    try:
        report.uncertainty = rig_uncertainty(rep["result"])
    except (np.linalg.LinAlgError, ValueError) as exc:  # singular: report without it
        log.warning("no uncertainty: the adjustment's covariance is singular (%s)", exc)
    if refine:
        for c0, c1 in zip(cams0, cams):
            dk = c1.matrix - c0.matrix
            dd = c1.dist[:2] - c0.dist[:2]
            report.intrinsics_change[c0.name] = (f"fx {dk[0, 0]:+.2f} px, cx {dk[0, 2]:+.2f} px, cy {dk[1, 2]:+.2f} px, "
                                                 f"k1 {dd[0]:+.4f}, k2 {dd[1]:+.4f}")
    return out, report


def _initialise(cams0, uv, xy, seen, i, j, L, min_frames, max_error_px):
    """Poses of all cameras from pair (i, j) then PnP; returns cams, labelled uv, points, rms."""
    C = len(cams0)
    Kw = uv.shape[2]
    R, t = _initial_pair(cams0, xy, seen, int(i), int(j), min_frames)
    posed: list[Camera | None] = [None] * C
    posed[i] = camera_from_pose(cams0[i], np.eye(3), np.zeros(3))
    posed[j] = camera_from_pose(cams0[j], R, t)
    uv, pts, rms = _resolve(posed, uv)
    good = np.isfinite(rms) & (rms < 5 * max_error_px)
    if good.sum() < min_frames:
        raise CalibrateError(f"pair {cams0[i].name}-{cams0[j].name}: only {int(good.sum())} frames fit the initial geometry")
    lengths = np.linalg.norm(pts[good, -1] - pts[good, 0], axis=1)
    s = L / np.median(lengths)
    posed[j] = camera_from_pose(cams0[j], R, t * s)
    while any(p is None for p in posed):
        uv, pts, rms = _resolve(posed, uv)
        have = np.isfinite(rms) & (rms < 5 * max_error_px)
        cand = [(int(np.sum(have & seen[:, c])), c) for c in range(C) if posed[c] is None]
        n, c = max(cand)
        if n < max(min_frames // 2, 6):
            names = [cams0[k].name for k in range(C) if posed[k] is None]
            raise CalibrateError(f"camera(s) {names} share too few wand frames ({n}) with the calibrated cameras")
        fr = np.flatnonzero(have & seen[:, c])
        obj = np.concatenate([pts[fr].reshape(-1, 3), pts[fr].reshape(-1, 3)])
        img = np.concatenate([xy[fr, c].reshape(-1, 2), xy[fr, c][:, ::-1].reshape(-1, 2)])
        f = cams0[c].matrix[0, 0]
        ok, rv, tv, inl = cv2.solvePnPRansac(obj, img, np.eye(3), None, iterationsCount=2000,
                                             reprojectionError=2.0 / f, confidence=0.9999, flags=cv2.SOLVEPNP_EPNP)
        if not ok or inl is None or len(inl) < 0.6 * n * Kw:
            raise CalibrateError(f"camera {cams0[c].name}: no consistent pose from {n} shared wand frames "
                                 f"({0 if inl is None else len(inl)} inliers)")
        inl = inl.ravel()
        ok, rv, tv = cv2.solvePnP(obj[inl], img[inl], np.eye(3), None, rv, tv, True, cv2.SOLVEPNP_ITERATIVE)
        posed[c] = Camera(cams0[c].name, cams0[c].size, cams0[c].matrix.copy(), cams0[c].dist.copy(),
                          rv.ravel(), tv.ravel())
        log.info("camera %s: PnP from %d frames, %d/%d inliers", cams0[c].name, n, len(inl), len(obj))
    cams = [p for p in posed if p is not None]
    uv, pts, rms = _resolve(cams, uv)
    return cams, uv, pts, rms


def _adjust(cams, uv, pts, rms, offsets, ref, max_error_px, refine=(), prior_cov=None):
    """Bundle adjustment with the rigid wand; a second pass without outlier observations
    (always made when intrinsics are refined: the priors are then weighed with the pixel
    noise measured in the first pass). The intrinsics' priors stay centred on the input."""
    F, C, Kw, _ = uv.shape
    use = np.isfinite(rms) & (rms < 5 * max_error_px)
    cams_in = cams
    sigma_px = 0.3
    for it in range(2):
        fr = np.flatnonzero(use)
        vis = np.all(np.isfinite(uv[fr]), axis=-1)  # (n, C, K)
        fi, ci, ki = np.nonzero(vis)
        obs = Observations(ci, fi * Kw + ki, uv[fr][fi, ci, ki])
        if refine and it == 1:  # restart the intrinsics at their input values (prior centre)
            cams = [Camera(c.name, c.size, c0.matrix.copy(), c0.dist.copy(), c.rvec, c.tvec)
                    for c, c0 in zip(cams, cams_in)]
        res = bundle_adjust(cams, obs, pts[fr].reshape(-1, 3), wand_offsets=offsets, fixed=(ref,),
                            f_scale=1.0 if it == 0 else max_error_px, intrinsics=tuple(refine),
                            prior_cov=prior_cov, sigma_px=sigma_px)
        cams = res.cameras
        pts = np.full((F, Kw, 3), np.nan)
        pts[fr] = res.points.reshape(-1, Kw, 3)
        err = np.linalg.norm(res.residuals, axis=1)
        bad = err > max_error_px
        if it == 0 and bad.any():
            # drop whole views with an outlier marker (mislabelled or merged) and re-run
            for f_, c_ in set(zip(fr[fi[bad]], ci[bad])):
                uv[f_, c_] = np.nan
            cnt = np.sum(np.all(np.isfinite(uv), axis=(2, 3)), axis=1)
            use &= cnt >= 2
            log.info("dropped %d outlier observations (> %.1f px)", int(bad.sum()), max_error_px)
        elif not (it == 0 and refine):
            break
        if it == 0 and refine:
            good = res.residuals[~bad]
            if len(good):
                sigma_px = max(float(np.sqrt(np.mean(good * good))), 0.02)
    rep = {"obs": obs, "residuals": res.residuals, "frames": fr, "result": res}
    return cams, pts, rep


def _coverage(points: np.ndarray, cell: float = 0.5, half: float = 2.0, height: float = 2.0) -> float:
    """Fraction of cells of the [-half, half]^2 x [0, height] volume holding a point (N, 3)."""
    nx, nz = int(round(2 * half / cell)), int(round(height / cell))
    idx = np.floor((points + [half, half, 0.0]) / cell).astype(int)
    ok = np.all((idx >= 0) & (idx < [nx, nx, nz]), axis=1)
    cells = {tuple(r) for r in idx[ok]}
    return len(cells) / (nx * nx * nz)


def _report(rig: CameraRig, uv: np.ndarray, offsets: np.ndarray, rep: dict) -> WandReport:
    obs, r = rep["obs"], rep["residuals"]
    names = rig.names
    e2 = np.sum(r * r, axis=1)
    rms = {n: float(np.sqrt(np.mean(e2[obs.cam == c]))) if np.any(obs.cam == c) else float("nan")
           for c, n in enumerate(names)}
    nobs = {n: int(np.sum(obs.cam == c)) for c, n in enumerate(names)}
    F, C, Kw, _ = uv.shape
    fr = rep["frames"]
    res = Triangulator(rig, TriangulateConfig(max_error_px=1e9, iterations=3)).triangulate(
        uv[fr].transpose(1, 0, 2, 3).reshape(C, -1, 2))
    P = res.points.reshape(len(fr), Kw, 3)
    mean_l, sigma_l, _ = wand_length_stats(np.linalg.norm(P[:, -1] - P[:, 0], axis=1))
    seen = np.all(np.isfinite(uv[fr]), axis=(2, 3))
    cov, pairs = {}, {}
    for a, b in itertools.combinations(range(C), 2):
        both = seen[:, a] & seen[:, b]
        key = f"{names[a]}-{names[b]}"
        pairs[key] = int(both.sum())
        pts = P[both].reshape(-1, 3)
        cov[key] = _coverage(pts[np.all(np.isfinite(pts), axis=1)])
    return WandReport(rms, nobs, mean_l, sigma_l, len(fr), cov, pairs)


def wand_length_stats(lengths: np.ndarray, k: float = 5.0) -> tuple[float, float, int]:
    """Mean and standard deviation (m) of free-triangulated wand lengths (N,) m (NaN ignored)
    over the positions within ``k`` robust sigmas (1.4826 x median absolute deviation) of the
    median, and the number left out. A wand seen by only two cameras facing each other is
    triangulated from nearly parallel rays (lengths off by decimetres) though the adjustment,
    which knows the wand is rigid, uses it well; such positions must not swamp the spread."""
    x = np.asarray(lengths, dtype=float)
    x = x[np.isfinite(x)]
    if not len(x):
        return float("nan"), float("nan"), 0
    med = float(np.median(x))
    mad = 1.4826 * float(np.median(np.abs(x - med)))
    keep = np.abs(x - med) <= k * mad if mad > 0 else np.ones(len(x), bool)
    return float(np.mean(x[keep])), float(np.std(x[keep])), int(len(x) - keep.sum())


__all__ = ["COV_KEY", "CalibrateError", "REFINE_INTRINSICS", "STD_KEY", "WandReport", "calibrate_wand", "default_prior_sigma",
           "normalized", "prior_covariance", "prior_sigma", "wand_length_stats"]
