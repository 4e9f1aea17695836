"""Make a complete simulated take on disk: videos, ground truth and calibration.

Output directory layout (FORMATS.md)::

    cam0.avi, cam1.avi, ...   FFV1 8-bit grey, one per camera, at SimConfig.fps
    calibration.toml           the rig used
    joints.npz                 ground-truth 13 joints (F, 13, 3) m and t (F,) s
    markers.npz                ground-truth 8 markers (the marker joints), same frames
    truth2d.npz                per camera: uv (C, F, 8, 2) px, visible (C, F, 8), radius (C, F, 8),
                               camera_names (C,), n_tpose (frames of T-pose lead-in)
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba_common.calib import CameraRig, default_rig
from samba_common.formats import load_joints, save_joints, save_markers
from samba_common.skeleton import MARKER_JOINT

from .motion import synthetic_motion
from .render import RenderedCamera, SimConfig, render_take
from .tpose import heading, prepend_tpose

log = logging.getLogger(__name__)


@dataclass
class SimTake:
    """A simulated take: ``out_dir`` with its files, and the rendered cameras in memory."""

    out_dir: Path
    joints: np.ndarray  # (F, 13, 3) m
    t: np.ndarray  # (F,) s
    rig: CameraRig
    cameras: list[RenderedCamera]
    n_tpose: int

    def video(self, name: str) -> Path:
        return self.out_dir / f"{name}.avi"


def load_motion(source: str | os.PathLike, start: float = 0.0, seconds: float | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(joints (F, 13, 3) m, t (F,) s, fps) from a .bvh file or a joints.npz, cut to [start, start+seconds)."""
    p = Path(source)
    if p.suffix.lower() == ".bvh":
        from samba_common.bvh import load_bvh, put_on_floor

        take = load_bvh(p)
        joints, t, fps = put_on_floor(take.joints), take.t, take.fps
    else:
        jt = load_joints(p)
        joints, t = jt.joints, jt.t - jt.t[0]
        fps = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 60.0
    keep = (t >= start) & ((seconds is None) | (t < start + (seconds or 0.0)))
    if not keep.any():
        raise ValueError(f"{p}: no frames in [{start}, {start + (seconds or 0)}) s (take is {t[-1]:.2f} s)")
    return joints[keep], t[keep] - t[keep][0], fps


def prepare_motion(joints: np.ndarray, t: np.ndarray, cfg: SimConfig, center: bool = True,
                   face_forward: bool = True) -> tuple[np.ndarray, np.ndarray, int]:
    """Resample to cfg.fps, optionally turn the take so its first frame faces +Y (like the
    T-pose, so the lead-in needs no turn) and centre it horizontally on the origin, then
    prepend the T-pose.

    Returns (joints (F, 13, 3), t (F,) from 0, number of lead-in frames)."""
    from samba_common.bvh import resample

    good = np.isfinite(joints).all(axis=(1, 2))
    joints, t = joints[good], t[good]
    if len(joints) == 0:
        raise ValueError("motion has no complete frame")
    joints, t = resample(joints, t, cfg.fps)
    if face_forward:
        yaw = heading(joints[0])
        hip0 = joints[0, 7:9].mean(axis=0)
        c, s_ = np.cos(-yaw), np.sin(-yaw)
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        joints = (joints - hip0 * [1, 1, 0]) @ R.T + hip0 * [1, 1, 0]
    if center:
        hips = joints[:, 7:9].mean(axis=1)
        mid = 0.5 * (hips[:, :2].min(0) + hips[:, :2].max(0))
        joints = joints.copy()
        joints[..., :2] -= mid
    return prepend_tpose(joints, t, cfg.fps, cfg.tpose_hold, cfg.tpose_transition, cfg.tpose_stance)


def write_videos(out_dir: Path, cameras: list[RenderedCamera], fps: float, fourcc: str = "FFV1") -> list[Path]:
    """Write one grey AVI per camera; returns the paths."""
    import cv2

    paths = []
    for cam in cameras:
        h, w = cam.frames.shape[1:]
        path = out_dir / f"{cam.name}.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (w, h), isColor=False)
        if not writer.isOpened():
            raise OSError(f"cannot write {path} with codec {fourcc}")
        for frame in cam.frames:
            writer.write(frame)
        writer.release()
        paths.append(path)
    return paths


def make_take(out_dir: str | os.PathLike, source: str | os.PathLike | np.ndarray | None = None,
              rig: CameraRig | int = 2, config: SimConfig | None = None, seed: int = 0,
              start: float = 0.0, seconds: float | None = None, t: np.ndarray | None = None,
              center: bool = True, face_forward: bool = True, write: bool = True) -> SimTake:
    """Simulate a take into ``out_dir`` and return it.

    source: a .bvh or joints.npz path, a (F, 13, 3) joints array (with ``t``), or None for
    the built-in synthetic motion (``seconds`` long, default 3 s). rig: a CameraRig or 2/4 for
    ``default_rig``. write=False keeps everything in memory (no files).
    """
    cfg = config or SimConfig()
    if isinstance(rig, int):
        rig = default_rig(rig)
    if source is None:
        joints, tt = synthetic_motion(seconds or 3.0, cfg.fps)
    elif isinstance(source, np.ndarray):
        if t is None:
            raise ValueError("pass t (F,) seconds with a joints array")
        joints, tt = source, np.asarray(t, float)
    else:
        joints, tt, _fps = load_motion(source, start, seconds)
    joints, tt, n_pre = prepare_motion(joints, tt, cfg, center=center, face_forward=face_forward)
    cams = render_take(joints, tt, rig, cfg, seed=seed)
    out = Path(out_dir)
    if write:
        out.mkdir(parents=True, exist_ok=True)
        write_videos(out, cams, cfg.fps)
        rig.save(out / "calibration.toml")
        save_joints(out / "joints.npz", joints, tt)
        save_markers(out / "markers.npz", joints[:, list(MARKER_JOINT)], tt)
        np.savez_compressed(out / "truth2d.npz", uv=np.stack([c.uv for c in cams]),
                            visible=np.stack([c.visible for c in cams]),
                            radius=np.stack([c.radius for c in cams]),
                            camera_names=np.array([c.name for c in cams]), n_tpose=np.int64(n_pre),
                            fps=np.float64(cfg.fps))
        log.info("wrote %d frames x %d cameras to %s", len(tt), len(cams), out)
    return SimTake(out, joints, tt, rig, cams, n_pre)
