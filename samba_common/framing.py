"""Serial framing: COBS-encoded payload + CRC32, each frame terminated by one zero byte.

A frame on the line is ``cobs(payload + crc32(payload) as <I) + b"\\x00"``. COBS removes every
zero byte from the body, so a receiver resynchronises on the next zero after any corruption.
"""

from __future__ import annotations

import logging
import struct
import zlib
from collections.abc import Iterator

log = logging.getLogger(__name__)

MAX_FRAME = 64 * 1024
_CRC = struct.Struct("<I")


class FramingError(ValueError):
    """A serial frame is corrupt (bad COBS, CRC mismatch, too short or too long)."""


def cobs_encode(data: bytes) -> bytes:
    """Consistent Overhead Byte Stuffing: returns ``data`` re-encoded without any zero byte."""
    out = bytearray([0])
    code_at, run = 0, 1
    for i, b in enumerate(data):
        if b:
            out.append(b)
            run += 1
        if not b or (run == 0xFF and i + 1 < len(data)):
            out[code_at] = run
            code_at, run = len(out), 1
            out.append(0)
    out[code_at] = run
    return bytes(out)


def cobs_decode(enc: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raise FramingError on a corrupt block."""
    out, i = bytearray(), 0
    while i < len(enc):
        code = enc[i]
        if code == 0 or i + code > len(enc):
            raise FramingError("corrupt COBS block")
        out += enc[i + 1:i + code]
        i += code
        if code != 0xFF and i < len(enc):
            out.append(0)
    return bytes(out)


def frame(payload: bytes) -> bytes:
    """One line frame for ``payload`` (ends with the 0x00 delimiter)."""
    if len(payload) > MAX_FRAME:
        raise FramingError(f"payload too large: {len(payload)} > {MAX_FRAME}")
    return cobs_encode(payload + _CRC.pack(zlib.crc32(payload))) + b"\x00"


def unframe(packet: bytes) -> bytes:
    """Payload of one frame (with or without its trailing delimiter); FramingError if corrupt."""
    body = cobs_decode(packet.rstrip(b"\x00"))
    if len(body) < _CRC.size:
        raise FramingError(f"frame too short: {len(body)} bytes")
    payload, (crc,) = body[:-4], _CRC.unpack(body[-4:])
    if zlib.crc32(payload) != crc:
        raise FramingError("CRC mismatch")
    return payload


class FrameReader:
    """Splits a byte stream into payloads; corrupt frames are dropped and counted.

    >>> r = FrameReader(); list(r.feed(frame(b"abc") + frame(b"de")))
    [b'abc', b'de']
    """

    def __init__(self, max_frame: int = MAX_FRAME + 16) -> None:
        self._buf = bytearray()
        self.max_frame = max_frame
        self.frames = 0
        self.errors = 0

    def feed(self, data: bytes) -> Iterator[bytes]:
        """Add received bytes; yield every complete, valid payload."""
        self._buf += data
        while True:
            end = self._buf.find(0)
            if end < 0:
                if len(self._buf) > self.max_frame:  # garbage without delimiter: resync
                    self.errors += 1
                    self._buf.clear()
                return
            chunk = bytes(self._buf[:end])
            del self._buf[:end + 1]
            if not chunk:
                continue  # idle delimiters
            try:
                payload = unframe(chunk)
            except FramingError as exc:
                self.errors += 1
                log.debug("dropped serial frame: %s", exc)
                continue
            self.frames += 1
            yield payload
