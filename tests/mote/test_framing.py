"""COBS + CRC32 serial framing, including a pyserial loop:// round trip."""

from __future__ import annotations

import os
import zlib

import pytest
import serial
from hypothesis import given, settings
from hypothesis import strategies as st

from samba_common.framing import FrameReader, FramingError, cobs_decode, cobs_encode, frame, unframe


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=700))
def test_cobs_round_trip_has_no_zeros(data: bytes) -> None:
    enc = cobs_encode(data)
    assert 0 not in enc
    assert cobs_decode(enc) == data


@pytest.mark.parametrize("n", [0, 1, 253, 254, 255, 256, 508, 509, 510])
def test_cobs_edge_runs(n: int) -> None:
    for data in (b"\x01" * n, b"\x00" * n, bytes(range(1, 256)) * 2 + b"\x01" * n):
        assert cobs_decode(cobs_encode(data)) == data


def test_crc_detects_corruption() -> None:
    assert zlib.crc32(b"123456789") == 0xCBF43926
    f = bytearray(frame(b"hello world"))
    assert unframe(bytes(f)) == b"hello world"
    f[3] ^= 0x10
    with pytest.raises(FramingError):
        unframe(bytes(f))
    with pytest.raises(FramingError):
        unframe(b"\x02\x01")


def test_reader_resyncs_after_garbage() -> None:
    r = FrameReader()
    stream = frame(b"one") + b"\x07garbage\x00" + frame(b"two")
    got = []
    for i in range(0, len(stream), 5):  # byte stream arrives in pieces
        got += list(r.feed(stream[i:i + 5]))
    assert got == [b"one", b"two"]
    assert r.errors == 1 and r.frames == 2


def test_serial_loop_round_trip() -> None:
    port = serial.serial_for_url("loop://", timeout=0.1)
    sent = [os.urandom(137) for _ in range(20)] + [b"\x00" * 300]
    for p in sent:
        port.write(frame(p))
    reader, got = FrameReader(), []
    while chunk := port.read(4096):
        got += list(reader.feed(chunk))
    port.close()
    assert got == sent
