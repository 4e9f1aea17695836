"""Pose wire format: what the server publishes on ``samba/{session}/pose`` (binary) and
``samba/{session}/pose/json`` (JSON), and records on the ``/pose`` MCAP channel.

Binary, version 3, little endian::

    header "<4sBBHIqffBBHfBB" (38 bytes)
        magic       4s  b"SMBP"
        version     B   3 (version 2, without joint bounds, and version 1, also without the
                        last three header fields, are still read)
        flags       B   FLAG_* bit set
        n_joints    H   13 (JOINT_NAMES order)
        seq         I   pose counter (wraps at 2**32)
        t_ns        q   frame capture time, ns since the Unix epoch, server clock
        latency_ms  f   capture -> publish on the server, milliseconds
        residual_m  f   solver residual, metres (NaN when unsolved)
        n_markers   B   markers used by the solver (triangulated this frame)
        n_views     B   motes that contributed a packet to the frame
        marker_mask H   bit i set = marker i (MARKER_NAMES order) triangulated
        margin_m    f   label margin, metres: how much worse the runner-up naming of the
                        least sure marker was (NaN when no marker was named)
        label_mode  B   LABEL_MODES index: 0 lost, 1 tracking, 2 identified (named from scratch)
        reserved    B   0
    joints   n_joints x 3 float32, world metres Z up; NaN when unsolved
    markers  8 x 3 float32 triangulated markers (NaN = missing), only if FLAG_MARKERS
    bounds   n_joints float32 per-joint error bounds, metres (inf = unknown), only if
             FLAG_BOUNDS: how far each joint may be from the truth; below 0.2 m a joint is
             confident (samba_server.recon.bounds)

JSON variant (UTF-8, one object; NaN becomes ``null``)::

    {"type": "samba.pose", "version": 1, "seq": 12, "t_ns": 1700000000123456789,
     "t": 1700000000.1234568, "latency_ms": 2.1, "residual_m": 0.004, "n_markers": 8,
     "n_views": 4, "marker_mask": 255, "label_margin_m": 0.08, "label_mode": "tracking",
     "flags": ["solved"], "joint_names": [...13 names...],
     "joints": [[x, y, z], ...13 rows..., or null rows], "markers": [[x, y, z] | null, ...8],
     "joint_bound": [0.02, ...13 metres or null (unknown)] or null}
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, field

import numpy as np

from .skeleton import JOINT_NAMES, N_JOINTS, N_MARKERS

MAGIC = b"SMBP"
VERSION = 3
HEADER = struct.Struct("<4sBBHIqffBBHfBB")
HEADER_V1 = struct.Struct("<4sBBHIqffBBH")
#: label_mode values, by index
LABEL_MODES = ("lost", "tracking", "identified")

FLAG_SOLVED = 0x01  #: joints hold a solution
FLAG_MARKERS = 0x02  #: the triangulated markers follow the joints
FLAG_INCOMPLETE = 0x04  #: at least one live mote had no packet in this frame
FLAG_LABEL_OVERRIDDEN = 0x08  #: the 3D labelling named a blob otherwise than its mote did
FLAG_SOLVE_SKIPPED = 0x10  #: live: the frame was older than max_lag_ms, so its solve was skipped
FLAG_LABEL_RENAMED = 0x20  #: the labelling found the names it held until the frame before wrong, and replaced them
FLAG_BOUNDS = 0x40  #: the per-joint error bounds follow the joints (and markers)
FLAG_NAMES = {FLAG_SOLVED: "solved", FLAG_MARKERS: "markers", FLAG_INCOMPLETE: "incomplete",
              FLAG_LABEL_OVERRIDDEN: "label_overridden", FLAG_SOLVE_SKIPPED: "solve_skipped",
              FLAG_LABEL_RENAMED: "label_renamed"}


class PoseError(ValueError):
    """A buffer is not a valid pose message."""


@dataclass
class PoseMessage:
    """One published pose.

    joints: (13, 3) float world metres (NaN rows when unsolved); markers: (8, 3) float or None;
    joint_bound: (13,) float metres, how far each joint may be off (inf = unknown), or None.
    """

    seq: int
    t_ns: int
    joints: np.ndarray
    latency_ms: float = 0.0
    residual_m: float = float("nan")
    n_markers: int = 0
    n_views: int = 0
    flags: int = 0
    markers: np.ndarray | None = None
    marker_mask: int = 0
    label_margin_m: float = float("nan")
    label_mode: str = "lost"
    joint_bound: np.ndarray | None = None
    extra: dict = field(default_factory=dict)

    @property
    def solved(self) -> bool:
        return bool(self.flags & FLAG_SOLVED)


def encode_pose(m: PoseMessage) -> bytes:
    """Binary encoding of ``m``; raise PoseError when a field does not fit."""
    joints = np.asarray(m.joints, dtype="<f4")
    if joints.shape != (N_JOINTS, 3):
        raise PoseError(f"joints must be ({N_JOINTS}, 3), got {joints.shape}")
    flags = m.flags & ~(FLAG_MARKERS | FLAG_BOUNDS)
    tail = b""
    if m.markers is not None:
        markers = np.asarray(m.markers, dtype="<f4")
        if markers.shape != (N_MARKERS, 3):
            raise PoseError(f"markers must be ({N_MARKERS}, 3), got {markers.shape}")
        flags |= FLAG_MARKERS
        tail = markers.tobytes()
    if m.joint_bound is not None:
        bound = np.asarray(m.joint_bound, dtype="<f4")
        if bound.shape != (N_JOINTS,):
            raise PoseError(f"joint_bound must be ({N_JOINTS},), got {bound.shape}")
        flags |= FLAG_BOUNDS
        tail += bound.tobytes()
    try:
        head = HEADER.pack(MAGIC, VERSION, flags, N_JOINTS, m.seq & 0xFFFFFFFF, int(m.t_ns),
                           float(m.latency_ms), float(m.residual_m), min(int(m.n_markers), 255),
                           min(int(m.n_views), 255), int(m.marker_mask) & 0xFFFF, float(m.label_margin_m),
                           LABEL_MODES.index(m.label_mode) if m.label_mode in LABEL_MODES else 0, 0)
    except struct.error as exc:
        raise PoseError(f"pose field out of range: {exc}") from None
    return head + joints.tobytes() + tail


def decode_pose(buf: bytes | bytearray | memoryview) -> PoseMessage:
    """Parse a binary pose; raise PoseError on truncated or foreign input."""
    buf = bytes(buf)
    if len(buf) < HEADER_V1.size:
        raise PoseError(f"truncated pose: {len(buf)} bytes < header {HEADER_V1.size}")
    magic, ver, flags, nj, seq, t_ns, lat, res, nm, nv, mask = HEADER_V1.unpack_from(buf)
    if magic != MAGIC:
        raise PoseError(f"bad magic {magic!r} (expected {MAGIC!r})")
    if ver not in (1, 2, VERSION):
        raise PoseError(f"unsupported pose version {ver} (this build reads 1 to {VERSION})")
    if ver < 3:
        flags &= ~FLAG_BOUNDS
    margin, mode, head = float("nan"), "lost", HEADER_V1
    if ver >= 2:
        if len(buf) < HEADER.size:
            raise PoseError(f"truncated pose: {len(buf)} bytes < header {HEADER.size}")
        margin, mode_i = HEADER.unpack_from(buf)[11:13]
        mode, head = LABEL_MODES[mode_i] if mode_i < len(LABEL_MODES) else "lost", HEADER
    if nj != N_JOINTS:
        raise PoseError(f"pose has {nj} joints, expected {N_JOINTS}")
    n_mk = N_MARKERS * 12 if flags & FLAG_MARKERS else 0
    expected = head.size + nj * 12 + n_mk + (nj * 4 if flags & FLAG_BOUNDS else 0)
    if len(buf) != expected:
        raise PoseError(f"pose is {len(buf)} bytes, header says {expected}")
    with np.errstate(invalid="ignore"):  # damaged bytes may hold signalling NaNs: NaN either way
        joints = np.frombuffer(buf, "<f4", count=nj * 3, offset=head.size).reshape(nj, 3).astype(np.float64)
        markers = None
        if flags & FLAG_MARKERS:
            markers = np.frombuffer(buf, "<f4", count=N_MARKERS * 3, offset=head.size + nj * 12)
            markers = markers.reshape(N_MARKERS, 3).astype(np.float64)
        bound = None
        if flags & FLAG_BOUNDS:
            bound = np.frombuffer(buf, "<f4", count=nj, offset=head.size + nj * 12 + n_mk).astype(np.float64)
    return PoseMessage(seq, t_ns, joints, lat, res, nm, nv, flags, markers, mask, float(margin), mode, bound)


def stack_bounds(poses: list[PoseMessage]) -> np.ndarray:
    """The joint bounds of poses as one (F, 13) array, metres (inf where a pose has none)."""
    out = np.full((len(poses), N_JOINTS), np.inf)
    for i, p in enumerate(poses):
        if p.joint_bound is not None:
            out[i] = p.joint_bound
    return out


def _rows(a: np.ndarray | None) -> list | None:
    if a is None:
        return None
    return [None if not np.all(np.isfinite(r)) else [round(float(x), 6) for x in r] for r in np.asarray(a)]


def _num(x: float, nd: int) -> float | None:
    return None if not math.isfinite(x) else round(float(x), nd)


def pose_to_json(m: PoseMessage) -> bytes:
    """The documented JSON variant of ``m`` (see the module docstring)."""
    d = {
        "type": "samba.pose", "version": VERSION, "seq": int(m.seq), "t_ns": int(m.t_ns),
        "t": m.t_ns / 1e9, "latency_ms": _num(m.latency_ms, 3), "residual_m": _num(m.residual_m, 6),
        "n_markers": int(m.n_markers), "n_views": int(m.n_views), "marker_mask": int(m.marker_mask),
        "label_margin_m": _num(m.label_margin_m, 4), "label_mode": m.label_mode,
        "flags": [name for bit, name in FLAG_NAMES.items() if m.flags & bit and bit != FLAG_MARKERS],
        "joint_names": list(JOINT_NAMES), "joints": _rows(m.joints), "markers": _rows(m.markers),
        "joint_bound": None if m.joint_bound is None else [_num(float(b), 4) for b in m.joint_bound],
    }
    return json.dumps(d, separators=(",", ":"), allow_nan=False).encode("utf-8")


def pose_from_json(buf: bytes | str) -> PoseMessage:
    """Parse the JSON variant; raise PoseError when it is not one."""
    try:
        d = json.loads(buf)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PoseError(f"pose JSON unreadable: {exc}") from None
    if not isinstance(d, dict) or d.get("type") != "samba.pose":
        raise PoseError("not a samba.pose message")

    def arr(rows, n):
        out = np.full((n, 3), np.nan)
        for i, r in enumerate(rows[:n]):
            if r is not None:
                out[i] = r
        return out

    try:
        names = {v: k for k, v in FLAG_NAMES.items()}
        flags = 0
        for f in d.get("flags", []):
            flags |= names.get(f, 0)
        markers = None if d.get("markers") is None else arr(d["markers"], N_MARKERS)
        if markers is not None:
            flags |= FLAG_MARKERS
        bound = None
        if d.get("joint_bound") is not None:
            bound = np.array([np.inf if b is None else float(b) for b in d["joint_bound"]], float)
            if bound.shape != (N_JOINTS,):
                raise ValueError(f"joint_bound has {bound.size} entries, expected {N_JOINTS}")
            flags |= FLAG_BOUNDS
        nan = float("nan")
        return PoseMessage(int(d["seq"]), int(d["t_ns"]), arr(d["joints"], N_JOINTS),
                           nan if d.get("latency_ms") is None else float(d["latency_ms"]),
                           nan if d.get("residual_m") is None else float(d["residual_m"]),
                           int(d.get("n_markers", 0)), int(d.get("n_views", 0)), flags, markers,
                           int(d.get("marker_mask", 0)),
                           nan if d.get("label_margin_m") is None else float(d["label_margin_m"]),
                           str(d.get("label_mode", "lost")), bound)
    except (KeyError, TypeError, ValueError, OverflowError) as exc:
        raise PoseError(f"pose JSON malformed: {exc}") from None
