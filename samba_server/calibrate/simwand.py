"""Simulated calibration takes with ground truth: a waved wand and a static L-frame.

2D observations come straight from the rig projection plus Gaussian pixel noise (no
rendering), unlabelled per view like the motes' unlabelled mode: each view lists its blobs
in random order, and a view that does not see all markers of the object is NaN.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba_common.calib import CameraRig

#: default L-frame: corner marker at the origin, long arm (+Y) 0.40 m, short arm (+X) 0.30 m
LFRAME_ARMS = (0.30, 0.40)


@dataclass
class SimObservations:
    """uv: (F, C, K, 2) raw pixels, per view in random order, NaN = view missed a marker;
    points: (F, K, 3) true marker positions (world m); t: (F,) seconds."""

    uv: np.ndarray
    points: np.ndarray
    t: np.ndarray


def observe(rig: CameraRig, points: np.ndarray, noise_px: float, rng: np.random.Generator,
            shuffle: bool = True, margin: float = 1.0) -> np.ndarray:
    """Project points (F, K, 3) into every camera -> (F, C, K, 2) with noise; views in which a
    marker is behind the camera or outside the image are NaN as a whole."""
    F, Kw, _ = points.shape
    uv = rig.project(points.reshape(-1, 3)).reshape(len(rig), F, Kw, 2).transpose(1, 0, 2, 3).copy()
    uv += rng.normal(0.0, noise_px, uv.shape)
    for c, cam in enumerate(rig.cameras):
        inside = cam.in_image(uv[:, c].reshape(-1, 2), margin).reshape(F, Kw)
        uv[~inside.all(axis=1), c] = np.nan
    if shuffle:
        order = np.argsort(rng.random((F, len(rig), Kw)), axis=2)
        uv = np.take_along_axis(uv, order[..., None], axis=2)
    return uv


def wand_motion(n_frames: int, offsets: np.ndarray, rng: np.random.Generator, fps: float = 60.0,
                half: float = 2.0, z_range: tuple[float, float] = (0.1, 2.2)) -> tuple[np.ndarray, np.ndarray]:
    """A wand waved through the whole volume, as the docs ask of a user: points (F, K, 3)
    world m, t (F,) s.

    The wand's centre walks the floor area [-half, half]^2 in a Lissajous pattern (x and y
    each cross the whole width 2.5-5.5 times over the take, so every part of the area is
    visited, up to its edges) while the arm sweeps it from ``z_range[0]`` to ``z_range[1]``
    every 3-7 s; the wand tumbles smoothly. Positions spread to the edges matter: the
    positions near and far from a camera are what separate its focal length from its
    distance (an average of sinusoids, used before, kept 2/3 of the positions within 0.6 m
    of the centre and left the centres 2x less certain)."""
    offsets = np.asarray(offsets, dtype=float)
    t = np.arange(n_frames) / fps
    T = max(n_frames / fps, 1e-9)
    lo = np.array([-half, -half, z_range[0]])
    hi = np.array([half, half, z_range[1]])
    # one sinusoid per axis (arcsine density: the edges are visited as much as the middle);
    # x, y: a few crossings per take at different rates; z: the arm, every few seconds
    freqs = np.array([rng.uniform(1.25, 2.0) / T, rng.uniform(2.0, 2.75) / T, rng.uniform(0.15, 0.33)])
    phases = rng.uniform(0, 2 * np.pi, 3)
    s = np.sin(2 * np.pi * freqs[None] * t[:, None] + phases[None])  # (F, 3) in [-1, 1]
    centre = lo + (hi - lo) * (0.5 + 0.5 * s)
    # direction: smoothly tumbling
    wf = rng.uniform(0.2, 0.8, 3)
    wp = rng.uniform(0, 2 * np.pi, 3)
    d = np.stack([np.sin(2 * np.pi * wf[0] * t + wp[0]), np.cos(2 * np.pi * wf[1] * t + wp[1]),
                  0.8 * np.sin(2 * np.pi * wf[2] * t + wp[2])], axis=1)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    mid = 0.5 * (offsets[0] + offsets[-1])
    pts = centre[:, None, :] + (offsets - mid)[None, :, None] * d[:, None, :]
    return pts, t


def simulate_wand(rig: CameraRig, n_frames: int = 600, length: float = 0.5, mid: float | None = None,
                  noise_px: float = 0.2, seed: int = 0, fps: float = 60.0) -> SimObservations:
    """A wand take seen by ``rig``: 2 markers ``length`` apart (a third at ``mid`` if given)."""
    rng = np.random.default_rng(seed)
    offsets = np.array([0.0, length] if mid is None else [0.0, mid, length])
    pts, t = wand_motion(n_frames, offsets, rng, fps)
    return SimObservations(observe(rig, pts, noise_px, rng), pts, t)


def lframe_points(arms: tuple[float, float] = LFRAME_ARMS, height: float = 0.0) -> np.ndarray:
    """L-frame markers (3, 3) world m: corner at the origin, short arm +X, long arm +Y."""
    sx, ly = arms
    return np.array([[0.0, 0.0, height], [sx, 0.0, height], [0.0, ly, height]])


def simulate_lframe(rig: CameraRig, n_frames: int = 30, noise_px: float = 0.2, seed: int = 0,
                    arms: tuple[float, float] = LFRAME_ARMS, height: float = 0.0, fps: float = 60.0) -> SimObservations:
    """A static L-frame lying on the floor at the origin, seen for ``n_frames`` frames."""
    rng = np.random.default_rng(seed)
    pts = np.repeat(lframe_points(arms, height)[None], n_frames, axis=0)
    return SimObservations(observe(rig, pts, noise_px, rng), pts, np.arange(n_frames) / fps)


def save_observations(path: str | os.PathLike, obs: SimObservations, names: list[str], kind: str,
                      offsets: np.ndarray | None = None) -> None:
    """Write a simulated take as ``.npz``: uv (F, C, K, 2), camera_names, t, and the ground
    truth points (F, K, 3); ``kind`` is "wand" or "lframe"."""
    extra = {} if offsets is None else {"offsets": np.asarray(offsets, float)}
    np.savez_compressed(Path(path), uv=obs.uv, t=obs.t, points=obs.points,
                        camera_names=np.array(names), kind=np.array(kind), **extra)


def simulate_subject(rig: CameraRig, seconds: float = 8.0, noise_px: float = 0.2, seed: int = 0,
                     fps: float = 60.0) -> SimObservations:
    """A labelled take for self-calibration: 1 s of the standard pose, then the mote
    simulator's procedural motion; uv (F, C, 8, 2) in MARKER_NAMES order, per-marker NaN
    outside the image; points (F, 8, 3) true markers."""
    from samba_common.body import prepend_standard_pose
    from samba_common.skeleton import MARKER_JOINT
    from samba_mote.sim.motion import synthetic_motion

    rng = np.random.default_rng(seed)
    joints, _ = synthetic_motion(seconds, fps)
    joints = prepend_standard_pose(joints, fps)
    pts = joints[:, list(MARKER_JOINT)]
    F = len(pts)
    uv = rig.project(pts.reshape(-1, 3)).reshape(len(rig), F, 8, 2).transpose(1, 0, 2, 3).copy()
    uv += rng.normal(0.0, noise_px, uv.shape)
    for c, cam in enumerate(rig.cameras):
        uv[:, c][~cam.in_image(uv[:, c].reshape(-1, 2), 1.0).reshape(F, 8)] = np.nan
    return SimObservations(uv, pts, np.arange(F) / fps)


def write_videos(out_dir: str | os.PathLike, rig: CameraRig, obs: SimObservations, fps: float,
                 seed: int = 0, fourcc: str = "FFV1") -> list[Path]:
    """Render the markers of ``obs`` as glowing disks into ``cam0.avi`` ... with the mote
    simulator's renderer (:mod:`samba_mote.sim.render`, no distractors)."""
    import cv2

    from samba_mote.sim.render import SimConfig, render_frame

    cfg = SimConfig(fps=fps, n_distractors=0, hot_pixels=0, occlusion=False)
    rng = np.random.default_rng(seed)
    paths = []
    F, K = obs.points.shape[:2]
    for cam in rig.cameras:
        X = obs.points.reshape(-1, 3)
        uv = cam.project(X).reshape(F, K, 2)
        depth = cam.to_camera(X)[:, 2].reshape(F, K)
        radius = cam.matrix[0, 0] * cfg.marker_radius_m / np.maximum(depth, 0.1)
        vis = (depth > 0.1) & cam.in_image(uv.reshape(-1, 2)).reshape(F, K)
        path = Path(out_dir) / f"{cam.name}.avi"
        w, h = cam.size
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h), isColor=False)
        if not writer.isOpened():
            raise OSError(f"cannot write {path} with codec {fourcc}")
        try:
            for f in range(F):
                writer.write(render_frame(cam.size, uv[f], radius[f], vis[f], None, cfg, rng))
        finally:
            writer.release()
        paths.append(path)
    return paths


def simulate_board_step(rig: CameraRig, views: int, seed: int = 0,
                        board: str = "checkerboard:7x5:0.03") -> CameraRig:
    """Intrinsics as a user gets them before the wand: ``views`` rendered images of the board
    per camera of ``rig`` through the board step (as ``samba-calibrate simulate board`` +
    ``intrinsics``), with its uncertainties in the metadata as the wand step's priors. The
    returned cameras have no pose."""
    from .intrinsics import Board, calibrate_frames, render_board_views
    from .wand import board_priors

    b = Board.parse(board)
    cams, meta = [], {}
    for i, c in enumerate(rig.cameras):
        res = calibrate_frames(c.name, render_board_views(c, b, views, seed=seed + i), b)
        cams.append(res.camera)
        meta.update(board_priors(c.name, res.std, res.cov))
    return CameraRig(cams, meta)


def pose_errors(est: CameraRig, true: CameraRig, mode: str = "aligned") -> tuple[np.ndarray, np.ndarray]:
    """Camera centre errors (C,) m and rotation errors (C,) deg of ``est`` against ``true``.

    mode "aligned" (default): after the rigid motion that best maps the estimated camera
    centres onto the true ones (least squares, no scale: the wand fixes the scale), i.e.
    without the arbitrary choice of world frame; needs >= 3 cameras (else "relative").
    "relative": each pose relative to the first camera (amplifies camera 0's rotation error
    by the distances). "absolute": in the world frames as they are (includes the floor)."""
    if mode == "aligned" and len(est) < 3:
        mode = "relative"
    ce, re = [], []
    A = np.eye(3)
    b = np.zeros(3)
    if mode == "aligned":
        P = np.stack([c.center for c in est.cameras])
        Q = np.stack([c.center for c in true.cameras])
        pc, qc = P.mean(axis=0), Q.mean(axis=0)
        U, _, Vt = np.linalg.svd((P - pc).T @ (Q - qc))
        D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
        A = Vt.T @ D @ U.T
        b = qc - A @ pc
    r0e, r0t = est.cameras[0], true.cameras[0]
    for a, t in zip(est.cameras, true.cameras):
        if mode == "relative":
            Ra, Rb = a.R @ r0e.R.T, t.R @ r0t.R.T
            ca, cb = r0e.R @ (a.center - r0e.center), r0t.R @ (t.center - r0t.center)
        else:
            Ra, Rb, ca, cb = a.R @ A.T, t.R, A @ a.center + b, t.center
        ce.append(np.linalg.norm(ca - cb))
        re.append(np.degrees(np.arccos(np.clip((np.trace(Ra @ Rb.T) - 1) / 2, -1, 1))))
    return np.array(ce), np.array(re)
