"""Score a mote's labels against the simulator's 2D ground truth (truth2d.npz)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba_common.wire import FLAG_MERGED, FLAG_TRACKED, MarkerPacket


@dataclass
class LabelScore:
    """frames: frames scored; bad_frames: frames with at least one wrong label; records:
    labelled, measured, unmerged records; wrong: of those, wrongly labelled; coverage: fraction
    of visible markers reported as labelled, measured and unmerged; first_bad: frame or -1."""

    frames: int
    bad_frames: int
    records: int
    wrong: int
    coverage: float
    first_bad: int

    @property
    def frame_accuracy(self) -> float:
        return 1.0 - self.bad_frames / max(self.frames, 1)


def record_correct(label: int, uv: np.ndarray, truth_uv: np.ndarray, visible: np.ndarray, tol: float = 1.5,
                   margin: float = 0.75) -> bool:
    """A labelled record is correct if it lies within ``tol`` px of its own marker, or its own
    marker is (within ``margin`` px) the nearest visible marker (a blob of touching markers)."""
    d = np.linalg.norm(truth_uv - uv, axis=1)
    d[~visible] = np.inf
    if not np.isfinite(d[label]):
        return False
    return bool(d[label] <= tol or d[label] <= d.min() + margin)


def score_labels(packets: list[MarkerPacket], truth_uv: np.ndarray, visible: np.ndarray,
                 start: int = 0) -> LabelScore:
    """packets: one per frame; truth_uv: (F, 8, 2) px; visible: (F, 8) bool; frames before
    ``start`` are skipped (e.g. the T-pose lead-in)."""
    bad = rec = wrong = seen = shown = 0
    first_bad = -1
    for f in range(start, len(packets)):
        p = packets[f]
        ok = True
        for lab, uv, fl in zip(p.labels, p.uv, p.flags):
            if lab > 7 or not fl & FLAG_TRACKED or fl & FLAG_MERGED:
                continue
            rec += 1
            if not record_correct(int(lab), uv, truth_uv[f], visible[f]):
                wrong += 1
                ok = False
            else:
                shown += 1
        seen += int(visible[f].sum())
        if not ok:
            bad += 1
            if first_bad < 0:
                first_bad = f
    return LabelScore(len(packets) - start, bad, rec, wrong, shown / max(seen, 1), first_bad)
