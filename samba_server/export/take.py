"""What an exporter gets: one take's joints (and markers when known), whatever file it came from.

A take is a ``joints.npz`` (FORMATS.md; optional ``markers`` extra key of shape (F, 8, 3),
or a sibling ``markers.npz`` passed explicitly) or a ``take.mcap`` recorded by
``samba-server`` (read through :mod:`samba_server.record`).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from samba_common.formats import load_joints, load_markers
from samba_common.skeleton import JOINT_NAMES, MARKER_NAMES
from samba_common.subject import Subject, subject_from_metadata

log = logging.getLogger(__name__)


class TakeError(ValueError):
    """The take cannot be read or is unusable for export (message names the file)."""


@dataclass
class ExportTake:
    """joints: (F, 13, 3) world metres Z up (NaN rows = unsolved frames); t: (F,) seconds;
    markers: (F, 8, 3) world metres NaN = unseen, or None when the take has no markers;
    subject: the bone lengths and marker offsets the take was solved with (the last one of a
    recording), or None when the file does not say."""

    joints: np.ndarray
    t: np.ndarray
    markers: np.ndarray | None = None
    source: str = ""
    subject: Subject | None = None

    @property
    def n_frames(self) -> int:
        return int(self.joints.shape[0])

    def rate(self) -> float:
        """Frames per second from the median time step (1.0 for a single frame)."""
        if self.n_frames < 2:
            return 1.0
        dt = float(np.median(np.diff(self.t)))
        if dt <= 0:
            raise TakeError(f"{self.source}: time stamps do not increase")
        return 1.0 / dt


def _check(take: ExportTake) -> ExportTake:
    F = take.joints.shape[0]
    if take.joints.shape != (F, len(JOINT_NAMES), 3) or take.t.shape != (F,):
        raise TakeError(f"{take.source}: joints {take.joints.shape} / t {take.t.shape} "
                        f"are not (F, 13, 3) / (F,)")
    if F == 0:
        raise TakeError(f"{take.source}: the take has no frames")
    if take.markers is not None and take.markers.shape != (F, len(MARKER_NAMES), 3):
        raise TakeError(f"{take.source}: markers {take.markers.shape} are not ({F}, 8, 3)")
    return take


def load_take(path: str | os.PathLike, markers_path: str | os.PathLike | None = None) -> ExportTake:
    """Read a joints.npz or a take.mcap (by suffix). ``markers_path``: optional markers.npz with
    the same number of frames. Raises TakeError / FormatError naming the file."""
    p = Path(path)
    if not p.exists():
        raise TakeError(f"{p}: file not found")
    if p.suffix.lower() == ".mcap":
        take = _load_mcap(p)
    else:
        jt = load_joints(p)
        markers = jt.extra.get("markers")
        if markers is not None:
            markers = np.asarray(markers, dtype=np.float64)
        take = ExportTake(jt.joints, jt.t, markers, str(p), subject_from_metadata(jt.extra))
    if markers_path is not None:
        mt = load_markers(markers_path)
        if mt.markers.shape[0] != take.n_frames:
            raise TakeError(f"{markers_path}: {mt.markers.shape[0]} frames but {p} has {take.n_frames}")
        take.markers = mt.markers
    return _check(take)


def read_mcap_poses(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The ``/pose`` messages of a Samba recording (through :mod:`samba_server.record`).

    Returns (joints (F, 13, 3) metres NaN rows = unsolved, t_ns (F,) int64 capture times,
    markers (F, 8, 3) metres NaN = missing, number of undecodable messages skipped).
    """
    from samba_common.pose_wire import PoseError, decode_pose
    from samba_server import record

    joints, t_ns, markers, bad = [], [], [], 0
    for msg in record.iter_messages(path, topics=[record.POSE_TOPIC]):
        try:
            pose = decode_pose(msg.data)
        except PoseError as exc:
            bad += 1
            log.debug("%s: skipped a bad pose message (%s)", path, exc)
            continue
        joints.append(np.asarray(pose.joints, dtype=np.float64))
        t_ns.append(int(pose.t_ns))
        m = pose.markers
        markers.append(np.full((len(MARKER_NAMES), 3), np.nan) if m is None else np.asarray(m, dtype=np.float64))
    if bad:
        log.warning("%s: skipped %d undecodable pose messages", path, bad)
    return (np.asarray(joints).reshape(-1, len(JOINT_NAMES), 3), np.asarray(t_ns, dtype=np.int64),
            np.asarray(markers).reshape(-1, len(MARKER_NAMES), 3), bad)


def _load_mcap(p: Path) -> ExportTake:
    """Joints and markers from a Samba recording (and the last subject it was solved with); t in
    seconds from the first pose."""
    from samba_server import record

    try:
        joints, t_ns, markers, _ = read_mcap_poses(p)
    except (ValueError, OSError) as exc:
        raise TakeError(f"{p}: cannot read the recording ({exc})") from None
    if joints.shape[0] == 0:
        raise TakeError(f"{p}: the recording holds no poses (was the server solving?)")
    order = np.argsort(t_ns, kind="stable")
    t = (t_ns[order] - t_ns[order[0]]) / 1e9
    return ExportTake(joints[order], t, markers[order], str(p), record.last_subject(p))


def fill_invalid(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hold the last complete pose over frames with any NaN joint (leading ones take the first).

    joints: (F, 13, 3). Returns (filled copy (F, 13, 3), held (F,) bool). Raises TakeError when
    no frame is complete.
    """
    valid = np.all(np.isfinite(joints), axis=(1, 2))
    if not valid.any():
        raise TakeError("no frame has all 13 joints: nothing to export")
    idx = np.where(valid, np.arange(len(valid)), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = int(np.argmax(valid))
    return joints[idx].copy(), ~valid
