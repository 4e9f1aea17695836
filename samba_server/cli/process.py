"""``samba-process``: the offline path, videos (one per camera) -> joints.npz through the same
:class:`~samba_server.server.Server` as live (:func:`samba_server.process.process_videos`)."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from samba_common.calib import CalibrationError
from samba_common.config import ConfigError
from samba_common.formats import save_joints
from samba_common.progress import Progress
from samba_common.skeleton import MARKER_NAMES
from samba_server.activity import MoteActivity
from samba_server.app import add_placement_arg, build_server, load_server_configs, setup_logging
from samba_server.process import VideoError, _open_video, process_videos
from samba_server.recon.bounds import guessed_summary
from samba_server.record import RecorderError

log = logging.getLogger(__name__)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-process",
                                 description="Offline: videos (one per camera) -> joints.npz, with the live code.")
    ap.add_argument("calibration", help="calibration.toml (camera names = video file names)")
    ap.add_argument("videos", nargs="+", help="cam0.avi cam1.avi ... (any format OpenCV reads)")
    ap.add_argument("--out", required=True, help="output joints.npz")
    ap.add_argument("--fps", type=float, help="frame rate of the videos (default: read from the files, else 30)")
    ap.add_argument("--record", metavar="TAKE.mcap", help="also record the packets and poses as a take")
    ap.add_argument("--db", help="motion database (.npz) (default: the shipped one)")
    ap.add_argument("--one-pass", action="store_true",
                    help="name the markers from the past frames only, as live (samba-server, samba-replay) does. "
                         "Default: the take is also labelled backwards, and names the live pass itself corrected "
                         "later (or never gave, as after a blackout) come from the backward pass; --record keeps "
                         "the live poses")
    add_placement_arg(ap)
    ap.add_argument("--config", help="server TOML (default: the packaged configs/server.toml)")
    ap.add_argument("--mote-config", help="mote TOML for detection/tracking (default: built-in defaults)")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    args = ap.parse_args(argv)
    setup_logging(args.verbose)
    videos = [Path(v) for v in args.videos]
    if len({v.stem for v in videos}) != len(videos):
        ap.error("two videos have the same camera name")
    try:
        if args.fps is not None and args.fps <= 0:
            ap.error("--fps must be > 0")
        import cv2

        cap = _open_video(videos[0])
        file_fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0)
        cap.release()
        fps = args.fps
        if fps is None:
            fps = file_fps if 1.0 <= file_fps <= 1000.0 else 30.0
        elif 1.0 <= file_fps <= 1000.0 and abs(fps - file_fps) > 0.01 * file_fps:
            print(f"samba-process: WARNING: --fps {fps:g} but {videos[0]} says {file_fps:g} fps; frame times, "
                  f"frame grouping and the solver's smoothing use {fps:g} (leave --fps out to use the file's)",
                  file=sys.stderr)
        mote_config = None
        if args.mote_config:
            from samba_mote.pipeline import load_mote_config

            mote_config = load_mote_config(args.mote_config)
        configs = load_server_configs(args.config, args.placement, fps=fps)
        server = build_server(args.calibration, configs, args.db, args.record, live=False)
        import cv2

        total = 0
        for v in videos:
            cap = _open_video(v)
            total = max(total, int(cap.get(cv2.CAP_PROP_FRAME_COUNT)))
            cap.release()
        activity = MoteActivity(server.rig.names)
        with Progress(total * (1 if args.one_pass else 2), "samba-process") as bar:  # both ways: two passes
            joints, t, extra = process_videos(server, videos, fps, mote_config, bar, activity,
                                              both_ways=not args.one_pass)
        if server.recorder is not None:
            server.recorder.close()
        subject = server.subject
        extra.pop("live", None)  # the forward pass alone: what samba-server gives live
        save_joints(args.out, joints, t, **extra, **(subject.metadata() if subject is not None else {}))
    except (VideoError, CalibrationError, ConfigError, RecorderError, OSError, ValueError) as exc:
        print(f"samba-process: {exc}", file=sys.stderr)
        return 1
    solved_rows = np.isfinite(joints).all(axis=(1, 2))
    solved = int(solved_rows.sum())
    print(f"wrote {args.out}: {len(t)} frames, {solved} solved", file=sys.stderr)
    if solved:
        print(guessed_summary(extra["joint_bound"], solved_rows), file=sys.stderr)
    note = getattr(server.reconstructor, "placement_note", None)
    if note:
        print(f"marker placement: {note}", file=sys.stderr)
    for line in activity.notes():
        log.info(line)
    for line in activity.warnings() + unnamed_warnings(extra["markers"], joints, extra.get("wrists_unseparated")) \
            + legs_warnings(extra.get("legs_unsure"), joints, t):
        print(f"samba-process: WARNING: {line}", file=sys.stderr)
    if server.stats.label_errors:
        print(f"samba-process: WARNING: the labelling failed on {server.stats.label_errors} frame(s) (an internal "
              f"error, logged above; please report it): those frames are output unnamed", file=sys.stderr)
    if solved < 0.5 * len(t):
        print(f"samba-process: WARNING: only {solved} of {len(t)} frames solved: {server.failure_reason()}",
              file=sys.stderr)
        return 3
    return 0


#: a marker unnamed in more than this share of the frames with a pose is reported
UNNAMED_WARN = 0.1


def unnamed_warnings(markers: np.ndarray, joints: np.ndarray, together: np.ndarray | None = None,
                     share: float = UNNAMED_WARN) -> list[str]:
    """One line per marker left unnamed in more than ``share`` of the frames with a pose: its
    limb there is the solver's guess (often tens of cm off), not a measurement. markers:
    (F, 8, 3) named markers (NaN = unnamed); joints: (F, 13, 3) poses (NaN = none); together:
    (F,) bool, the frames whose two wrists were left unnamed because no view saw them apart
    (hands together: solved from their merged point, not guessed), reported on a line of their
    own (None: none)."""
    solved = np.isfinite(joints).all(axis=(1, 2))
    n = int(solved.sum())
    if n == 0:
        return []
    unnamed = ~np.isfinite(markers[solved]).all(axis=2)  # (n, 8)
    out = []
    if together is not None:
        held = np.asarray(together, bool)[solved]
        unnamed[np.ix_(held, [MARKER_NAMES.index("left_wrist"), MARKER_NAMES.index("right_wrist")])] = False
        k = int(held.sum())
        if k > share * n:
            out.append(f"both wrists unnamed in {k} of {n} frames with a pose ({100 * k / n:.0f} %): hands together, "
                       f"no view saw them apart; the arms are solved from their merged blobs and may be each "
                       f"other's (joint_bound covers it; wrists_unseparated in the output marks the frames)")
    for m in np.flatnonzero(unnamed.mean(axis=0) > share):
        side, part = MARKER_NAMES[m].split("_")
        limb = "arm" if part in ("shoulder", "wrist") else "leg"
        k = int(unnamed[:, m].sum())
        out.append(f"{side} {part} unnamed in {k} of {n} frames with a pose ({100 * k / n:.0f} %): the {side} "
                   f"{limb} there is the solver's guess (n_markers in the output counts the named markers)")
    return out


#: legs unsure of their side for at least this long (s, summed) are reported
LEGS_UNSURE_WARN_S = 0.5


def legs_warnings(unsure: np.ndarray | None, joints: np.ndarray, t: np.ndarray,
                  min_s: float = LEGS_UNSURE_WARN_S) -> list[str]:
    """One line when the legs' left and right were unsure (unsure (F,) bool, the output's
    ``legs_unsure``) in frames with a pose (joints (F, 13, 3)) for at least min_s s in all (t
    (F,) s): the knees and ankles there may be the other side's, and their bounds say so."""
    if unsure is None or len(t) < 2:
        return []
    solved = np.isfinite(joints).all(axis=(1, 2))
    hit = np.asarray(unsure, bool) & solved
    dt = float(np.median(np.diff(t)))
    if hit.sum() * dt < min_s:
        return []
    edges = np.flatnonzero(np.diff(np.r_[0, hit.astype(int), 0]))
    a, b = max(zip(edges[::2], edges[1::2]), key=lambda ab: ab[1] - ab[0])
    return [f"left and right legs unsure in {int(hit.sum())} of {int(solved.sum())} frames with a pose "
            f"(longest {t[a]:.2f}-{t[b - 1]:.2f} s): the legs were named afresh (at the start, after a blackout or "
            f"a loss) and their knees not seen apart since, so the markers cannot tell which leg is which (legs one "
            f"behind the other, or knees in one blob); the knees and ankles there may be the other side's "
            f"(joint_bound says how far; legs_unsure in the output marks the frames)"]


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
