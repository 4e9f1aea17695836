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
from numba import njit

from samba_common.wire import FLAG_LOST, FLAG_MERGED, FLAG_PREDICTED, UNLABELLED

__all__ = ["ViewBlobs", "median_rows", "percentile", "view_blobs", "warm_up"]


def percentile(x: np.ndarray, q: float) -> float:
    """np.percentile(x, q) (linear interpolation) of a small 1-D array without NaN, about 20x
    faster than numpy's general routine on the few values of one frame."""
    s = np.sort(np.asarray(x, float))
    pos = q / 100.0 * (len(s) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(s) - 1)
    return float(s[lo] + (pos - lo) * (s[hi] - s[lo]))


def median_rows(x: np.ndarray) -> np.ndarray:
    """np.median(x, axis=0) of a small (N, D) array without NaN (N >= 1), several times faster
    than numpy's general routine: (D,)."""
    s = np.sort(x, axis=0)
    n = len(s)
    return 0.5 * (s[(n - 1) // 2] + s[n // 2])


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
    uv = np.ascontiguousarray(np.asarray(packet.uv, float).reshape(-1, 2))
    area = np.ascontiguousarray(packet.area, float)
    rows, merged, hint = _distinct_blobs(np.ascontiguousarray(packet.flags, np.int64), area, uv,
                                         np.ascontiguousarray(packet.labels, np.int64), float(merged_area_ratio),
                                         int(max_blobs))
    if not len(rows):
        return ViewBlobs.empty()
    return ViewBlobs(uv[rows], np.where(merged, 2, 1), np.sqrt(area[rows] / np.pi), hint,
                     np.asarray(packet.moments, float).reshape(-1, 3)[rows])


def warm_up() -> None:
    """Compile :func:`view_blobs`' kernel (the first run on a machine) or load it from disk now,
    not on the first live frame."""
    _distinct_blobs(np.zeros(1, np.int64), np.ones(1), np.zeros((1, 2)), np.zeros(1, np.int64), 1.5, 40)


@njit(cache=True)
def _distinct_blobs(flags: np.ndarray, area: np.ndarray, uv: np.ndarray, labels: np.ndarray, merged_area_ratio: float,
                    max_blobs: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The work of :func:`view_blobs` on a packet's records (flags, area, labels (N,), uv (N, 2)
    px): per distinct measured blob, in order of position, (U,) the record that first gave it,
    (U,) whether it is merged and (U,) the mote's label (-1: none or ambiguous)."""
    measured = np.flatnonzero(((flags & (FLAG_PREDICTED | FLAG_LOST)) == 0) & (area > 0)
                              & np.isfinite(uv[:, 0]) & np.isfinite(uv[:, 1]))
    M = len(measured)
    # one row per distinct blob: the tracker repeats a merged blob once per marker it holds
    key = np.empty(M, np.int64)
    for i in range(M):
        r = measured[i]
        key[i] = np.int64(np.round(uv[r, 0] * 1000.0)) * (1 << 32) + np.int64(np.round(uv[r, 1] * 1000.0))
    order = np.argsort(key, kind="mergesort")  # stable: the first record of a position comes first
    group = np.empty(M, np.int64)  # each record's distinct blob
    first = np.empty(M, np.int64)  # each distinct blob's first record (index into measured)
    U = 0
    for j in range(M):
        i = order[j]
        if j == 0 or key[i] != key[order[j - 1]]:
            first[U] = i
            U += 1
        group[i] = U - 1
    first = first[:U]
    count = np.zeros(U, np.int64)
    merged = np.zeros(U, np.bool_)
    for i in range(M):
        count[group[i]] += 1
        merged[group[i]] |= (flags[measured[i]] & FLAG_MERGED) != 0
    merged |= count > 1
    hint = np.full(U, -1, np.int64)
    for i in range(M):  # a blob holding two labelled markers keeps no single hint
        lab = labels[measured[i]]
        if lab != UNLABELLED and lab < 8:
            j = group[i]
            hint[j] = lab if (hint[j] == -1 or hint[j] == lab) and count[j] == 1 else -2
    for j in range(U):
        if hint[j] == -2:
            hint[j] = -1
    a = area[measured[first]]
    if U >= 4:  # the view's typical single-marker area: the 40th percentile (see percentile)
        s = np.sort(a)
        pos = 40.0 / 100.0 * (U - 1)
        lo = int(pos)
        hi = min(lo + 1, U - 1)
        merged |= a >= merged_area_ratio * (s[lo] + (pos - lo) * (s[hi] - s[lo]))
    if U > max_blobs:
        keep = np.sort(np.argsort(a, kind="mergesort")[:max_blobs])
        first, merged, hint = first[keep], merged[keep], hint[keep]
    return measured[first], merged, hint
