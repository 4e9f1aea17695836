"""``samba-process``: the offline path. Runs the mote pipeline (detection + tracking,
``samba_mote.pipeline.MotePipeline``) on one video per camera and feeds the packets through
the same :class:`~samba_server.server.Server` as live, frame by frame.

Camera names come from the video file names (``cam0.avi`` -> ``cam0``) and must be in the
calibration. Frame ``i`` of every video is stamped ``start + i / fps``, ``start`` being the
wall time when processing begins, and the server runs on that same take clock (its ``clock``
returns the current frame's time): a recording (``--record``) then has capture times,
arrival times and poses on one clock, like a live take, and latencies of 0 (offline). The
output has one row per video frame (FORMATS.md): ``t = i / fps``; frames that could not be
solved are NaN.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from samba_common.calib import CalibrationError
from samba_common.progress import Progress

from .server import Server

log = logging.getLogger(__name__)


class VideoError(OSError):
    """A video cannot be opened or read."""


def _open_video(path: Path):
    """An opened cv2.VideoCapture; frames come out decoded to BGR whatever the codec (MJPG's
    yuvj420p, H.264, grey FFV1), so :func:`grey` gives the true 8-bit intensity."""
    import cv2

    if not path.exists():
        raise VideoError(f"{path}: file not found")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise VideoError(f"{path}: OpenCV cannot open this video")
    return cap


def grey(frame: np.ndarray) -> np.ndarray:
    """(H, W) uint8 intensity of a decoded frame: (H, W), (H, W, 1) or BGR (H, W, 3)."""
    import cv2

    if frame.ndim == 3:
        return frame[..., 0].copy() if frame.shape[2] == 1 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    return frame


def _video_frames(cap) -> Iterator[np.ndarray]:
    while True:
        ok, frame = cap.read()
        if not ok:
            return
        yield grey(frame)


def process_frames(server: Server, names: list[str], frames: list[Iterable[np.ndarray]], fps: float,
                   mote_config=None, progress: Progress | None = None, n_frames: int = 0,
                   activity=None, both_ways: bool = False) -> tuple[np.ndarray, np.ndarray, dict]:
    """Run each camera's frames ((H, W) uint8, in capture order) through its MotePipeline and
    ``server``; frame i of every camera is stamped start + i / fps (see the module docstring).
    ``activity``: optional callable(MarkerPacket) seeing every packet (e.g. a MoteActivity).
    both_ways: then label the take again backwards and mend the live names where the two
    passes show them wrong (:mod:`samba_server.both_ways`); ``server`` keeps the forward (live)
    poses.

    Returns joints (F, 13, 3), t (F,) seconds (F = the longest camera, at least ``n_frames``),
    and extras: markers (F, 8, 3), residual (F,), n_markers (F,), label_margin (F,) metres,
    joint_bound (F, 13) m, legs_unsure (F,) bool (the legs' names may be each other's:
    :attr:`~samba_server.labelling.Labeller.legs_unsure`; the knees' and ankles' bounds cover
    it), wrists_unseparated (F,) bool (both wrists left unnamed: no view saw them apart,
    :meth:`~samba_server.labelling.Labeller.unseparated`; the wrists' and elbows' bounds cover
    either naming); with both_ways also from_backward (F,) bool and live: the forward pass's joints,
    markers and bounds (a dict).
    """
    from samba_common.wire import encode_packet
    from samba_mote.pipeline import MotePipeline

    missing = [n for n in names if n not in server.rig.names]
    if missing:
        raise CalibrationError(None, None, f"videos {missing} have no camera of that name in the calibration "
                               f"(cameras: {server.rig.names})")
    pipes = [MotePipeline(mote_config, n, server.rig) for n in names]
    base = time.time_ns()
    now = [base]
    server.clock = lambda: now[0]  # the take's clock: the time of the frame being processed
    for n in names:
        server.mote_event(n, True, base)
    period = 1e9 / fps
    its = [iter(f) for f in frames]
    open_ = [True] * len(its)
    rig_index = [server.rig.names.index(n) for n in names]
    kept: list[list] = []  # per frame, per rig camera: the packet (both_ways)
    # pose seq -> the markers its labelling renamed, its identification's margin (NaN: tracked),
    # its markers whose position is rough, whether its legs' names may be each other's, its
    # wrists no view saw apart (output unnamed) and its names before that (the two-way pass's)
    labelled_by_seq: dict[int, tuple[int, float, np.ndarray, bool, np.ndarray, np.ndarray]] = {}

    def note_renamed(msg) -> None:  # runs right after its frame was labelled: the last quality is that frame's
        q = server.labeller.last_quality
        named = np.array(server.last_named, float)
        gap = np.isfinite(named).all(axis=1) & ~np.isfinite(np.asarray(msg.markers, float)).all(axis=1)
        labelled_by_seq[msg.seq] = (q.renamed, q.margin_m if q.mode == "identified" else float("nan"),
                                    server.labeller.loose(named), server.labeller.legs_unsure, gap, named)

    server.pose_listeners.append(note_renamed)  # (legs_unsure is output one-pass too)
    i = 0
    while any(open_):
        if both_ways:
            kept.append([None] * len(server.rig.names))
        t_ns = base + int(round(i * period))
        now[0] = t_ns
        for c, it in enumerate(its):
            if not open_[c]:
                continue
            frame = next(it, None)
            if frame is None:
                open_[c] = False
                server.mote_event(names[c], False, t_ns)
                continue
            pkt = pipes[c].process(t_ns, frame)
            if both_ways:
                kept[-1][rig_index[c]] = pkt
            if activity is not None:
                activity(pkt)
            server.ingest(names[c], encode_packet(pkt), arrival_ns=t_ns)
        server.process_pending()
        if any(open_):
            i += 1
            if progress is not None:
                progress.update(1)
    server.finish()
    server.pose_listeners.remove(note_renamed)
    n_frames = max(i, n_frames)
    joints = np.full((n_frames, 13, 3), np.nan)
    markers = np.full((n_frames, 8, 3), np.nan)  # as output (live: unseparated wrists unnamed)
    named = np.full((n_frames, 8, 3), np.nan)  # as labelled
    residual = np.full(n_frames, np.nan)
    margin = np.full(n_frames, np.nan)
    n_markers = np.zeros(n_frames, int)
    bound = np.full((n_frames, 13), np.inf)
    renamed = np.zeros(n_frames, np.int64)
    identified = np.full(n_frames, np.nan)
    loose = np.zeros((n_frames, 8), bool)
    legs_unsure = np.zeros(n_frames, bool)
    unseparated = np.zeros((n_frames, 8), bool)
    t_live = np.arange(n_frames) / fps  # the server's own frame times (s since its first frame)
    t0_ns = server.poses[0].t_ns if server.poses else base
    for p in server.poses:
        k = int(round((p.t_ns - base) / period))
        if 0 <= k < n_frames:
            joints[k], markers[k], residual[k], n_markers[k] = p.joints, p.markers, p.residual_m, p.n_markers
            margin[k] = p.label_margin_m
            if p.joint_bound is not None:
                bound[k] = p.joint_bound
            renamed[k], identified[k], loose[k], legs_unsure[k], unseparated[k], named[k] = labelled_by_seq.get(
                p.seq, (0, np.nan, loose[k], False, unseparated[k], p.markers))
            t_live[k] = (p.t_ns - t0_ns) / 1e9
    t = np.arange(n_frames) / fps
    extra = {"markers": markers, "residual": residual, "n_markers": n_markers, "label_margin": margin,
             "joint_bound": bound, "legs_unsure": legs_unsure, "wrists_unseparated": unseparated.any(axis=1)}
    if both_ways:
        from .both_ways import PassResult, relabel_both_ways

        kept += [[None] * len(server.rig.names) for _ in range(n_frames - len(kept))]
        again = relabel_both_ways(server, kept[:n_frames], t_live,
                                  PassResult(named, renamed, margin, identified, loose, residual, legs_unsure,
                                             unseparated),
                                  progress)
        if again is not None:
            live = {"joints": joints, "markers": markers, "joint_bound": bound}
            joints, extra = again
            extra["live"] = live
    return joints, t, extra


def process_videos(server: Server, videos: list[Path], fps: float, mote_config=None,
                   progress: Progress | None = None, activity=None,
                   both_ways: bool = False) -> tuple[np.ndarray, np.ndarray, dict]:
    """:func:`process_frames` on one video per camera (camera name = file stem)."""
    import cv2

    caps = [_open_video(v) for v in videos]
    try:
        counts = [int(c.get(cv2.CAP_PROP_FRAME_COUNT)) for c in caps]
        return process_frames(server, [v.stem for v in videos], [_video_frames(c) for c in caps], fps,
                              mote_config, progress, max(counts, default=0), activity, both_ways)
    finally:
        for cap in caps:
            cap.release()
