"""Make a complete simulated take on disk: videos, ground truth and calibration.

Output directory layout (FORMATS.md)::

    cam0.avi, cam1.avi, ...   one per camera at SimConfig.fps: FFV1 8-bit grey (lossless, default),
                               MJPG (yuvj420p, lossy, as USB cameras send) or H.264 / MPEG-4
                               (cam0.mp4 ... if the AVI container refuses it)
    calibration.toml           the rig used
    joints.npz                 ground-truth 13 joints (F, 13, 3) m and t (F,) s
    markers.npz                ground-truth 8 markers (the marker joints, or the skin landmarks with
                               offsets), same frames, marker_placement ("joint_centres" / "skin")
    truth2d.npz                per camera: uv (C, F, 8, 2) px, visible (C, F, 8), radius (C, F, 8),
                               camera_names (C,), n_tpose (frames of lead-in: T-pose + blend),
                               fps, blackout (F,) bool, stance (m), codec, fourcc, videos (C,)
"""

from __future__ import annotations

import contextlib
import logging
import os
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from samba_common.calib import CameraRig, default_rig
from samba_common.formats import load_joints, save_joints, save_markers
from samba_common.markerset import markers_from_joints, soft_tissue
from samba_common.skeleton import J, MARKER_JOINT

from .motion import synthetic_motion
from .render import RenderedCamera, SimConfig, blackout_frames, render_take
from .tpose import heading, prepend_tpose, stance_offset

#: video codecs of make_take / samba-sim --codec
CODECS = ("ffv1", "mjpg", "h264")
# (fourcc, file suffix, colour) to try in order; the first that opens is used for every camera
_CODEC_TRIES: dict[str, list[tuple[str, str, bool]]] = {
    "ffv1": [("FFV1", ".avi", False)],
    "mjpg": [("MJPG", ".avi", True)],  # from BGR frames: yuvj420p, like a USB camera's stream
    "h264": [(fcc, ext, True) for fcc in ("avc1", "H264", "X264") for ext in (".avi", ".mp4")]
    + [("mp4v", ".avi", True), ("mp4v", ".mp4", True)],  # MPEG-4 part 2 if there is no H.264 encoder
}

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
    blackout: np.ndarray | None = None  #: (F,) bool, frames in a SimConfig.blackout window
    stance: float = 0.0  #: m each ankle stood outside its hip in the T-pose
    fourcc: str = ""  #: fourcc of the written videos ("" when nothing was written)
    videos: list[Path] = field(default_factory=list)  #: the written video files, camera order
    notes: list[str] = field(default_factory=list)  #: warnings (e.g. the clip was shorter than asked)

    def video(self, name: str) -> Path:
        for p in self.videos:
            if p.stem == name:
                return p
        return self.out_dir / f"{name}.avi"


def load_motion(source: str | os.PathLike, start: float = 0.0, seconds: float | None = None,
                notes: list[str] | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """(joints (F, 13, 3) m, t (F,) s, fps) from a .bvh file or a joints.npz, cut to [start, start+seconds).

    If the clip ends before start + seconds, all of it is used and a note is appended to
    ``notes`` (when given)."""
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
        span = f"in [{start:g}, {start + seconds:g}) s" if seconds is not None else f"from {start:g} s"
        raise ValueError(f"{p}: no frames {span} (take is {t[-1]:.2f} s)")
    length = float(t[-1]) + 1.0 / fps  # the clip's duration (the last frame lasts 1/fps)
    if seconds is not None and notes is not None and start + seconds > length + 0.5 / fps:
        if start > 0:
            notes.append(f"clip is only {length:.2f} s; rendered all of it from {start:g} s "
                         f"({length - start:.2f} s)")
        else:
            notes.append(f"clip is only {length:.2f} s; rendered all of it")
    return joints[keep], t[keep] - t[keep][0], fps


def prepare_motion(joints: np.ndarray, t: np.ndarray, cfg: SimConfig, center: bool = True,
                   face_forward: bool = True) -> tuple[np.ndarray, np.ndarray, int]:
    """Resample to cfg.fps, optionally turn the take so its first frame faces +Y (like the
    T-pose, so the lead-in needs no turn) and centre it horizontally on the origin, then
    prepend the T-pose (at cfg.pose_at, with cfg.tpose_stance) and the walk into the take.

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
    return prepend_tpose(joints, t, cfg.fps, cfg.tpose_hold, cfg.tpose_transition, cfg.tpose_stance,
                         pose_at=cfg.pose_at)


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence file descriptor 2 (FFmpeg's complaints while probing encoders)."""
    try:
        fd = os.dup(2)
    except OSError:
        yield
        return
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield
            finally:
                os.dup2(fd, 2)
    finally:
        os.close(fd)


def _open_writer(out_dir: Path, name: str, codec: str, fps: float, size: tuple[int, int],
                 tries: list[tuple[str, str, bool]] | None = None):
    """(writer, path, fourcc, colour) for the first of ``codec``'s candidates this OpenCV can write."""
    import cv2

    tries = tries or _CODEC_TRIES.get(codec.lower())
    if tries is None:
        raise ValueError(f"unknown codec {codec!r} (use {'|'.join(CODECS)})")
    quiet = _quiet_stderr() if len(tries) > 1 else contextlib.nullcontext()
    with quiet:
        for fourcc, suffix, colour in tries:
            path = out_dir / f"{name}{suffix}"
            writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, size, isColor=colour)
            if writer.isOpened():
                return writer, path, fourcc, colour
            writer.release()
            if path.exists() and path.stat().st_size == 0:
                path.unlink()
    names = "/".join(dict.fromkeys(f for f, _, _ in tries))
    raise OSError(f"cannot write {codec} video: this OpenCV build has no encoder for it (tried {names})")


def write_video_files(out_dir: Path, cameras: list[RenderedCamera], fps: float,
                      codec: str = "ffv1") -> tuple[list[Path], str]:
    """Write one video per camera (camN.avi; camN.mp4 if the codec needs it) with ``codec``
    (CODECS); returns (paths, fourcc written). Lossy files are checked to decode."""
    import cv2

    paths: list[Path] = []
    fourcc = ""
    chosen = None  # the candidate that worked for the first camera
    for cam in cameras:
        h, w = cam.frames.shape[1:]
        writer, path, fourcc, colour = _open_writer(out_dir, cam.name, codec, fps, (w, h), chosen)
        chosen = [(fourcc, path.suffix, colour)]
        for frame in cam.frames:
            writer.write(cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR) if colour else frame)
        writer.release()
        for other in (".avi", ".mp4"):  # a stale file of an earlier take would confuse readers
            stale = out_dir / f"{cam.name}{other}"
            if other != path.suffix and stale.exists():
                stale.unlink()
        if codec.lower() != "ffv1":
            cap = cv2.VideoCapture(str(path))
            ok = cap.isOpened() and cap.read()[0]
            cap.release()
            if not ok:
                raise OSError(f"{path}: written with {fourcc} but does not decode")
        paths.append(path)
    return paths, fourcc


def write_videos(out_dir: Path, cameras: list[RenderedCamera], fps: float, fourcc: str = "FFV1") -> list[Path]:
    """Write one grey AVI per camera with ``fourcc``; returns the paths (see write_video_files)."""
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


def _blackout_notes(t: np.ndarray, cfg: SimConfig) -> list[str]:
    """Warnings for ``cfg.blackout`` windows (start, seconds) that miss the take's frame times
    t (F,) s, wholly or in part: a blackout asked for and not rendered must not pass silently."""
    notes: list[str] = []
    if not len(t):
        return notes
    lo, end = float(t[0]), float(t[-1]) + 1.0 / cfg.fps  # the last frame lasts one period
    for start, seconds in cfg.blackout:
        hit = int(blackout_frames(t, replace(cfg, blackout=((start, seconds),))).sum())
        if hit == 0:
            notes.append(f"blackout {start:g}+{seconds:g} s lies outside the take ({lo:g}-{end:.2f} s): "
                         "no frame blacked out")
        elif start + seconds > end + 1e-9 or start < lo - 1e-9:
            notes.append(f"blackout {start:g}+{seconds:g} s runs past the take ({lo:g}-{end:.2f} s): "
                         f"{hit / cfg.fps:.2f} s blacked out")
    return notes


def make_take(out_dir: str | os.PathLike, source: str | os.PathLike | np.ndarray | None = None,
              rig: CameraRig | int = 2, config: SimConfig | None = None, seed: int = 0,
              start: float = 0.0, seconds: float | None = None, t: np.ndarray | None = None,
              center: bool = True, face_forward: bool = True, write: bool = True,
              on_warning: Callable[[str], None] | None = None, offsets: np.ndarray | None = None,
              wobble: float = 0.0) -> SimTake:
    """Simulate a take into ``out_dir`` and return it.

    source: a .bvh or joints.npz path, a (F, 13, 3) joints array (with ``t``), or None for
    the built-in synthetic motion (``seconds`` long, default 3 s). rig: a CameraRig or 2/4 for
    ``default_rig``. write=False keeps everything in memory (no files). Warnings (a clip
    shorter than ``seconds``) go to ``on_warning`` (default: this module's logger) and
    ``SimTake.notes``. Lead-in, stance, blackout and codec: ``config`` (SimConfig).
    offsets: (8, 3) skin-marker offsets (samba_common.markerset; None = markers on the joint
    centres); wobble: soft-tissue wobble sigma (m) of skin markers. Skin markers are rendered and
    written to markers.npz (with ``marker_placement`` and the true ``marker_offsets``);
    joints.npz keeps the joint centres.
    """
    cfg = config or SimConfig()
    if cfg.codec.lower() not in CODECS:
        raise ValueError(f"unknown codec {cfg.codec!r} (use {'|'.join(CODECS)})")
    for window in cfg.blackout:
        if len(window) != 2 or not window[1] > 0:
            raise ValueError(f"blackout window {window!r}: expected (start s, seconds > 0)")
    if isinstance(rig, int):
        rig = default_rig(rig)
    notes: list[str] = []
    if source is None:
        joints, tt = synthetic_motion(seconds or 3.0, cfg.fps)
    elif isinstance(source, np.ndarray):
        if t is None:
            raise ValueError("pass t (F,) seconds with a joints array")
        joints, tt = source, np.asarray(t, float)
    else:
        joints, tt, _fps = load_motion(source, start, seconds, notes=notes)
    for note in notes:
        (on_warning or log.warning)(note)
    joints, tt, n_pre = prepare_motion(joints, tt, cfg, center=center, face_forward=face_forward)
    first = joints[n_pre]  # the clip's first frame: its hip width sets "together"
    stance = stance_offset(cfg.tpose_stance, float(np.linalg.norm(first[J["left_hip"]] - first[J["right_hip"]])))
    markers = joints[:, list(MARKER_JOINT)]
    shown = joints
    if offsets is not None:
        markers = markers_from_joints(joints, offsets)
        if wobble > 0:
            markers = soft_tissue(markers, np.random.default_rng(seed + 7919), wobble, fps=cfg.fps)
        shown = joints.copy()
        shown[:, list(MARKER_JOINT)] = markers  # the cameras see the landmarks
    cams = render_take(shown, tt, rig, cfg, seed=seed)
    dark = blackout_frames(tt, cfg)
    for note in _blackout_notes(tt, cfg):
        notes.append(note)
        (on_warning or log.warning)(note)
    out = Path(out_dir)
    videos: list[Path] = []
    fourcc = ""
    if write:
        out.mkdir(parents=True, exist_ok=True)
        videos, fourcc = write_video_files(out, cams, cfg.fps, cfg.codec)
        if cfg.codec.lower() == "h264" and fourcc == "mp4v":
            notes.append("no H.264 encoder in this OpenCV build; wrote MPEG-4 part 2 (mp4v) instead")
            (on_warning or log.warning)(notes[-1])
        rig.save(out / "calibration.toml")
        save_joints(out / "joints.npz", joints, tt)
        if offsets is None:
            save_markers(out / "markers.npz", markers, tt, marker_placement=np.array("joint_centres"))
        else:
            save_markers(out / "markers.npz", markers, tt, marker_placement=np.array("skin"),
                         marker_offsets=np.asarray(offsets, float), wobble=np.float64(wobble))
        np.savez_compressed(out / "truth2d.npz", uv=np.stack([c.uv for c in cams]),
                            visible=np.stack([c.visible for c in cams]),
                            radius=np.stack([c.radius for c in cams]),
                            camera_names=np.array([c.name for c in cams]), n_tpose=np.int64(n_pre),
                            fps=np.float64(cfg.fps), blackout=dark, stance=np.float64(stance),
                            codec=np.array(cfg.codec.lower()), fourcc=np.array(fourcc),
                            videos=np.array([v.name for v in videos]))
        log.info("wrote %d frames x %d cameras to %s", len(tt), len(cams), out)
    return SimTake(out, joints, tt, rig, cams, n_pre, blackout=dark, stance=stance, fourcc=fourcc,
                   videos=videos, notes=notes)
