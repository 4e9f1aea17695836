"""Read a BVH file and run forward kinematics: the check that an exported BVH means what it says.

Generic (any channel order, position channels on any joint), so it also reads other tools'
files; :func:`fk_positions` maps the joints of :mod:`samba_server.export.bvh` back to the 13
Samba joints in the Samba world frame.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from samba_common.skeleton import JOINT_NAMES


class BvhParseError(ValueError):
    """The file is not a BVH this reader understands (message names the file)."""


@dataclass
class BvhJoint:
    """name; parent index (-1 for the root); offset (3,) file units; channel names; first
    column of its channels in the motion table."""

    name: str
    parent: int
    offset: np.ndarray
    channels: list[str] = field(default_factory=list)
    first: int = 0


@dataclass
class BvhFile:
    """joints in file order (End Sites excluded); motion (F, C) channel values; frame_time s."""

    joints: list[BvhJoint]
    motion: np.ndarray
    frame_time: float

    def index(self, name: str) -> int:
        for k, j in enumerate(self.joints):
            if j.name == name:
                return k
        raise KeyError(name)


def parse_bvh(path: str | os.PathLike) -> BvhFile:
    """Parse HIERARCHY and MOTION. Raises BvhParseError naming the file on malformed input."""
    try:
        with open(path, encoding="ascii", errors="replace") as fh:
            tok = fh.read().split()
    except OSError as exc:
        raise BvhParseError(f"{path}: cannot read ({exc.strerror})") from None
    joints: list[BvhJoint] = []
    stack: list[int | None] = []  # None marks an End Site block
    pending: int | None = None
    n_chan, i = 0, 1
    try:
        if not tok or tok[0] != "HIERARCHY":
            raise BvhParseError(f"{path}: does not start with HIERARCHY")
        while tok[i] != "MOTION":
            t = tok[i]
            if t in ("ROOT", "JOINT"):
                parent = next((s for s in reversed(stack) if s is not None), -1)
                joints.append(BvhJoint(tok[i + 1], parent, np.zeros(3)))
                pending, i = len(joints) - 1, i + 2
            elif t == "End":
                pending, i = None, i + 2
            elif t == "{":
                stack.append(pending)
                i += 1
            elif t == "}":
                stack.pop()
                i += 1
            elif t == "OFFSET":
                if stack[-1] is not None:
                    joints[stack[-1]].offset = np.array(tok[i + 1:i + 4], dtype=float)
                i += 4
            elif t == "CHANNELS":
                k = int(tok[i + 1])
                j = joints[stack[-1]]  # type: ignore[index]
                j.channels, j.first = tok[i + 2:i + 2 + k], n_chan
                n_chan, i = n_chan + k, i + 2 + k
            else:
                raise BvhParseError(f"{path}: unexpected {t!r} in HIERARCHY")
        if tok[i + 1] != "Frames:" or tok[i + 3] != "Frame" or tok[i + 4] != "Time:":
            raise BvhParseError(f"{path}: MOTION header is not 'Frames: N' / 'Frame Time: T'")
        n_frames, frame_time = int(tok[i + 2]), float(tok[i + 5])
        values = np.array(tok[i + 6:], dtype=float)
    except (IndexError, ValueError, TypeError) as exc:
        if isinstance(exc, BvhParseError):
            raise
        raise BvhParseError(f"{path}: malformed BVH ({exc})") from None
    if values.size != n_frames * n_chan:
        raise BvhParseError(f"{path}: {values.size} motion values, expected {n_frames} x {n_chan}")
    return BvhFile(joints, values.reshape(n_frames, n_chan), frame_time)


def _rot(axis: str, deg: np.ndarray) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    k = "XYZ".index(axis)
    i, j = (k + 1) % 3, (k + 2) % 3
    R[:, k, k] = 1.0
    R[:, i, i], R[:, j, j], R[:, j, i], R[:, i, j] = c, c, s, -s
    return R


def forward_kinematics(bvh: BvhFile) -> np.ndarray:
    """Global joint positions (F, n_joints, 3) in file units; rotations compose in channel order."""
    F = bvh.motion.shape[0]
    pos = np.zeros((F, len(bvh.joints), 3))
    rot = np.zeros((F, len(bvh.joints), 3, 3))
    for k, j in enumerate(bvh.joints):
        t = np.tile(j.offset, (F, 1))
        R = np.tile(np.eye(3), (F, 1, 1))
        for c, ch in enumerate(j.channels):
            v = bvh.motion[:, j.first + c]
            if ch.endswith("position"):
                t[:, "XYZ".index(ch[0].upper())] += v
            else:
                R = R @ _rot(ch[0].upper(), v)
        if j.parent < 0:
            pos[:, k], rot[:, k] = t, R
        else:
            pos[:, k] = pos[:, j.parent] + np.einsum("fij,fj->fi", rot[:, j.parent], t)
            rot[:, k] = rot[:, j.parent] @ R
    return pos


def fk_positions(bvh: BvhFile) -> np.ndarray:
    """The 13 Samba joints (F, 13, 3) in world metres (Z up) from a Samba-exported BVH."""
    from .bvh import BVH_TO_SAMBA, TO_BVH

    samba_to_bvh = {v: k for k, v in BVH_TO_SAMBA.items()}
    g = forward_kinematics(bvh)
    try:
        cols = [bvh.index(samba_to_bvh[n]) for n in JOINT_NAMES]
    except KeyError as exc:
        raise BvhParseError(f"not a Samba BVH: no joint {exc}") from None
    return g[:, cols] @ np.linalg.inv(TO_BVH).T
