"""The measured blobs of one frame, per view, from the motes' packets.

A packet holds measured records (labelled or not), the tracker's predictions (not measured:
skipped here) and, for two markers in one blob, the same centroid twice. What the 3D stage
needs per view is each distinct measured blob once, how many markers it may stand for (2 when
the mote flags it merged or its area is about that of two markers) and the mote's label as a
hint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba_common.wire import FLAG_LOST, FLAG_MERGED, FLAG_PREDICTED, UNLABELLED

__all__ = ["ViewBlobs", "percentile", "view_blobs"]


def percentile(x: np.ndarray, q: float) -> float:
    """np.percentile(x, q) (linear interpolation) of a small 1-D array without NaN, about 20x
    faster than numpy's general routine on the few values of one frame."""
    s = np.sort(np.asarray(x, float))
    pos = q / 100.0 * (len(s) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(s) - 1)
    return float(s[lo] + (pos - lo) * (s[hi] - s[lo]))


@dataclass
class ViewBlobs:
    """Distinct measured blobs of one view.

    uv: (N, 2) raw pixels; capacity: (N,) int, markers the blob may stand for (1, or 2 when
    merged); radius: (N,) px, radius of a disk of the blob's area; hint: (N,) int, the mote's
    label (0..7) or -1; moments: (N, 3) px^2 second central moments (var_u, cov_uv, var_v), NaN
    where the mote sent none.
    """

    uv: np.ndarray
    capacity: np.ndarray
    radius: np.ndarray
    hint: np.ndarray
    moments: np.ndarray

    def __len__(self) -> int:
        return len(self.uv)

    @staticmethod
    def empty() -> "ViewBlobs":
        return ViewBlobs(np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64), np.zeros((0, 3)))


def view_blobs(packet, merged_area_ratio: float = 1.5, max_blobs: int = 40) -> ViewBlobs:
    """ViewBlobs of one MarkerPacket (or an empty one for None).

    merged_area_ratio: a blob whose area is this many times the view's typical single-marker
    area (the 40th percentile of its blob areas; most blobs are single markers) counts as
    merged (needs >= 4 blobs). max_blobs: beyond this many blobs the largest
    (lamps, reflections of large objects) are dropped, which bounds the cost of the 3D stage.
    """
    if packet is None or len(packet) == 0:
        return ViewBlobs.empty()
    flags = np.asarray(packet.flags, np.int64)
    area = np.asarray(packet.area, float)
    uv = np.asarray(packet.uv, float).reshape(-1, 2)
    measured = ((flags & (FLAG_PREDICTED | FLAG_LOST)) == 0) & (area > 0) & np.isfinite(uv).all(axis=1)
    if not measured.any():
        return ViewBlobs.empty()
    labels = np.asarray(packet.labels, np.int64)[measured]
    flags, area, uv = flags[measured], area[measured], uv[measured]
    moments = np.asarray(packet.moments, float).reshape(-1, 3)[measured]
    # one row per distinct blob: the tracker repeats a merged blob once per marker it holds
    key = np.round(uv * 1000.0).astype(np.int64)
    key = key[:, 0] * (1 << 32) + key[:, 1]  # one integer per position (1-D unique is much faster)
    _, first, inverse, count = np.unique(key, return_index=True, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    merged = np.zeros(len(first), bool)
    np.logical_or.at(merged, inverse, (flags & FLAG_MERGED) != 0)
    merged |= count > 1
    hint = np.full(len(first), -1, np.int64)
    for i, lab in enumerate(labels):  # a blob holding two labelled markers keeps no single hint
        if lab != UNLABELLED and lab < 8:
            j = inverse[i]
            hint[j] = lab if hint[j] in (-1, lab) and count[j] == 1 else -2
    hint[hint == -2] = -1
    a = area[first]
    if len(a) >= 4:
        merged |= a >= merged_area_ratio * percentile(a, 40.0)
    if len(first) > max_blobs:
        keep = np.sort(np.argsort(a, kind="stable")[:max_blobs])
        first, merged, hint, a = first[keep], merged[keep], hint[keep], a[keep]
    return ViewBlobs(uv[first], np.where(merged, 2, 1), np.sqrt(a / np.pi), hint, moments[first])
