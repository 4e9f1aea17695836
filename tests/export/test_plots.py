"""plot_take on a real take.mcap written by the server's Recorder."""

from __future__ import annotations

import numpy as np
import pytest

from samba_common.skeleton import MARKER_JOINT

record = pytest.importorskip("samba_server.record")
pose_wire = pytest.importorskip("samba_common.pose_wire")
wire = pytest.importorskip("samba_common.wire")
from samba_server.plots import plot_take, read_take_data  # noqa: E402

T0 = 1_700_000_000_000_000_000


def _write_take(path, joints, t):
    """cam0 sees everything; cam1 loses the left wrist (label 2) after 1 s, with a predicted
    record instead; cam2 stops sending at 1 s."""
    with record.Recorder(path) as rec:
        for i, (j, tt) in enumerate(zip(joints, t)):
            t_ns = T0 + int(round(tt * 1e9))
            for mote in ("cam0", "cam1", "cam2"):
                if mote == "cam2" and tt >= 1.0:
                    continue
                labels = np.arange(8, dtype=np.uint8)
                flags = np.full(8, wire.FLAG_TRACKED, np.uint8)
                if mote == "cam1" and tt >= 1.0:
                    flags[2] = wire.FLAG_PREDICTED
                pk = wire.MarkerPacket(mote, i, t_ns, 160, 120, 128, labels,
                                       np.full((8, 2), 50.0, np.float32), np.full(8, 9, np.uint16), flags)
                rec.write_packet(mote, wire.encode_packet(pk), t_ns + 3_000_000, t_ns, i)
            m = pose_wire.PoseMessage(seq=i, t_ns=t_ns, joints=j.astype(np.float32), latency_ms=4.0 + (i % 5),
                                      residual_m=0.003, n_markers=8, n_views=3,
                                      flags=pose_wire.FLAG_SOLVED | pose_wire.FLAG_MARKERS,
                                      markers=j[list(MARKER_JOINT)].astype(np.float32), marker_mask=255)
            rec.write_pose(pose_wire.encode_pose(m), t_ns + 5_000_000, t_ns, i)
        rec.write_pose(b"garbage", T0, T0, 0)


def test_plot_take_from_recording(tmp_path, walk):
    import matplotlib.image as mpimg

    joints, t = walk
    take = tmp_path / "take.mcap"
    _write_take(take, joints, t)
    data = read_take_data(take)
    assert data.bad == 1 and len(data.pose_t) == 120 and sorted(data.motes) == ["cam0", "cam1", "cam2"]
    np.testing.assert_allclose(data.pose_latency_ms[:5], [4, 5, 6, 7, 8], atol=1e-4)
    np.testing.assert_allclose(data.motes["cam0"].latency_ms, 3.0, atol=1e-6)
    cam1 = data.motes["cam1"]
    assert cam1.seen[cam1.t < 1.0, 2].all() and not cam1.seen[cam1.t >= 1.0, 2].any()
    assert cam1.seen[:, 3].all()
    assert data.motes["cam2"].t.max() < 1.0

    out = tmp_path / "take.png"
    plot_take(take, out)
    img = mpimg.imread(out)
    assert img.shape[1] == 1300 and img.shape[0] > 700
    assert np.std(img[..., :3]) > 0.05


def test_plot_take_rejects_an_empty_take(tmp_path):
    take = tmp_path / "empty.mcap"
    with record.Recorder(take):
        pass
    with pytest.raises(ValueError, match="nothing|no poses"):
        plot_take(take, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_plot_take_from_pose_arrays(tmp_path, walk):
    """The call form samba-inspect uses: plot_take(joints, t, out)."""
    import matplotlib.image as mpimg

    joints, t = walk
    out = tmp_path / "poses.png"
    data = plot_take(joints, t, out)
    assert out.exists() and len(data.pose_t) == 120 and not data.motes
    assert mpimg.imread(out).shape[1] == 1300
    with pytest.raises(ValueError, match="frames"):
        plot_take(joints, t[:5], tmp_path / "bad.png")
