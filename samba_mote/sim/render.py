"""Render camera frames of the 8 markers: blurred anti-aliased disks, noise, distractors,
occlusion by the body.

Everything is a pure function of (joints, rig, SimConfig, seed): the same call gives the
same frames. Pixel convention (as the detector): origin at the centre of the top-left pixel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba_common.calib import Camera, CameraRig
from samba_common.skeleton import BONES, J, MARKER_JOINT, N_MARKERS


@dataclass(frozen=True)
class SimConfig:
    """Simulation settings (``[sim]`` in configs/mote.toml or samba-sim options)."""

    fps: float = 60.0
    marker_radius_m: float = 0.06  #: apparent radius of the glowing marker (px = fx * this / depth)
    blur: float = 0.45  #: edge softness of the disk (px)
    peak: float = 235.0  #: marker grey level at the centre
    background: float = 12.0  #: mean background grey level
    noise_sigma: float = 3.0  #: sensor noise (grey levels, Gaussian)
    n_distractors: int = 3  #: static distractors per camera (1 large lamp + small reflections)
    hot_pixels: int = 4  #: isolated hot pixels per camera (static)
    occlusion: bool = True  #: hide markers behind the body (capsules around the bones)
    limb_radius: float = 0.055  #: m, capsule radius of arms and legs
    torso_radius: float = 0.13  #: m, capsule radius of the torso
    tpose_hold: float = 1.0  #: s of T-pose prepended to each take
    tpose_transition: float = 0.6  #: s of blend from the T-pose into the take (at least; longer to walk there)
    #: m each ankle stands outside its hip in the T-pose, or "hip" (0.0: legs straight down,
    #: ankles at hip width), "apart" (0.12), "together" (feet touching; negative)
    tpose_stance: float | str = 0.0
    #: (x, y) m where the T-pose stands (the volume centre); the lead-in then walks (1 m/s) to
    #: where the take starts. None: stand where the take starts
    pose_at: tuple[float, float] | None = (0.0, 0.0)
    #: (start, seconds) windows of take time (from the first frame of the output, lead-in
    #: included) in which no marker is visible in any camera; noise and distractors still render
    blackout: tuple[tuple[float, float], ...] = ()
    codec: str = "ffv1"  #: video codec of make_take's files: ffv1 (lossless) | mjpg | h264


@dataclass
class Distractors:
    """Static image clutter of one camera. lamps: (K, 3) rows (u, v, radius px); hot: (H, 2) int (x, y)."""

    lamps: np.ndarray
    hot: np.ndarray


def make_distractors(size: tuple[int, int], cfg: SimConfig, rng: np.random.Generator) -> Distractors:
    """A large lamp near the top edge and small marker-like reflections near the image edges."""
    w, h = size
    rows = []
    for k in range(cfg.n_distractors):
        if k == 0:
            rows.append((rng.uniform(0.15, 0.85) * w, rng.uniform(0.03, 0.12) * h, 7.5 * w / 160))
        else:
            side = rng.integers(2)
            u = rng.uniform(0.02, 0.08) * w if side == 0 else rng.uniform(0.92, 0.98) * w
            rows.append((u, rng.uniform(0.05, 0.95) * h, rng.uniform(1.2, 2.0) * w / 160))
    hot = np.stack([rng.integers(0, w, cfg.hot_pixels), rng.integers(0, h, cfg.hot_pixels)], axis=1)
    return Distractors(np.asarray(rows, float).reshape(-1, 3), hot)


def _capsules(cfg: SimConfig) -> list[tuple[int | str, int | str, float]]:
    caps: list[tuple[int | str, int | str, float]] = [(a, b, cfg.limb_radius) for a, b in BONES
                                                      if (a, b) != (J["left_shoulder"], J["right_shoulder"])
                                                      and (a, b) != (J["left_hip"], J["right_hip"])]
    caps.append(("sm", "hm", cfg.torso_radius))
    caps.append(("sm", J["head"], 0.09))
    return caps


def _seg_seg_dist(p0, p1, q0, q1) -> np.ndarray:
    """Minimum distance between segments p0-p1 and q0-q1, all (..., 3) broadcast -> (...)."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a = (d1 * d1).sum(-1)
    e = (d2 * d2).sum(-1)
    f = (d2 * r).sum(-1)
    c = (d1 * r).sum(-1)
    b = (d1 * d2).sum(-1)
    denom = np.maximum(a * e - b * b, 1e-12)
    s = np.clip((b * f - c * e) / denom, 0.0, 1.0)
    tt = (b * s + f) / np.maximum(e, 1e-12)
    tt = np.clip(tt, 0.0, 1.0)
    s = np.clip((b * tt - c) / np.maximum(a, 1e-12), 0.0, 1.0)
    diff = (p0 + d1 * s[..., None]) - (q0 + d2 * tt[..., None])
    return np.sqrt((diff * diff).sum(-1))


def occluded(joints: np.ndarray, camera_center: np.ndarray, cfg: SimConfig) -> np.ndarray:
    """joints: (F, 13, 3) m -> (F, 8) bool: the marker is hidden from the camera by a body capsule
    that does not touch the marker's own joint (its own limb does not hide it)."""
    F = len(joints)
    sm = 0.5 * (joints[:, J["left_shoulder"]] + joints[:, J["right_shoulder"]])
    hm = 0.5 * (joints[:, J["left_hip"]] + joints[:, J["right_hip"]])

    def point(k):
        return sm if k == "sm" else hm if k == "hm" else joints[:, k]

    markers = joints[:, list(MARKER_JOINT)]  # (F, 8, 3)
    cam = np.broadcast_to(camera_center, markers.shape)
    # stop the ray a little before the marker so the surface it sits on does not hide it
    to_m = markers - cam
    dist = np.linalg.norm(to_m, axis=-1, keepdims=True)
    end = markers - to_m / np.maximum(dist, 1e-9) * 0.04
    hidden = np.zeros((F, N_MARKERS), bool)
    for a, b, rad in _capsules(cfg):
        pa, pb = point(a), point(b)
        d = _seg_seg_dist(cam, end, pa[:, None, :], pb[:, None, :])
        block = d < rad
        for m, jn in enumerate(MARKER_JOINT):
            own = jn in (a, b) or (a == "sm" and jn in (J["left_shoulder"], J["right_shoulder"]))
            if not own:
                hidden[:, m] |= block[:, m]
    return hidden


def project_markers(camera: Camera, joints: np.ndarray, cfg: SimConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """joints (F, 13, 3) -> uv (F, 8, 2) px (distorted, NaN behind camera), radius (F, 8) px,
    visible (F, 8) bool (in front, inside the image, not occluded)."""
    F = len(joints)
    markers = joints[:, list(MARKER_JOINT)].reshape(-1, 3)
    uv = camera.project(markers).reshape(F, N_MARKERS, 2)
    depth = camera.to_camera(markers)[:, 2].reshape(F, N_MARKERS)
    fx = float(camera.matrix[0, 0])
    radius = np.where(depth > 0.1, fx * cfg.marker_radius_m / np.maximum(depth, 0.1), np.nan)
    w, h = camera.size
    inside = (depth > 0.1) & (uv[..., 0] >= -0.5) & (uv[..., 0] <= w - 0.5) & (uv[..., 1] >= -0.5) & (uv[..., 1] <= h - 0.5)
    vis = inside.copy()
    if cfg.occlusion:
        vis &= ~occluded(joints, camera.center, cfg)
    return uv, radius, vis


def draw_disk(img: np.ndarray, u: float, v: float, radius: float, peak: float, blur: float) -> None:
    """Draw one soft anti-aliased disk into float image ``img`` (H, W) in place (max compositing)."""
    h, w = img.shape
    ext = radius + 4.0 * blur + 1.0
    x0, x1 = max(int(np.floor(u - ext)), 0), min(int(np.ceil(u + ext)) + 1, w)
    y0, y1 = max(int(np.floor(v - ext)), 0), min(int(np.ceil(v + ext)) + 1, h)
    if x0 >= x1 or y0 >= y1:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    r = np.hypot(xx - u, yy - v)
    val = peak / (1.0 + np.exp((r - radius) / max(blur * 0.6, 1e-3)))
    np.maximum(img[y0:y1, x0:x1], val, out=img[y0:y1, x0:x1])


def render_frame(size: tuple[int, int], uv: np.ndarray, radius: np.ndarray, visible: np.ndarray,
                 distractors: Distractors | None, cfg: SimConfig, rng: np.random.Generator) -> np.ndarray:
    """One (H, W) uint8 frame: uv (N, 2) px, radius (N,) px, visible (N,) bool."""
    w, h = size
    img = np.full((h, w), cfg.background, np.float32)
    if distractors is not None:
        for u, v, rad in distractors.lamps:
            draw_disk(img, u, v, rad, cfg.peak, cfg.blur)
    for (u, v), rad, ok in zip(uv, radius, visible):
        if ok:
            draw_disk(img, float(u), float(v), float(rad), cfg.peak, cfg.blur)
    if cfg.noise_sigma > 0:
        img += rng.normal(0.0, cfg.noise_sigma, img.shape).astype(np.float32)
    if distractors is not None and len(distractors.hot):
        img[distractors.hot[:, 1], distractors.hot[:, 0]] = 255.0
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@dataclass
class RenderedCamera:
    """Frames and 2D ground truth of one camera: frames (F, H, W) uint8; uv (F, 8, 2) px;
    radius (F, 8) px; visible (F, 8) bool."""

    name: str
    frames: np.ndarray
    uv: np.ndarray
    radius: np.ndarray
    visible: np.ndarray


def blackout_frames(t: np.ndarray, cfg: SimConfig) -> np.ndarray:
    """(F,) bool: frames at times t (s) inside one of ``cfg.blackout``'s (start, seconds) windows."""
    t = np.asarray(t, float)
    out = np.zeros(len(t), bool)
    for start, seconds in cfg.blackout:
        out |= (t >= start - 1e-9) & (t < start + seconds - 1e-9)
    return out


def render_camera(camera: Camera, joints: np.ndarray, cfg: SimConfig, seed: int = 0,
                  t: np.ndarray | None = None) -> RenderedCamera:
    """Render every frame of (F, 13, 3) joints for one camera. With the frame times ``t`` (F,) s,
    no marker is visible in ``cfg.blackout``."""
    rng = np.random.default_rng(seed)
    distractors = make_distractors(camera.size, cfg, rng)
    uv, radius, vis = project_markers(camera, joints, cfg)
    if t is not None and cfg.blackout:
        vis[blackout_frames(t, cfg)] = False
    w, h = camera.size
    frames = np.empty((len(joints), h, w), np.uint8)
    for f in range(len(joints)):
        frames[f] = render_frame(camera.size, uv[f], radius[f], vis[f], distractors, cfg, rng)
    return RenderedCamera(camera.name, frames, uv, radius, vis & ~in_glare(uv, radius, distractors.lamps))


def in_glare(uv: np.ndarray, radius: np.ndarray, lamps: np.ndarray, gap_px: float = 1.0) -> np.ndarray:
    """(F, 8) bool: markers drawn on or against a lamp, whose blob is the lamp's (no camera
    sees them: the truth calls them hidden). uv (F, 8, 2) px; radius (F, 8) px; lamps (K, 3)
    rows (u, v, radius px)."""
    out = np.zeros(uv.shape[:2], bool)
    for u, v, rad in lamps:
        d = np.hypot(uv[..., 0] - u, uv[..., 1] - v)
        out |= d <= rad + radius + gap_px
    return out


def render_take(joints: np.ndarray, t: np.ndarray, rig: CameraRig, config: SimConfig | None = None,
                seed: int = 0) -> list[RenderedCamera]:
    """Frames per camera of a take. joints: (F, 13, 3) world m at times t (F,) s.

    Frames are rendered exactly at the given times (resample beforehand for another rate);
    ``cfg.blackout`` windows are in these times.
    """
    cfg = config or SimConfig()
    if joints.ndim != 3 or joints.shape[1:] != (13, 3) or len(t) != len(joints):
        raise ValueError(f"expected joints (F, 13, 3) and t (F,), got {joints.shape} and {np.shape(t)}")
    return [render_camera(cam, joints, cfg, seed=seed * 1000 + i, t=t) for i, cam in enumerate(rig.cameras)]
