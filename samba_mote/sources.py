"""Frame sources behind one interface, chosen by a URL-like string.

=========================================================  =====================================
``v4l2:/dev/video0?width=160&height=120&fps=60&fourcc=GREY&exposure=10&gain=0``  camera (OpenCV V4L2)
``file:take/cam0.avi?fps=60&realtime=1&loop=0&start=T``    video file (any OpenCV codec)
``images:dir/%04d.png?fps=60``                             numbered image files
``sim:?clip=walk.bvh&cam=cam0&cameras=2&seed=0&seconds=10&realtime=1&loop=0``  simulator
=========================================================  =====================================

``read()`` returns ``(t_ns, frame)`` with ``frame`` a (H, W) uint8 grey image and ``t_ns`` the
capture time in integer ns since the Unix epoch, or ``None`` at the end of a finite source.
Clocks: V4L2 buffers carry a CLOCK_MONOTONIC timestamp (exposed by OpenCV as
``CAP_PROP_POS_MSEC``); it is mapped to wall time with the offset ``time_ns() -
monotonic_ns()`` measured at open (keep the board's wall clock disciplined by NTP/PTP/chrony).
When the driver gives no usable stamp, the time of the ``read()`` return is used. Files,
images and the simulator stamp frame k as ``start + k / fps`` where ``start`` is the wall
time at open (or ``start=T``, Unix seconds, for a file: frame 0 is stamped T and the source
waits until then, so several motes playing the files of one take stay in step), and with
``realtime=1`` they also pace frames at ``fps``. A video file, like the simulator, plays in real
time by default, as a camera would; ``realtime=0`` reads it as fast as possible (offline tools).
"""

from __future__ import annotations

import logging
import time
import urllib.parse
from pathlib import Path
from typing import Protocol

import numpy as np

log = logging.getLogger(__name__)


class SourceError(OSError):
    """A source cannot be opened or stopped delivering frames (e.g. camera unplugged)."""


class SourceGone(SourceError):
    """A source that will not come back by waiting (a missing or unreadable file): not retried."""


class Source(Protocol):
    size: tuple[int, int]  # (width, height)
    fps: float

    def read(self) -> tuple[int, np.ndarray] | None: ...

    def close(self) -> None: ...


def _grey(frame: np.ndarray) -> np.ndarray:
    if frame.ndim == 3:
        if frame.shape[2] == 1:
            return np.ascontiguousarray(frame[..., 0])
        import cv2

        return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    return frame


def _q(query: dict[str, list[str]], key: str, default, typ=str):
    if key not in query:
        return default
    try:
        return typ(query[key][-1])
    except ValueError:
        raise ValueError(f"source option {key}={query[key][-1]!r} is not a valid {typ.__name__}") from None


def _flag(v: str) -> bool:
    return v.lower() in ("1", "true", "yes", "on")


class _Paced:
    """Frame k stamped start + k/fps; optional real-time pacing (sleep, no busy wait)."""

    def __init__(self, fps: float, realtime: bool, start_s: float | None = None) -> None:
        self.fps, self.realtime = fps, realtime
        now_ns = time.time_ns()
        self.start_ns = now_ns if start_s is None else int(round(start_s * 1e9))
        # the monotonic instant of frame 0 (in the future when start= is ahead of now)
        self._mono0 = time.monotonic() + (self.start_ns - now_ns) / 1e9
        self.k = 0

    def stamp(self) -> int:
        if self.realtime:
            due = self._mono0 + self.k / self.fps
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        t = self.start_ns + int(round(self.k * 1e9 / self.fps))
        self.k += 1
        return t


class V4L2Source:
    """A V4L2 camera through OpenCV. Raises SourceError when it cannot open or read."""

    def __init__(self, device: str = "/dev/video0", width: int = 160, height: int = 120, fps: float = 60.0,
                 fourcc: str = "GREY", exposure: float | None = None, gain: float | None = None) -> None:
        import cv2

        self.device = device
        cap = cv2.VideoCapture(device, cv2.CAP_V4L2)
        if not cap.isOpened():
            raise SourceError(f"cannot open camera {device}")
        cap.set(cv2.CAP_PROP_FOURCC, cv2.VideoWriter_fourcc(*fourcc))
        cap.set(cv2.CAP_PROP_FRAME_WIDTH, width)
        cap.set(cv2.CAP_PROP_FRAME_HEIGHT, height)
        cap.set(cv2.CAP_PROP_FPS, fps)
        cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        if exposure is not None:
            cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, 1)  # V4L2 menu: 1 = manual
            cap.set(cv2.CAP_PROP_EXPOSURE, exposure)
        if gain is not None:
            cap.set(cv2.CAP_PROP_GAIN, gain)
        self.size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        self.fps = float(cap.get(cv2.CAP_PROP_FPS)) or fps
        log.info("%s: %dx%d @ %.1f fps, fourcc %s, exposure %s, gain %s (as read back)", device, *self.size, self.fps,
                 fourcc, cap.get(cv2.CAP_PROP_EXPOSURE), cap.get(cv2.CAP_PROP_GAIN))
        self._cap = cap
        self._cv2 = cv2
        self._offset = time.time_ns() - time.monotonic_ns()

    def read(self) -> tuple[int, np.ndarray]:
        ok, frame = self._cap.read()
        now = time.time_ns()
        if not ok or frame is None:
            raise SourceError(f"{self.device}: no frame (camera unplugged?)")
        ms = self._cap.get(self._cv2.CAP_PROP_POS_MSEC)
        t = int(ms * 1e6) + self._offset if ms > 0 else now
        if abs(t - now) > 1_000_000_000:  # not a monotonic stamp after all
            t = now
        return t, _grey(frame)

    def close(self) -> None:
        self._cap.release()


class FileSource:
    """A video file (FFV1/MJPG/... anything OpenCV reads). ``fps`` overrides the file's rate
    (a warning when they disagree); ``realtime`` paces frames like a camera; ``start_s``: Unix
    time of frame 0. A file that is missing or unreadable raises :class:`SourceGone` (it will
    not come back, so it is not retried)."""

    def __init__(self, path: str, fps: float | None = None, realtime: bool = True, loop: bool = False,
                 start_s: float | None = None) -> None:
        import cv2

        if not Path(path).is_file():
            raise SourceGone(f"{path}: video file not found")
        cap = cv2.VideoCapture(path)
        if not cap.isOpened():
            raise SourceGone(f"{path}: not a video OpenCV can read")
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        self.path, self._cap, self._cv2, self.loop = path, cap, cv2, loop
        self.size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        file_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if fps and file_fps > 0 and abs(fps - file_fps) > 0.01 * file_fps:
            log.warning("%s: fps=%g given, but the file says %g fps; stamping frames at %g fps", path, fps, file_fps, fps)
        self.fps = float(fps or file_fps or 60.0)
        self._pace = _Paced(self.fps, realtime, start_s)

    def read(self) -> tuple[int, np.ndarray] | None:
        ok, frame = self._cap.read()
        if not ok and self.loop:
            self._cap.set(self._cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self._cap.read()
        if not ok:
            return None
        return self._pace.stamp(), _grey(frame)

    def close(self) -> None:
        self._cap.release()


class ImageFolderSource(FileSource):
    """Numbered image files, e.g. ``dir/%04d.png`` (OpenCV image-sequence reader)."""

    def __init__(self, pattern: str, fps: float = 60.0, realtime: bool = False, loop: bool = False) -> None:
        import cv2

        cap = cv2.VideoCapture(pattern, cv2.CAP_IMAGES)
        if not cap.isOpened():
            raise SourceGone(f"no images match {pattern}")
        self.path, self._cap, self._cv2, self.loop = pattern, cap, cv2, loop
        self.size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        self.fps = fps
        self._pace = _Paced(fps, realtime)


class SimSource:
    """Simulated frames of one camera of the default (or a given) rig, rendered up front."""

    def __init__(self, clip: str | None = None, cam: str = "cam0", cameras: int = 2, seed: int = 0,
                 seconds: float | None = None, realtime: bool = True, loop: bool = False, fps: float = 60.0,
                 calibration: str | None = None) -> None:
        from samba_common.calib import CameraRig, default_rig

        from .sim.render import SimConfig, render_camera
        from .sim.take import load_motion, prepare_motion
        from .sim.motion import synthetic_motion

        cfg = SimConfig(fps=fps)
        rig = CameraRig.load(calibration) if calibration else default_rig(cameras)
        try:
            camera = rig.camera(cam)
        except (KeyError, ValueError):
            raise SourceError(f"sim: no camera {cam!r} in the rig ({rig.names})") from None
        if clip:
            joints, t, _ = load_motion(clip, 0.0, seconds)
        else:
            joints, t = synthetic_motion(seconds or 10.0, fps)
        joints, t, _ = prepare_motion(joints, t, cfg)
        self.rendered = render_camera(camera, joints, cfg, seed=seed * 1000 + rig.index(cam))
        self.rig, self.camera = rig, camera
        self.size, self.fps, self.loop = camera.size, fps, loop
        self._pace = _Paced(fps, realtime)
        self._k = 0

    def read(self) -> tuple[int, np.ndarray] | None:
        n = len(self.rendered.frames)
        if self._k >= n:
            if not self.loop:
                return None
            self._k = 0
        frame = self.rendered.frames[self._k]
        self._k += 1
        return self._pace.stamp(), frame

    def close(self) -> None:
        pass


def open_source(url: str) -> Source:
    """Open a source from its URL-like string (see the module docstring). ValueError for a bad
    URL, SourceError when the device or file cannot be opened."""
    scheme, _, rest = url.partition(":")
    path_part, _, query_s = rest.partition("?")
    if path_part.startswith("//"):
        path_part = path_part[2:]
    q = urllib.parse.parse_qs(query_s)
    if scheme == "v4l2":
        return V4L2Source(path_part or "/dev/video0", _q(q, "width", 160, int), _q(q, "height", 120, int),
                          _q(q, "fps", 60.0, float), _q(q, "fourcc", "GREY"), _q(q, "exposure", None, float),
                          _q(q, "gain", None, float))
    if scheme == "file":
        if not path_part:
            raise ValueError("file: source needs a path, e.g. file:take/cam0.avi")
        return FileSource(path_part, _q(q, "fps", None, float), _q(q, "realtime", True, _flag), _q(q, "loop", False, _flag),
                          _q(q, "start", None, float))
    if scheme == "images":
        if not path_part:
            raise ValueError("images: source needs a pattern, e.g. images:dir/%04d.png")
        return ImageFolderSource(path_part, _q(q, "fps", 60.0, float), _q(q, "realtime", False, _flag),
                                 _q(q, "loop", False, _flag))
    if scheme == "sim":
        return SimSource(_q(q, "clip", None) or (path_part or None), _q(q, "cam", "cam0"), _q(q, "cameras", 2, int),
                         _q(q, "seed", 0, int), _q(q, "seconds", None, float), _q(q, "realtime", True, _flag),
                         _q(q, "loop", False, _flag), _q(q, "fps", 60.0, float), _q(q, "calibration", None))
    raise ValueError(f"unknown source {url!r}; use v4l2:, file:, images: or sim:")


__all__ = ["Source", "SourceError", "SourceGone", "open_source", "V4L2Source", "FileSource", "ImageFolderSource", "SimSource"]
