"""Pose wire format: binary and JSON round trips, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from samba_common.pose_wire import (FLAG_BOUNDS, FLAG_INCOMPLETE, FLAG_MARKERS, FLAG_SOLVED, HEADER, PoseError,
                                    PoseMessage, decode_pose, encode_pose, pose_from_json, pose_to_json)


def _pose(with_markers: bool = True) -> PoseMessage:
    rng = np.random.default_rng(1)
    markers = rng.normal(size=(8, 3)) if with_markers else None
    if markers is not None:
        markers[3] = np.nan
    return PoseMessage(seq=2**32 + 5, t_ns=1_700_000_000_123_456_789, joints=rng.normal(size=(13, 3)),
                       latency_ms=2.5, residual_m=0.004, n_markers=7, n_views=4,
                       flags=FLAG_SOLVED | FLAG_INCOMPLETE, markers=markers, marker_mask=0b11110111)


@pytest.mark.parametrize("with_markers", [True, False])
def test_binary_round_trip(with_markers):
    p = _pose(with_markers)
    buf = encode_pose(p)
    assert len(buf) == HEADER.size + 13 * 12 + (96 if with_markers else 0)
    q = decode_pose(buf)
    assert q.seq == 5 and q.t_ns == p.t_ns and q.n_markers == 7 and q.n_views == 4
    assert q.marker_mask == p.marker_mask
    assert q.solved and q.flags & FLAG_INCOMPLETE and bool(q.flags & FLAG_MARKERS) == with_markers
    np.testing.assert_allclose(q.joints, p.joints, rtol=1e-6, atol=1e-6)
    assert q.latency_ms == pytest.approx(2.5) and q.residual_m == pytest.approx(0.004)
    if with_markers:
        np.testing.assert_allclose(q.markers, p.markers, rtol=1e-6, atol=1e-6, equal_nan=True)
    else:
        assert q.markers is None


def test_unsolved_pose_keeps_nan():
    p = PoseMessage(seq=0, t_ns=1, joints=np.full((13, 3), np.nan))
    q = decode_pose(encode_pose(p))
    assert np.isnan(q.joints).all() and not q.solved and np.isnan(q.residual_m)
    j = json.loads(pose_to_json(p))
    assert j["joints"] == [None] * 13 and j["residual_m"] is None


def test_json_round_trip_and_layout():
    p = _pose()
    raw = pose_to_json(p)
    d = json.loads(raw)
    assert d["type"] == "samba.pose" and d["joint_names"][0] == "head" and len(d["joints"]) == 13
    assert d["markers"][3] is None and d["flags"] == ["solved", "incomplete"]
    q = pose_from_json(raw)
    np.testing.assert_allclose(q.joints, p.joints, atol=1e-6)
    np.testing.assert_allclose(q.markers, p.markers, atol=1e-6, equal_nan=True)
    assert q.flags == p.flags | FLAG_MARKERS and q.marker_mask == p.marker_mask


@pytest.mark.parametrize("with_markers", [True, False])
def test_joint_bounds_round_trip(with_markers):
    """The per-joint bounds travel after the joints (and markers) in binary and JSON; an
    unknown bound (inf) stays unknown."""
    p = _pose(with_markers)
    p.joint_bound = np.linspace(0.02, 0.3, 13)
    p.joint_bound[3] = np.inf
    buf = encode_pose(p)
    assert len(buf) == HEADER.size + 13 * 12 + (96 if with_markers else 0) + 13 * 4
    q = decode_pose(buf)
    assert q.flags & FLAG_BOUNDS
    np.testing.assert_allclose(q.joint_bound, p.joint_bound, rtol=1e-6)
    if with_markers:
        np.testing.assert_allclose(q.markers, p.markers, rtol=1e-6, atol=1e-6, equal_nan=True)
    d = json.loads(pose_to_json(p))
    assert d["joint_bound"][3] is None and d["joint_bound"][0] == pytest.approx(0.02)
    r = pose_from_json(pose_to_json(p))
    np.testing.assert_allclose(r.joint_bound, p.joint_bound, atol=1e-4)
    with pytest.raises(PoseError):
        decode_pose(buf[:-4])


def test_version_2_pose_still_read():
    """A recording from before the bounds (version 2) decodes, without bounds."""
    buf = bytearray(encode_pose(_pose()))
    buf[4] = 2
    q = decode_pose(bytes(buf))
    assert q.joint_bound is None and q.label_mode == "lost" and q.n_markers == 7


@pytest.mark.parametrize("buf", [b"", b"SMBP", b"XXXX" + bytes(200), None])
def test_bad_binary(buf):
    if buf is None:
        buf = encode_pose(_pose())[:-3]
    with pytest.raises(PoseError):
        decode_pose(buf)


def test_bad_json_and_bad_shapes():
    for raw in (b"{", b"[]", b'{"type": "samba.pose"}', b"\xff"):
        with pytest.raises(PoseError):
            pose_from_json(raw)
    with pytest.raises(PoseError):
        encode_pose(PoseMessage(seq=0, t_ns=0, joints=np.zeros((12, 3))))
