"""The mote's per-frame work as one reusable object: detection + tracking -> MarkerPacket.

``samba-mote`` (live) and ``samba-process`` (offline, on recorded videos) both run this, so
offline results are exactly what the motes would have sent.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field

import numpy as np

from samba_common.config import ConfigError, from_dict, read_toml
from samba_common.wire import MarkerPacket

from .detect import DetectConfig, Detector
from .track import MarkerTracker, TrackConfig, view_from_calibration

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MoteConfig:
    """All per-frame settings: ``[detect]`` and ``[track]`` tables of configs/mote.toml."""

    detect: DetectConfig = field(default_factory=DetectConfig)
    track: TrackConfig = field(default_factory=TrackConfig)


def load_mote_config(path: str | os.PathLike | None) -> MoteConfig:
    """MoteConfig from a TOML file (missing tables take defaults); defaults when path is None."""
    if path is None:
        return MoteConfig()
    data = read_toml(path)
    return MoteConfig(
        detect=from_dict(DetectConfig, data.get("detect", {}), f"{path} [detect]"),
        track=from_dict(TrackConfig, data.get("track", {}), f"{path} [track]"),
    )


def _camera_for(calibration, mote_id: str):
    """A Camera from a Camera, a CameraRig (by name = mote id) or None."""
    if calibration is None:
        return None
    if hasattr(calibration, "cameras"):
        try:
            return calibration.camera(mote_id)
        except (KeyError, ValueError):
            log.warning("calibration has no camera named %r; labelling from the image layout", mote_id)
            return None
    return calibration


class MotePipeline:
    """Detection + tracking for one camera.

    config: MoteConfig (or None for defaults); mote_id: camera name; calibration: this
    camera's ``Camera`` or a ``CameraRig`` holding it (decides front/back for T-pose labelling).
    """

    def __init__(self, config: MoteConfig | None = None, mote_id: str = "cam0", calibration=None) -> None:
        self.config = config or MoteConfig()
        self.mote_id = mote_id
        self.detector = Detector(self.config.detect)
        self.camera = _camera_for(calibration, mote_id)
        view = None
        if self.camera is not None:
            view = view_from_calibration(self.camera)
            if view is None:
                log.warning("%s: camera sees the T-pose from the side; using tpose_view=%s",
                            mote_id, self.config.track.tpose_view)
            else:
                log.info("%s: T-pose seen from the %s (from calibration)", mote_id, view)
        self.tracker = MarkerTracker(self.config.track, view=view)
        self.seq = 0
        self.last_detect_us = 0.0
        self.last_blobs = 0

    def set_calibration(self, calibration) -> None:
        """Adopt a calibration that arrived later (labels again from the next T-pose)."""
        cam = _camera_for(calibration, self.mote_id)
        if cam is None:
            return
        view = view_from_calibration(cam)
        self.camera = cam
        if view is not None and view != self.tracker.view:
            self.tracker.view = view
            self.tracker.reset()

    def process(self, t_ns: int, frame: np.ndarray) -> MarkerPacket:
        """One (H, W) uint8 frame captured at t_ns (ns since the Unix epoch) -> MarkerPacket."""
        if frame.ndim == 3:
            frame = frame[..., 0] if frame.shape[2] == 1 else frame.mean(axis=2).astype(np.uint8)
        t0 = time.perf_counter()
        det = self.detector.detect(frame)
        out = self.tracker.update(int(t_ns), det.uv, det.area, det.cov)
        self.last_detect_us = (time.perf_counter() - t0) * 1e6
        self.last_blobs = len(det)
        h, w = frame.shape
        pkt = MarkerPacket(self.mote_id, self.seq, int(t_ns), w, h, det.threshold, out.labels, out.uv, out.area,
                           out.flags, out.moments(det.cov))
        self.seq = (self.seq + 1) & 0xFFFFFFFF
        return pkt


__all__ = ["MoteConfig", "MotePipeline", "load_mote_config", "ConfigError"]
