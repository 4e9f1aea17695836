"""Blob detection on 8-bit grey frames: threshold, contours, filters, grey-weighted centroids.

Pipeline per frame (``Detector.detect``):

1. threshold: fixed, or automatic (background median + noise MAD from a sub-sampled frame
   and the frame maximum, refreshed every ``auto_every`` frames);
2. ``cv2.findContours`` on the binary image (external contours = connected blobs);
3. filters: pixel count in ``[min_area, max_area]`` (specks, large reflections), bounding box
   aspect ratio <= ``max_aspect`` and fill ratio >= ``min_fill`` (streaks, rings);
4. intensity-weighted centroid in a padded ROI around each blob, weights = grey level minus a
   floor (background + ``floor_sigmas`` x noise), which removes the ~0.2 px bias of binary
   centroids;
5. static distractor mask: blobs that sit still (within ``static_radius`` px) for
   ``static_frames`` frames in a row are remembered as distractors (lamps, reflections) and
   dropped until they disappear for ``static_forget`` frames.

Pixel coordinates: origin at the centre of the top-left pixel, u right, v down.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DetectConfig:
    """Detection settings (``[detect]`` in configs/mote.toml)."""

    threshold_mode: str = "auto"  #: "auto" or "fixed"
    threshold: int = 128  #: fixed threshold (grey level), also the start value in auto mode
    auto_sigmas: float = 8.0  #: auto: at least background + this many noise sigmas
    auto_fraction: float = 0.45  #: auto: at least background + this fraction of (max - background)
    auto_min: int = 30
    auto_max: int = 230
    auto_every: int = 15  #: auto: refresh the statistics every this many frames
    min_area: int = 2  #: pixels above threshold
    max_area: int = 150  #: at 160x120 a marker is <= ~40 px, two merged <= ~90
    max_aspect: float = 3.5  #: bounding-box long side / short side
    min_fill: float = 0.25  #: pixels above threshold / bounding-box area
    pad: int = 2  #: ROI padding around the blob for the weighted centroid (px)
    floor_sigmas: float = 2.0  #: weight floor above background, in noise sigmas
    max_blobs: int = 64  #: keep at most this many (largest) blobs
    static_mask: bool = True
    static_frames: int = 600  #: frames a blob must stay still to become a distractor
    static_radius: float = 0.35  #: px
    static_forget: int = 30  #: frames a distractor may be absent before it is forgotten
    static_every: int = 4  #: learn the static mask every this many frames (the mask applies to all)

    def __post_init__(self) -> None:
        if self.threshold_mode not in ("auto", "fixed"):
            raise ValueError(f"threshold_mode must be 'auto' or 'fixed', got {self.threshold_mode!r}")
        if not 1 <= self.threshold <= 254:
            raise ValueError(f"threshold must be 1..254, got {self.threshold}")
        if self.min_area < 1 or self.max_area < self.min_area:
            raise ValueError("need 1 <= min_area <= max_area")


@dataclass
class Detections:
    """Blobs of one frame. uv: (N, 2) float32 px; area: (N,) int32 px above threshold;
    size: (N, 2) int32 bounding box (w, h); cov: (N, 3) float32 intensity-weighted second
    central moments (var_u, cov_uv, var_v) in px^2."""

    uv: np.ndarray
    area: np.ndarray
    size: np.ndarray
    threshold: int
    cov: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.uv)

    @classmethod
    def empty(cls, threshold: int) -> "Detections":
        return cls(np.zeros((0, 2), np.float32), np.zeros(0, np.int32), np.zeros((0, 2), np.int32),
                   threshold, np.zeros((0, 3), np.float32))


_LEVELS = np.arange(256)  # grey levels of uint8 frames


def _hist_median(hist: np.ndarray) -> float:
    """Median of the values 0..len(hist)-1 counted by hist (same value as np.median: the
    mean of the two middle values for an even count)."""
    c = np.cumsum(hist)
    n = int(c[-1])
    lo, hi = np.searchsorted(c, [(n - 1) // 2, n // 2], side="right").tolist()
    return float(hi) if lo == hi else (lo + hi) / 2.0


class StaticMask:
    """Learns blobs that never move and masks them. Positions in px."""

    def __init__(self, frames: int, radius: float, forget: int) -> None:
        self.frames, self.radius, self.forget = frames, radius, forget
        self.pos = np.zeros((0, 2))  # candidate positions (running mean)
        self.count = np.zeros(0, np.int64)  # consecutive frames seen still
        self.absent = np.zeros(0, np.int64)  # consecutive frames not seen
        self._static: list | None = None  # cache of static.tolist()

    @property
    def static(self) -> np.ndarray:
        """(K, 2) positions currently masked."""
        return self.pos[self.count >= self.frames]

    def apply(self, uv: np.ndarray) -> np.ndarray:
        """(N,) bool keep-mask for blobs uv (N, 2) against the learnt distractors only."""
        return np.array(self.apply_list(uv.tolist()), bool).reshape(len(uv))

    def apply_list(self, uv: list) -> list[bool]:
        """apply() on N [u, v] pairs as plain Python floats (cheaper for a few blobs per frame)."""
        if self._static is None:  # learnt positions, cached until the next update()
            self._static = self.static.tolist()
        st = self._static
        if not st or not uv:
            return [True] * len(uv)
        r2 = self.radius ** 2
        keep = []
        for u, v in uv:
            d2 = min((u - su) * (u - su) + (v - sv) * (v - sv) for su, sv in st)
            keep.append(d2 > r2)
        return keep

    def update(self, uv: np.ndarray) -> np.ndarray:
        """Learn from this frame's blobs (N, 2); returns a (N,) bool keep-mask (False = distractor)."""
        self._static = None
        n = len(uv)
        if len(self.pos) * n <= 1024:  # the usual few blobs: plain Python floats are cheaper
            return self._update_small(uv)
        keep = np.ones(n, bool)
        matched = np.zeros(len(self.pos), bool)
        new = np.ones(n, bool)
        if len(self.pos) and n:
            d2 = ((uv[:, None, :] - self.pos[None, :, :]) ** 2).sum(-1)
            j = d2.argmin(1)
            close = d2[np.arange(n), j] <= self.radius ** 2
            idx = np.flatnonzero(close)
            k = j[idx]
            matched[k] = True
            learnt = self.count[k] >= self.frames
            keep[idx[learnt]] = False
            ku, iu = k[~learnt], idx[~learnt]
            c = np.minimum(self.count[ku], 50)[:, None]
            self.pos[ku] = (self.pos[ku] * c + uv[iu]) / (c + 1)
            self.count[k] += 1
            new = ~close
        self.absent[matched] = 0
        self.absent[~matched] += 1
        # a still-learning candidate that was missed or moved starts over; a learnt one is
        # forgotten only after `forget` absent updates
        alive = np.where(self.count >= self.frames, self.absent <= self.forget, matched)
        if not alive.all():
            self.pos, self.count, self.absent = self.pos[alive], self.count[alive], self.absent[alive]
        if new.any():
            m = int(new.sum())
            self.pos = np.vstack([self.pos, uv[new]])
            self.count = np.concatenate([self.count, np.ones(m, np.int64)])
            self.absent = np.concatenate([self.absent, np.zeros(m, np.int64)])
        if len(self.pos) > 256:  # bound memory under heavy noise
            order = np.argsort(-self.count)[:256]
            self.pos, self.count, self.absent = self.pos[order], self.count[order], self.absent[order]
        return keep


    def _update_small(self, uv: np.ndarray) -> np.ndarray:
        """update() on Python lists, for few blobs and candidates (same results, fewer numpy calls)."""
        uvl = uv.tolist()
        pos, count, absent = self.pos.tolist(), self.count.tolist(), self.absent.tolist()
        frames, r2 = self.frames, self.radius ** 2
        n, K = len(uvl), len(pos)
        keep = [True] * n
        matched = [False] * K
        new = [True] * n
        if K and n:
            moves = []  # (candidate, new position), computed from the old positions
            bumped = set()
            for i, (u, v) in enumerate(uvl):
                best, j = math.inf, 0
                for q, (pu, pv) in enumerate(pos):
                    d2 = (u - pu) * (u - pu) + (v - pv) * (v - pv)
                    if d2 < best:
                        best, j = d2, q
                if best <= r2:
                    new[i] = False
                    matched[j] = True
                    bumped.add(j)
                    if count[j] >= frames:
                        keep[i] = False
                    else:
                        c = min(count[j], 50)
                        moves.append((j, [(pos[j][0] * c + u) / (c + 1), (pos[j][1] * c + v) / (c + 1)]))
            for j, p in moves:  # (several blobs on one candidate: the last one wins)
                pos[j] = p
            for j in bumped:
                count[j] += 1
        forget = self.forget
        for q in range(K):
            absent[q] = 0 if matched[q] else absent[q] + 1
        alive = [(absent[q] <= forget) if count[q] >= frames else matched[q] for q in range(K)]
        if not all(alive):
            pos = [p for p, a in zip(pos, alive) if a]
            count = [c for c, a in zip(count, alive) if a]
            absent = [b for b, a in zip(absent, alive) if a]
        for i in range(n):
            if new[i]:
                pos.append(uvl[i])
                count.append(1)
                absent.append(0)
        self.pos = np.array(pos, np.float64).reshape(-1, 2)
        self.count = np.array(count, np.int64)
        self.absent = np.array(absent, np.int64)
        if len(self.pos) > 256:  # bound memory under heavy noise
            order = np.argsort(-self.count)[:256]
            self.pos, self.count, self.absent = self.pos[order], self.count[order], self.absent[order]
        return np.array(keep, bool)


class Detector:
    """Stateful blob detector (auto threshold statistics, static mask). Not thread-safe."""

    def __init__(self, config: DetectConfig | None = None) -> None:
        self.cfg = config or DetectConfig()
        self.threshold = int(self.cfg.threshold)
        self.background = 0.0
        self.noise = 2.0
        self._frame_no = 0
        every = max(self.cfg.static_every, 1)
        self.mask = StaticMask(max(self.cfg.static_frames // every, 1), self.cfg.static_radius,
                               max(self.cfg.static_forget // every, 1))
        self.masked = 0  #: blobs dropped by the static mask, total
        self._kernel = np.ones((2 * self.cfg.pad + 1, 2 * self.cfg.pad + 1), np.uint8)

    def _update_threshold(self, img: np.ndarray) -> None:
        # medians from a 256-bin histogram (exactly np.median's values, several times faster)
        hist = np.bincount(img[::4, ::4].ravel(), minlength=256)
        bg = _hist_median(hist)
        # |grey - int(bg)| histogram: bin d gathers the grey levels int(bg) +- d
        dev = np.bincount(np.abs(_LEVELS - int(bg)), weights=hist, minlength=256)
        mad = _hist_median(dev)
        self.background = bg
        self.noise = max(1.4826 * mad, 0.5)
        if self.cfg.threshold_mode == "auto":
            peak = float(img.max())
            thr = max(bg + self.cfg.auto_sigmas * self.noise, bg + self.cfg.auto_fraction * (peak - bg))
            self.threshold = int(min(max(round(thr), self.cfg.auto_min), self.cfg.auto_max))

    def detect(self, img: np.ndarray) -> Detections:
        """img: (H, W) uint8 grey frame -> Detections (after filters and static mask)."""
        if img.ndim != 2 or img.dtype != np.uint8:
            raise ValueError(f"expected a (H, W) uint8 frame, got {img.shape} {img.dtype}")
        cfg = self.cfg
        if self._frame_no % cfg.auto_every == 0:
            self._update_threshold(img)
        self._frame_no += 1
        thr = self.threshold
        _, binary = cv2.threshold(img, thr - 1, 255, cv2.THRESH_BINARY)  # >= thr
        contours, _ = cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if not contours:
            return Detections.empty(thr)
        if len(contours) > 4 * cfg.max_blobs:
            log.debug("%d contours: frame is noisy, keeping the first %d", len(contours), 4 * cfg.max_blobs)
            contours = contours[: 4 * cfg.max_blobs]
        h, w = img.shape
        floor = int(min(self.background + cfg.floor_sigmas * self.noise, thr - 1))
        pad = cfg.pad
        min_area, max_area, max_aspect, min_fill = cfg.min_area, cfg.max_area, cfg.max_aspect, cfg.min_fill
        # centroid weights for the whole frame at once (one call instead of one per blob)
        full = cv2.subtract(img, floor)
        bounding_rect, count_nonzero, moments = cv2.boundingRect, cv2.countNonZero, cv2.moments
        kernel = self._kernel
        rows = []
        speck = min_area > 1  # one-point contours (1x1 px) can be skipped unseen
        for c in contours:
            if speck and len(c) == 1:
                continue
            x, y, bw, bh = bounding_rect(c)
            if bw * bh < min_area or (bw > max_aspect * bh + 1 or bh > max_aspect * bw + 1):
                continue
            area = count_nonzero(binary[y:y + bh, x:x + bw])
            # (the blob's own pixel count below is <= this count, so the fill test can go first)
            if area > max_area or area < min_area or area < min_fill * bw * bh:
                continue
            x0, y0 = x - pad if x > pad else 0, y - pad if y > pad else 0
            x1, y1 = min(x + bw + pad, w), min(y + bh + pad, h)
            weights = full[y0:y1, x0:x1]
            if count_nonzero(binary[y0:y1, x0:x1]) != area:
                # another blob reaches into the padded ROI: weight only this blob's pixels
                # and the background around them
                # (components of the ROI alone: the blob lies inside its box, so its ROI component
                # is exactly the blob; a contour point is one of its pixels)
                lab = cv2.connectedComponents(binary[y0:y1, x0:x1], connectivity=8)[1]
                own = (lab == lab[c[0, 0, 1] - y0, c[0, 0, 0] - x0]).astype(np.uint8)
                area = count_nonzero(own)
                near = cv2.dilate(own, kernel) & ((lab == 0) | (own > 0)).astype(np.uint8)
                weights = weights * near
                if area < min_area or area < min_fill * bw * bh:
                    continue
            m = moments(weights)
            m00 = m["m00"]
            if m00 <= 0:
                continue
            rows.append((x0 + m["m10"] / m00, y0 + m["m01"] / m00, area, bw, bh,
                         m["mu20"] / m00, m["mu11"] / m00, m["mu02"] / m00))
        if not rows:
            return Detections.empty(thr)
        a = np.asarray(rows, dtype=np.float64)
        if len(a) > cfg.max_blobs:
            a = a[np.argsort(-a[:, 2])[: cfg.max_blobs]]
        if cfg.static_mask:
            # learn every `static_every` frames (counts are in learning steps), mask every frame
            if self._frame_no % cfg.static_every == 0:
                keep = self.mask.update(a[:, :2])
                dropped = int((~keep).sum())
            else:
                keep = self.mask.apply_list(a[:, :2].tolist())
                dropped = len(keep) - sum(keep)
            if dropped:
                self.masked += dropped
                a = a[keep]
        return Detections(a[:, :2].astype(np.float32), a[:, 2].astype(np.int32), a[:, 3:5].astype(np.int32),
                          thr, a[:, 5:8].astype(np.float32))
