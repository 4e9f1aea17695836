"""Exports straight from a take.mcap written by the server's Recorder."""

from __future__ import annotations

import numpy as np
import pytest

from samba_common.bvh import read_bvh
from samba_common.skeleton import MARKER_JOINT
from samba_server.cli.export import main
from samba_server.export.bvh import fk_positions
from samba_server.export.take import TakeError, load_take

record = pytest.importorskip("samba_server.record")
pose_wire = pytest.importorskip("samba_common.pose_wire")


def _record(path, joints, t, unsolved=()):
    t0 = 1_700_000_000_000_000_000
    with record.Recorder(path) as rec:
        for i, (j, tt) in enumerate(zip(joints, t)):
            solved = i not in unsolved
            m = pose_wire.PoseMessage(
                seq=i, t_ns=t0 + int(round(tt * 1e9)),
                joints=(j if solved else np.full_like(j, np.nan)).astype(np.float32),
                latency_ms=2.0, residual_m=0.003, n_markers=8, n_views=4,
                flags=(pose_wire.FLAG_SOLVED if solved else 0) | pose_wire.FLAG_MARKERS,
                markers=j[list(MARKER_JOINT)].astype(np.float32), marker_mask=255)
            payload = pose_wire.encode_pose(m)
            rec.write_packet("cam0", b"\x00" * 20, t0 + int(tt * 1e9))  # other topics are ignored
            rec.write_pose(payload, t0 + int(tt * 1e9) + 2_000_000, m.t_ns, i)


def test_load_take_from_mcap(tmp_path, walk):
    joints, t = walk
    path = tmp_path / "take.mcap"
    _record(path, joints, t, unsolved={5})
    take = load_take(path)
    assert take.n_frames == 120 and take.markers is not None
    np.testing.assert_allclose(take.t, t, atol=1e-6)
    assert np.isnan(take.joints[5]).all()
    ok = np.arange(120) != 5
    np.testing.assert_allclose(take.joints[ok], joints[ok], atol=1e-6)  # float32 on the wire


def test_export_bvh_from_mcap(tmp_path, walk):
    joints, t = walk
    path = tmp_path / "take.mcap"
    _record(path, joints, t)
    out = tmp_path / "take.bvh"
    assert main([str(path), "--format", "bvh", "--out", str(out)]) == 0
    assert np.abs(fk_positions(read_bvh(out)) - joints).max() < 1e-3


def test_mcap_without_poses_is_a_clear_error(tmp_path):
    path = tmp_path / "empty.mcap"
    with record.Recorder(path) as rec:
        rec.write_packet("cam0", b"\x00" * 20, 1)
    with pytest.raises(TakeError, match="no poses"):
        load_take(path)
    (tmp_path / "junk.mcap").write_bytes(b"garbage" * 10)
    assert main([str(tmp_path / "junk.mcap"), "-o", str(tmp_path / "x.csv")]) == 1
