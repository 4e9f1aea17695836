"""Mote wire formats: the binary 2D marker packet and the JSON status message.

Marker packet, version 2, little endian (defined only here; FORMATS.md is the contract)::

    header  "<4sBBHIqHHBB" (26 bytes)
        magic      4s   b"SMBM"
        version    B    2 (1 is read too)
        reserved   B    0 (readers ignore it)
        n          H    number of marker records (<= MAX_MARKERS)
        seq        I    sequence number (wraps at 2**32)
        t_ns       q    capture time, integer nanoseconds since the Unix epoch
        width      H    frame width in pixels
        height     H    frame height in pixels
        threshold  B    binarisation threshold used for this frame
        id_len     B    length of the UTF-8 mote id (1..MAX_ID_LEN)
    mote id  id_len bytes of UTF-8
    records  n x 18 bytes: label u1, flags u1, u f4, v f4, area u2,
             var_u f2, cov_uv f2, var_v f2 (version 1: 12 bytes, without the moments)

``label`` is an index into ``MARKER_NAMES`` (0..7) or :data:`UNLABELLED` (255); ``flags`` is
a bit set of :data:`FLAG_TRACKED`, :data:`FLAG_PREDICTED`, :data:`FLAG_LOST`,
:data:`FLAG_MERGED` (and :data:`FLAG_UNCERTAIN` on unlabelled records of markers the tracker
follows but whose identity it is not sure of, e.g. after two markers crossed). A predicted or lost record carries the tracker's predicted position
(or NaN when it has none) and area 0: it was *not* measured in this frame.

The moments are the blob's intensity-weighted second central moments in px^2 (half floats:
three significant digits, plenty for blobs a few pixels wide), NaN on records not measured and
in version-1 packets. Two markers in one blob make it elongated: the gap between the
eigenvalues of its 2x2 covariance is a quarter of their squared separation, along the major
axis, which is how the server places two markers it cannot see apart.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field
from typing import Any

import numpy as np

MAGIC = b"SMBM"
VERSION = 2
HEADER = struct.Struct("<4sBBHIqHHBB")
RECORD = np.dtype([("label", "u1"), ("flags", "u1"), ("u", "<f4"), ("v", "<f4"), ("area", "<u2"),
                   ("var_u", "<f2"), ("cov_uv", "<f2"), ("var_v", "<f2")])
RECORD_V1 = np.dtype([("label", "u1"), ("flags", "u1"), ("u", "<f4"), ("v", "<f4"), ("area", "<u2")])
_RECORDS = {1: RECORD_V1, 2: RECORD}
MAX_MARKERS = 1024
MAX_ID_LEN = 64
MAX_PACKET = HEADER.size + MAX_ID_LEN + MAX_MARKERS * RECORD.itemsize
_MAX_F2 = 65000.0  #: moments beyond this (no marker blob is that large) are written as NaN

UNLABELLED = 255
FLAG_TRACKED = 0x01  #: measured this frame and matched to its track
FLAG_PREDICTED = 0x02  #: not measured this frame; position is the tracker's prediction
FLAG_LOST = 0x04  #: not seen for longer than the coast time; identity kept for re-acquisition
FLAG_MERGED = 0x08  #: measured blob holds two or more markers; its centroid is biased
FLAG_UNCERTAIN = 0x10  #: on an unlabelled record: a tracked marker whose identity is in doubt
FLAG_NAMES = {FLAG_TRACKED: "tracked", FLAG_PREDICTED: "predicted", FLAG_LOST: "lost", FLAG_MERGED: "merged",
              FLAG_UNCERTAIN: "uncertain"}


class PacketError(ValueError):
    """A buffer is not a valid Samba marker packet or status message."""


@dataclass
class MarkerPacket:
    """2D markers seen by one mote in one frame.

    labels: (N,) uint8 marker index or UNLABELLED; uv: (N, 2) float32 pixels (raw, distorted
    image coordinates, origin at the centre of the top-left pixel); area: (N,) uint16 pixels;
    flags: (N,) uint8 FLAG_* bit set; moments: (N, 3) float32 blob second central moments
    (var_u, cov_uv, var_v) px^2, NaN where not measured. t_ns: capture time, ns since the Unix
    epoch.
    """

    mote_id: str
    seq: int
    t_ns: int
    width: int
    height: int
    threshold: int
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))
    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))
    area: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint16))
    flags: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint8))
    moments: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.moments is None:
            self.moments = np.full((len(self.labels), 3), np.nan, np.float32)

    def __len__(self) -> int:
        return int(len(self.labels))

    def labelled_uv(self, n_markers: int = 8, measured_only: bool = True, drop_merged: bool = False) -> np.ndarray:
        """(n_markers, 2) float64 pixels by label, NaN where absent.

        measured_only: skip predicted/lost records; drop_merged: skip merged records too.
        """
        out = np.full((n_markers, 2), np.nan)
        for lab, (u, v), fl in zip(self.labels, self.uv, self.flags):
            if lab >= n_markers:
                continue
            if measured_only and not fl & FLAG_TRACKED:
                continue
            if drop_merged and fl & FLAG_MERGED:
                continue
            out[lab] = (u, v)
        return out


def encode_packet(p: MarkerPacket) -> bytes:
    """Serialise ``p``; raise PacketError if a field does not fit the format."""
    mid = p.mote_id.encode("utf-8")
    n = len(p.labels)
    if not 1 <= len(mid) <= MAX_ID_LEN:
        raise PacketError(f"mote id must be 1..{MAX_ID_LEN} UTF-8 bytes, got {len(mid)}")
    if n > MAX_MARKERS:
        raise PacketError(f"too many markers: {n} > {MAX_MARKERS}")
    uv = np.asarray(p.uv, dtype=np.float32).reshape(-1, 2)
    if not (len(uv) == len(p.area) == len(p.flags) == n):
        raise PacketError(f"field lengths differ: labels {n}, uv {len(uv)}, area {len(p.area)}, flags {len(p.flags)}")
    try:
        head = HEADER.pack(MAGIC, VERSION, 0, n, p.seq & 0xFFFFFFFF, int(p.t_ns), p.width, p.height,
                           p.threshold, len(mid))
    except struct.error as exc:
        raise PacketError(f"header field out of range: {exc}") from None
    mom = np.asarray(p.moments, dtype=np.float32).reshape(-1, 3) if p.moments is not None \
        else np.full((n, 3), np.nan, np.float32)
    if len(mom) != n:
        raise PacketError(f"field lengths differ: labels {n}, moments {len(mom)}")
    mom = np.where(np.abs(mom) <= _MAX_F2, mom, np.nan)
    rec = np.empty(n, RECORD)
    rec["label"] = p.labels
    rec["flags"] = p.flags
    rec["u"] = uv[:, 0]
    rec["v"] = uv[:, 1]
    rec["area"] = np.clip(np.asarray(p.area), 0, 0xFFFF)
    rec["var_u"], rec["cov_uv"], rec["var_v"] = mom[:, 0], mom[:, 1], mom[:, 2]
    return head + mid + rec.tobytes()


def decode_packet(buf: bytes | bytearray | memoryview) -> MarkerPacket:
    """Parse one packet; raise PacketError on truncated, garbage or oversized input."""
    buf = bytes(buf)
    if len(buf) > MAX_PACKET:
        raise PacketError(f"packet too large: {len(buf)} > {MAX_PACKET} bytes")
    if len(buf) < HEADER.size:
        raise PacketError(f"truncated packet: {len(buf)} bytes < header {HEADER.size}")
    magic, ver, _res, n, seq, t_ns, w, h, thr, id_len = HEADER.unpack_from(buf)
    if magic != MAGIC:
        raise PacketError(f"bad magic {magic!r} (expected {MAGIC!r})")
    if ver not in _RECORDS:
        raise PacketError(f"unsupported packet version {ver} (this build reads 1..{VERSION})")
    record = _RECORDS[ver]
    if n > MAX_MARKERS:
        raise PacketError(f"too many markers: {n} > {MAX_MARKERS}")
    if not 1 <= id_len <= MAX_ID_LEN:
        raise PacketError(f"bad mote id length {id_len}")
    expected = HEADER.size + id_len + n * record.itemsize
    if len(buf) != expected:
        kind = "truncated" if len(buf) < expected else "trailing bytes in"
        raise PacketError(f"{kind} packet: {len(buf)} bytes, header says {expected}")
    try:
        mote_id = buf[HEADER.size:HEADER.size + id_len].decode("utf-8")
    except UnicodeDecodeError:
        raise PacketError("mote id is not valid UTF-8") from None
    rec = np.frombuffer(buf, record, count=n, offset=HEADER.size + id_len)
    uv = np.empty((n, 2), np.float32)
    uv[:, 0] = rec["u"]
    uv[:, 1] = rec["v"]
    mom = np.full((n, 3), np.nan, np.float32)
    if ver >= 2:
        mom[:, 0], mom[:, 1], mom[:, 2] = rec["var_u"], rec["cov_uv"], rec["var_v"]
        mom[~(np.abs(mom) <= _MAX_F2)] = np.nan  # infinities of a corrupted record
    return MarkerPacket(mote_id, seq, t_ns, w, h, thr, rec["label"].copy(), uv, rec["area"].copy(),
                        rec["flags"].copy(), mom)


# ---------------------------------------------------------------------------------- status


@dataclass
class MoteStatus:
    """About once a second from each mote. Times in ns since the Unix epoch, durations in us."""

    mote_id: str
    t_ns: int
    fps: float = 0.0
    frames: int = 0
    dropped: int = 0
    detect_us: float = 0.0
    cpu_load: float = 0.0
    n_blobs: float = 0.0
    source: str = ""
    send_errors: int = 0
    extra: dict[str, Any] = field(default_factory=dict)


_STATUS_KEYS = {"mote_id": str, "t_ns": int, "fps": float, "frames": int, "dropped": int, "detect_us": float,
                "cpu_load": float, "n_blobs": float, "source": str, "send_errors": int}
MAX_STATUS = 64 * 1024


def encode_status(s: MoteStatus) -> bytes:
    """JSON bytes of ``s`` (UTF-8, one object; unknown ``extra`` keys travel along)."""
    d = {k: getattr(s, k) for k in _STATUS_KEYS}
    d.update({k: v for k, v in s.extra.items() if k not in d})
    d["type"] = "samba.mote.status"
    d["version"] = 1
    return json.dumps(d, separators=(",", ":"), allow_nan=False).encode("utf-8")


def decode_status(buf: bytes | bytearray | memoryview) -> MoteStatus:
    """Parse a status message; raise PacketError if it is not one."""
    buf = bytes(buf)
    if len(buf) > MAX_STATUS:
        raise PacketError(f"status message too large: {len(buf)} bytes")
    try:
        d = json.loads(buf.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PacketError(f"status is not JSON: {exc}") from None
    if not isinstance(d, dict) or d.get("type") != "samba.mote.status":
        raise PacketError("not a samba.mote.status message")
    kw: dict[str, Any] = {}
    for k, typ in _STATUS_KEYS.items():
        if k not in d:
            if k in ("mote_id", "t_ns"):
                raise PacketError(f"status lacks {k!r}")
            continue
        v = d.pop(k)
        if typ is float and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        if not isinstance(v, typ) or isinstance(v, bool):
            raise PacketError(f"status field {k!r} has type {type(v).__name__}, expected {typ.__name__}")
        kw[k] = v
    d.pop("type", None)
    d.pop("version", None)
    return MoteStatus(**kw, extra=d)
