"""3D-guided labelling: give labels to blobs the motes left unlabelled, from the predicted pose.

A mote labels its 8 markers by 2D tracking alone. After two markers merge (knees passing in a
walk, a wrist passing the hip) it rightly withholds the label of the blob whose identity is in
doubt, and without help it may not get it back until the next standard pose. The server knows
much more: the skeleton of the last frames. :class:`GuidedLabeller` predicts the 8 markers in
3D (constant velocity from the last two solved poses), projects them into every camera and
labels the **unlabelled** blob nearest each prediction when it is unambiguous: within
``gate_px`` of the prediction, no other unlabelled blob within ``ratio`` times that distance,
and not wanted by another marker. Labels the motes did send are kept; label swaps are the
swap repair's job (:mod:`samba_server.swap`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from samba_common.calib import CameraRig
from samba_common.skeleton import MARKER_JOINT
from samba_common.wire import FLAG_MERGED, UNLABELLED


@dataclass(frozen=True)
class RelabelConfig:
    """``[relabel]`` in configs/server.toml.

    enabled: use the predicted pose to label unlabelled blobs; gate_px: largest distance
    (pixels) between a predicted marker and its blob; ratio: the runner-up blob must be this
    many times farther; max_age: the prediction is used up to this long (s) after the last
    solved pose.
    """

    enabled: bool = True
    gate_px: float = 4.0
    ratio: float = 1.5
    max_age: float = 0.25


class GuidedLabeller:
    """Keeps the last two solved poses and labels unlabelled blobs from their prediction."""

    def __init__(self, rig: CameraRig, config: RelabelConfig | None = None):
        self.rig = rig
        self.config = config or RelabelConfig()
        self._poses: list[tuple[float, np.ndarray]] = []  # (t s, (8, 3) markers of solved joints)
        self.labelled = 0  #: labels added so far

    def observe(self, t: float, joints: np.ndarray) -> None:
        """Remember a solved pose: t seconds, joints (13, 3) metres (NaN frames are ignored)."""
        if np.all(np.isfinite(joints)):
            self._poses = (self._poses + [(t, joints[list(MARKER_JOINT)].copy())])[-2:]

    def predict(self, t: float) -> np.ndarray | None:
        """Predicted markers (8, 3) at time t, or None without a recent solved pose."""
        if not self._poses or t - self._poses[-1][0] > self.config.max_age:
            return None
        if len(self._poses) == 1:
            return self._poses[-1][1]
        (t0, m0), (t1, m1) = self._poses
        if t1 <= t0:
            return m1
        return m1 + (m1 - m0) * (t - t1) / (t1 - t0)

    def fill(self, uv: np.ndarray, packets: list, t: float) -> np.ndarray:
        """Add labels to ``uv`` (C, 8, 2) pixels (NaN = no label) from unlabelled blobs.

        packets: per camera (rig order) the MarkerPacket of this frame or None. Returns the
        filled copy of uv.
        """
        pred = self.predict(t) if self.config.enabled else None
        if pred is None:
            return uv
        out = uv.copy()
        cfg = self.config
        for c, pkt in enumerate(packets):
            if pkt is None:
                continue
            free = (np.asarray(pkt.labels) == UNLABELLED) & ((np.asarray(pkt.flags) & FLAG_MERGED) == 0)
            if not free.any():
                continue
            blobs = np.asarray(pkt.uv, dtype=float)[free]                    # (B, 2)
            want = np.flatnonzero(~np.isfinite(out[c]).all(axis=1))          # markers without a label
            if want.size == 0:
                continue
            proj = self.rig.cameras[c].project(pred[want])                   # (W, 2)
            d = np.linalg.norm(proj[:, None, :] - blobs[None, :, :], axis=2)  # (W, B)
            d[~np.isfinite(d)] = np.inf
            choice: dict[int, int] = {}
            for w in range(len(want)):
                order = np.argsort(d[w])
                best = order[0]
                second = d[w, order[1]] if len(order) > 1 else np.inf
                if d[w, best] <= cfg.gate_px and second >= cfg.ratio * d[w, best]:
                    choice[w] = int(best)
            claimed = np.bincount(list(choice.values()), minlength=len(blobs)) if choice else None
            for w, b in choice.items():
                if claimed[b] == 1:  # a blob two markers want stays unlabelled
                    out[c, want[w]] = blobs[b]
                    self.labelled += 1
        return out


