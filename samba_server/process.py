"""``samba-process``: the offline path. Runs the mote pipeline (detection + tracking,
``samba_mote.pipeline.MotePipeline``) on one video per camera and feeds the packets through
the same :class:`~samba_server.server.Server` as live, frame by frame.

Camera names come from the video file names (``cam0.avi`` -> ``cam0``) and must be in the
calibration. Frame ``i`` of every video is stamped ``i / fps`` seconds. The output has one
row per video frame (FORMATS.md): ``t = i / fps``; frames that could not be solved are NaN.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from samba_common.calib import CalibrationError
from samba_common.config import ConfigError
from samba_common.progress import Progress

from .record import RecorderError
from .server import Server
from .server_cli import build_server, load_server_configs, setup_logging

log = logging.getLogger(__name__)


class VideoError(OSError):
    """A video cannot be opened or read."""


def _open_video(path: Path):
    import cv2

    if not path.exists():
        raise VideoError(f"{path}: file not found")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise VideoError(f"{path}: OpenCV cannot open this video")
    cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
    return cap


def _grey(frame: np.ndarray) -> np.ndarray:
    import cv2

    if frame.ndim == 3:
        return frame[..., 0].copy() if frame.shape[2] == 1 else cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
    return frame


def process_videos(server: Server, videos: list[Path], fps: float, mote_config=None,
                   progress: Progress | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Run every video through its MotePipeline and ``server``.

    Returns joints (F, 13, 3), t (F,) seconds (F = longest video), and extras (markers
    (F, 8, 3), residual (F,), n_markers (F,)).
    """
    from samba_common.wire import encode_packet
    from samba_mote.pipeline import MotePipeline

    import cv2

    names = [v.stem for v in videos]
    missing = [n for n in names if n not in server.rig.names]
    if missing:
        raise CalibrationError(None, None, f"videos {missing} have no camera of that name in the calibration "
                               f"(cameras: {server.rig.names})")
    caps = [_open_video(v) for v in videos]
    counts = [int(c.get(cv2.CAP_PROP_FRAME_COUNT)) for c in caps]
    pipes = [MotePipeline(mote_config, n, server.rig) for n in names]
    for n in names:
        server.mote_event(n, True, 0)
    period = 1e9 / fps
    open_ = [True] * len(caps)
    i = 0
    try:
        while any(open_):
            t_ns = int(round(i * period))
            for c, cap in enumerate(caps):
                if not open_[c]:
                    continue
                ok, frame = cap.read()
                if not ok:
                    open_[c] = False
                    server.mote_event(names[c], False, t_ns)
                    continue
                pkt = pipes[c].process(t_ns, _grey(frame))
                server.ingest(names[c], encode_packet(pkt), arrival_ns=t_ns)
            server.process_pending()
            if any(open_):
                i += 1
                if progress is not None:
                    progress.update(1)
    finally:
        for cap in caps:
            cap.release()
    server.finish()
    n_frames = max(i, max(counts) if counts else 0)
    joints = np.full((n_frames, 13, 3), np.nan)
    markers = np.full((n_frames, 8, 3), np.nan)
    residual = np.full(n_frames, np.nan)
    n_markers = np.zeros(n_frames, int)
    for p in server.poses:
        k = int(round(p.t_ns / period))
        if 0 <= k < n_frames:
            joints[k], markers[k], residual[k], n_markers[k] = p.joints, p.markers, p.residual_m, p.n_markers
    t = np.arange(n_frames) / fps
    return joints, t, {"markers": markers, "residual": residual, "n_markers": n_markers}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-process",
                                 description="Offline: videos (one per camera) -> joints.npz, with the live code.")
    ap.add_argument("calibration", help="calibration.toml (camera names = video file names)")
    ap.add_argument("videos", nargs="+", help="cam0.avi cam1.avi ... (any format OpenCV reads)")
    ap.add_argument("--out", required=True, help="output joints.npz")
    ap.add_argument("--fps", type=float, help="frame rate of the videos (default: read from the files, else 30)")
    ap.add_argument("--record", metavar="TAKE.mcap", help="also record the packets and poses as a take")
    ap.add_argument("--db", help="motion database (.npz) (default: the shipped one)")
    ap.add_argument("--config", help="server TOML (default: the packaged configs/server.toml)")
    ap.add_argument("--mote-config", help="mote TOML for detection/tracking (default: built-in defaults)")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    args = ap.parse_args(argv)
    setup_logging(args.verbose)
    videos = [Path(v) for v in args.videos]
    if len({v.stem for v in videos}) != len(videos):
        ap.error("two videos have the same camera name")
    try:
        fps = args.fps
        if fps is None:
            import cv2

            cap = _open_video(videos[0])
            fps = float(cap.get(cv2.CAP_PROP_FPS)) or 30.0
            cap.release()
            if not 1.0 <= fps <= 1000.0:
                fps = 30.0
        if fps <= 0:
            ap.error("--fps must be > 0")
        mote_config = None
        if args.mote_config:
            from samba_mote.pipeline import load_mote_config

            mote_config = load_mote_config(args.mote_config)
        configs = load_server_configs(args.config, fps=fps)
        server = build_server(args.calibration, configs, args.db, args.record, live=False)
        import cv2

        total = 0
        for v in videos:
            cap = _open_video(v)
            total = max(total, int(cap.get(cv2.CAP_PROP_FRAME_COUNT)))
            cap.release()
        with Progress(total, "samba-process") as bar:
            joints, t, extra = process_videos(server, videos, fps, mote_config, bar)
        if server.recorder is not None:
            server.recorder.close()
        from samba_common.formats import save_joints

        save_joints(args.out, joints, t, **extra)
    except (VideoError, CalibrationError, ConfigError, RecorderError, OSError, ValueError) as exc:
        print(f"samba-process: {exc}", file=sys.stderr)
        return 1
    solved = int(np.isfinite(joints).all(axis=(1, 2)).sum())
    print(f"wrote {args.out}: {len(t)} frames, {solved} solved", file=sys.stderr)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
