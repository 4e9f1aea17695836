"""Read calibration takes into observation arrays (F, C, K, 2) raw pixels, NaN = unseen.

Sources (chosen by what TAKE is):

* a directory of videos ``cam0.avi`` ... (one per camera, frames in sync by index): blobs
  detected with the mote detector (:class:`samba_mote.detect.Detector`, unlabelled) or, for
  labelled takes, the full mote pipeline (detection + tracking + T-pose labelling);
* an MCAP recording (``*.mcap``, ``samba_server.record`` layout) of marker packets: frames
  grouped across motes by capture time;
* a ``.npz`` written by ``samba-calibrate simulate`` (keys ``uv``, ``camera_names``).

Unlabelled mode (wand, L-frame): a view enters a frame only when it holds exactly K blobs.
Labelled mode (self-calibration): ``uv[:, c, m]`` is marker m (``MARKER_NAMES`` order), using
only measured records (not predicted, lost or merged).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from samba_common.skeleton import N_MARKERS

log = logging.getLogger(__name__)


class TakeError(ValueError):
    """A calibration take cannot be read or does not match the cameras."""


def _views_from_blobs(blobs: list[list[np.ndarray | None]], K: int) -> np.ndarray:
    """blobs[f][c]: (n, 2) array or None -> (F, C, K, 2) with views of exactly K blobs."""
    F, C = len(blobs), len(blobs[0]) if blobs else 0
    uv = np.full((F, C, K, 2), np.nan)
    for f, row in enumerate(blobs):
        for c, b in enumerate(row):
            if b is not None and len(b) == K:
                uv[f, c] = b
    return uv


def read_videos(directory: Path, names: list[str], K: int | None, progress=None, rig=None,
                fps: float = 60.0) -> np.ndarray:
    """Videos ``<name>.avi`` (or any extension) -> (F, C, K, 2) unlabelled (K given) or
    (F, C, 8, 2) labelled (K None, mote pipeline; ``rig`` tells the pipeline where each camera
    stands, which decides left/right in the T-pose labelling). Frames are synchronised by index."""
    import cv2

    from samba_mote.detect import Detector

    caps, paths = [], []
    for n in names:
        cands = sorted(directory.glob(f"{n}.*"))
        if not cands:
            raise TakeError(f"{directory}: no video for camera {n!r} (expected {n}.avi)")
        cap = cv2.VideoCapture(str(cands[0]))
        if not cap.isOpened():
            raise TakeError(f"{cands[0]}: cannot open video")
        cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
        caps.append(cap)
        paths.append(cands[0])
    if K is None:
        from samba_mote.pipeline import MotePipeline

        pipes = [MotePipeline(mote_id=n, calibration=rig) for n in names]
    else:
        dets = [Detector() for _ in names]
    rows = []
    f = 0
    try:
        while True:
            frames = []
            for cap in caps:
                ok, img = cap.read()
                if not ok:
                    break
                if img.ndim == 3:
                    img = img[..., 0]
                frames.append(img)
            if len(frames) < len(caps):
                break
            if K is None:
                row = np.full((len(names), N_MARKERS, 2), np.nan)
                for c, (p, img) in enumerate(zip(pipes, frames)):
                    pk = p.process(int(round(f * 1e9 / fps)), img)
                    _fill_labelled(row[c], pk)
                rows.append(row)
            else:
                rows.append([d.detect(img).uv.astype(float) for d, img in zip(dets, frames)])
            f += 1
            if progress is not None:
                progress(f)
    finally:
        for cap in caps:
            cap.release()
    if not rows:
        raise TakeError(f"{directory}: the videos hold no frames")
    return np.stack(rows) if K is None else _views_from_blobs(rows, K)


def _fill_labelled(out: np.ndarray, pk) -> None:
    """Write measured, labelled, unmerged records of packet ``pk`` into out (8, 2)."""
    from samba_common.wire import FLAG_LOST, FLAG_MERGED, FLAG_PREDICTED

    bad = FLAG_PREDICTED | FLAG_LOST | FLAG_MERGED
    for lab, fl, uv in zip(pk.labels, pk.flags, pk.uv):
        if lab < N_MARKERS and not (int(fl) & bad):
            out[int(lab)] = uv


def read_mcap(path: Path, names: list[str], K: int | None) -> np.ndarray:
    """Marker packets of an MCAP take -> (F, C, K, 2) (unlabelled, K given) or (F, C, 8, 2).

    Packets are grouped into frames by capture time: a packet joins the frame whose first
    packet is within half a frame period (median packet interval of the first mote)."""
    from samba_common.wire import PacketError, decode_packet
    from samba_server.record import iter_messages

    index = {n: i for i, n in enumerate(names)}
    packets: list[tuple[int, int, object]] = []
    dropped = 0
    for msg in iter_messages(path):
        mote = msg.mote_id
        if mote is None:
            continue
        if mote not in index:
            dropped += 1
            continue
        try:
            pk = decode_packet(msg.data)
        except PacketError:
            dropped += 1
            continue
        packets.append((pk.t_ns, index[mote], pk))
    if dropped:
        log.info("%s: skipped %d packets (unknown mote or undecodable)", path, dropped)
    if not packets:
        raise TakeError(f"{path}: no marker packets of cameras {names}")
    packets.sort(key=lambda p: p[0])
    t_first = np.array([p[0] for p in packets if p[1] == packets[0][1]])
    period = float(np.median(np.diff(t_first))) if len(t_first) > 1 else 1e9 / 60
    frames: list[list] = []
    t0 = None
    for t, c, pk in packets:
        if t0 is None or t - t0 > 0.5 * period:
            frames.append([None] * len(names))
            t0 = t
        frames[-1][c] = pk
    Kn = N_MARKERS if K is None else K
    uv = np.full((len(frames), len(names), Kn, 2), np.nan)
    for f, row in enumerate(frames):
        for c, pk in enumerate(row):
            if pk is None:
                continue
            if K is None:
                _fill_labelled(uv[f, c], pk)
            else:
                from samba_common.wire import FLAG_MERGED

                keep = (pk.flags & FLAG_MERGED) == 0
                if int(keep.sum()) == K and len(pk.uv) == K:
                    uv[f, c] = pk.uv.astype(float)
    return uv


def read_npz(path: Path, names: list[str], K: int | None) -> np.ndarray:
    """A simulated take (``samba-calibrate simulate``) -> (F, C, K, 2) in ``names`` order."""
    try:
        with np.load(path, allow_pickle=False) as z:
            uv = z["uv"]
            file_names = [str(n) for n in z["camera_names"]]
    except (OSError, KeyError, ValueError) as exc:
        raise TakeError(f"{path}: not a calibration take npz ({exc})") from None
    missing = [n for n in names if n not in file_names]
    if missing:
        raise TakeError(f"{path}: no observations of camera(s) {missing}; file has {file_names}")
    uv = uv[:, [file_names.index(n) for n in names]].astype(float)
    if K is not None and uv.shape[2] != K:
        raise TakeError(f"{path}: take has {uv.shape[2]} markers per view, expected {K}")
    return uv


def read_take(take: str | os.PathLike, names: list[str], K: int | None, progress=None, rig=None,
              fps: float = 60.0) -> np.ndarray:
    """Dispatch on the kind of TAKE (directory of videos, .mcap, .npz); see module doc.
    ``rig`` and ``fps`` only matter for labelled videos (mote pipeline)."""
    p = Path(take)
    if not p.exists():
        raise TakeError(f"{p}: not found")
    if p.is_dir():
        if (p / "take.npz").exists() and not any(p.glob(f"{names[0]}.*")):
            return read_npz(p / "take.npz", names, K)  # a `samba-calibrate simulate` folder
        return read_videos(p, names, K, progress, rig, fps)
    if p.suffix == ".mcap":
        return read_mcap(p, names, K)
    if p.suffix == ".npz":
        return read_npz(p, names, K)
    raise TakeError(f"{p}: expected a directory of videos, a .mcap recording or a .npz take")
