"""Marker packet and status codecs: round trips, rejection of bad input, hypothesis fuzz."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from samba_common.wire import (FLAG_MERGED, FLAG_PREDICTED, FLAG_TRACKED, HEADER, MAX_PACKET,
                               UNLABELLED, MarkerPacket, MoteStatus, PacketError, decode_packet,
                               decode_status, encode_packet, encode_status)
from samba_common.wire import RECORD_V1


def _packet(n: int = 8, seed: int = 0) -> MarkerPacket:
    rng = np.random.default_rng(seed)
    return MarkerPacket("cam0", 42, 1_700_000_000_123_456_789, 160, 120, 128,
                        labels=np.arange(n, dtype=np.uint8),
                        uv=rng.uniform(0, 160, (n, 2)).astype(np.float32),
                        area=rng.integers(0, 60, n).astype(np.uint16),
                        flags=np.full(n, FLAG_TRACKED, np.uint8),
                        moments=rng.uniform(-2, 8, (n, 3)).astype(np.float32))


def test_round_trip_exact() -> None:
    p = _packet()
    buf = encode_packet(p)
    assert len(buf) == HEADER.size + 4 + 8 * 18
    q = decode_packet(buf)
    assert (q.mote_id, q.seq, q.t_ns, q.width, q.height, q.threshold) == ("cam0", 42, p.t_ns, 160, 120, 128)
    np.testing.assert_array_equal(q.uv, p.uv)
    np.testing.assert_array_equal(q.labels, p.labels)
    np.testing.assert_array_equal(q.area, p.area)
    np.testing.assert_array_equal(q.flags, p.flags)
    # the moments travel as half floats: three significant digits
    np.testing.assert_allclose(q.moments, p.moments, rtol=1e-3, atol=4e-3)


def test_version_1_packets_still_read() -> None:
    """Recordings made before the moments were carried replay: a version-1 packet (12-byte
    records) decodes with NaN moments."""
    p = _packet()
    head = HEADER.pack(b"SMBM", 1, 0, 8, 42, p.t_ns, 160, 120, 128, 4)
    rec = np.empty(8, RECORD_V1)
    rec["label"], rec["flags"], rec["u"], rec["v"], rec["area"] = p.labels, p.flags, p.uv[:, 0], p.uv[:, 1], p.area
    q = decode_packet(head + b"cam0" + rec.tobytes())
    np.testing.assert_array_equal(q.uv, p.uv)
    np.testing.assert_array_equal(q.area, p.area)
    assert q.moments.shape == (8, 3) and np.isnan(q.moments).all()


def test_unmeasured_and_huge_moments_are_nan() -> None:
    p = _packet(2)
    p.moments = None
    assert np.isnan(decode_packet(encode_packet(p)).moments).all()
    p = _packet(2)
    p.moments[0] = (1e6, 0.0, 1.0)
    q = decode_packet(encode_packet(p))
    assert np.isnan(q.moments[0, 0]) and q.moments[0, 2] == 1.0


def test_empty_packet_and_nan_prediction() -> None:
    p = _packet(0)
    assert len(decode_packet(encode_packet(p))) == 0
    p = _packet(2)
    p.uv[1] = np.nan
    p.flags[1] = FLAG_PREDICTED
    q = decode_packet(encode_packet(p))
    assert np.isnan(q.uv[1]).all()
    lab = q.labelled_uv()
    assert np.isnan(lab[1]).all() and np.allclose(lab[0], p.uv[0])


def test_labelled_uv_drops_merged_and_unlabelled() -> None:
    p = _packet(3)
    p.labels[2] = UNLABELLED
    p.flags[1] |= FLAG_MERGED
    lab = p.labelled_uv(drop_merged=True)
    assert not np.isnan(lab[0]).any() and np.isnan(lab[1]).all() and np.isnan(lab[2:]).all()


@pytest.mark.parametrize("cut", [0, 3, HEADER.size - 1, HEADER.size, HEADER.size + 4 + 17])
def test_truncated_rejected(cut: int) -> None:
    buf = encode_packet(_packet())
    with pytest.raises(PacketError, match="truncated"):
        decode_packet(buf[:cut])


def test_garbage_and_oversized_rejected() -> None:
    buf = encode_packet(_packet())
    with pytest.raises(PacketError, match="magic"):
        decode_packet(b"XXXX" + buf[4:])
    with pytest.raises(PacketError, match="version"):
        decode_packet(buf[:4] + b"\x09" + buf[5:])
    with pytest.raises(PacketError, match="trailing"):
        decode_packet(buf + b"\x00")
    with pytest.raises(PacketError, match="too large"):
        decode_packet(b"\x00" * (MAX_PACKET + 1))


def test_encode_rejects_bad_fields() -> None:
    p = _packet()
    p.mote_id = ""
    with pytest.raises(PacketError):
        encode_packet(p)
    p = _packet()
    p.threshold = 300
    with pytest.raises(PacketError):
        encode_packet(p)
    p = _packet()
    p.area = p.area[:3]
    with pytest.raises(PacketError):
        encode_packet(p)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=400))
def test_fuzz_random_bytes_never_crash(buf: bytes) -> None:
    try:
        p = decode_packet(buf)
    except PacketError:
        return
    again = encode_packet(p)  # the reserved byte 5 is ignored by readers
    assert again[:5] + again[6:] == buf[:5] + buf[6:]


@settings(max_examples=200, deadline=None)
@given(n=st.integers(0, 40), seq=st.integers(0, 2**32 - 1), t=st.integers(-2**63, 2**63 - 1),
       mid=st.text(min_size=1, max_size=16).filter(lambda s: len(s.encode()) <= 64),
       seed=st.integers(0, 1000), flip=st.integers(0, 10_000))
def test_fuzz_round_trip_and_mutations(n: int, seq: int, t: int, mid: str, seed: int, flip: int) -> None:
    rng = np.random.default_rng(seed)
    p = MarkerPacket(mid, seq, t, int(rng.integers(1, 65535)), int(rng.integers(1, 65535)), int(rng.integers(256)),
                     labels=rng.integers(0, 256, n).astype(np.uint8),
                     uv=rng.normal(0, 1000, (n, 2)).astype(np.float32),
                     area=rng.integers(0, 65536, n).astype(np.uint16),
                     flags=rng.integers(0, 16, n).astype(np.uint8),
                     moments=rng.normal(0, 10, (n, 3)).astype(np.float32))
    buf = encode_packet(p)
    q = decode_packet(buf)
    assert (q.mote_id, q.seq, q.t_ns, len(q)) == (mid, seq, t, n)
    np.testing.assert_array_equal(q.uv, p.uv)
    # a mutated or truncated buffer either decodes to something re-encodable or raises PacketError
    mutated = bytearray(buf)
    mutated[flip % len(buf)] ^= 0xFF
    for cand in (bytes(mutated), buf[: flip % len(buf)]):
        try:
            r = decode_packet(cand)
        except PacketError:
            continue
        again = decode_packet(encode_packet(r))  # and decodes again to the same
        assert (again.mote_id, again.seq, again.t_ns, again.width, again.height, again.threshold) == \
            (r.mote_id, r.seq, r.t_ns, r.width, r.height, r.threshold)
        for name in ("labels", "uv", "area", "flags", "moments"):
            np.testing.assert_array_equal(getattr(again, name), getattr(r, name))


def test_status_round_trip_and_errors() -> None:
    s = MoteStatus("cam0", 123, fps=59.9, frames=600, dropped=2, detect_us=87.5, cpu_load=0.3,
                   extra={"temperature_c": 51.0})
    r = decode_status(encode_status(s))
    assert r == s
    for bad in (b"", b"\xff\xfe", b"[]", b'{"type": "other"}', b'{"type": "samba.mote.status", "t_ns": 1}',
                b'{"type": "samba.mote.status", "mote_id": "a", "t_ns": "x"}'):
        with pytest.raises(PacketError):
            decode_status(bad)
