"""End to end over real Zenoh on loopback: simulated motes -> server -> joints, with packet
loss, jitter, clock offsets and a mote killed and restarted; the recording replays exactly."""

from __future__ import annotations

import time

import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.pose_wire import decode_pose, pose_from_json
from samba_common.skeleton import MARKER_JOINT
from samba_server.live import LiveServer
from samba_server.recon import Reconstructor
from samba_server.record import POSE_TOPIC, Recorder, TakeReader
from samba_server.replay import replay_into, take_calibration
from samba_server.server import Server
from samba_server.simmotes import SimMotes, SimNetwork

from .conftest import short_take


def _errors(poses, sim, joints, skip=(48, 100)):
    """Marker errors (m) of all frames; mean joint errors (m) of solved frames after the body
    estimate, outside ``skip`` (the dead mote and the tracker's recovery)."""
    m_err, j_err = [], []
    for p in poses:
        k = sim.frame_of(p.t_ns)
        if not 0 <= k < len(joints):
            continue
        gt = joints[k][list(MARKER_JOINT)]
        ok = np.isfinite(p.markers).all(axis=1)
        m_err += list(np.linalg.norm(p.markers[ok] - gt[ok], axis=1))
        if p.solved and k >= 30 and not skip[0] <= k < skip[1]:
            j_err.append(np.linalg.norm(p.joints - joints[k], axis=1).mean())
    return np.array(m_err), np.array(j_err)


@pytest.mark.parametrize("n_motes", [2, 4])
def test_live_take_with_network_trouble(tmp_path, endpoint, n_motes):
    import zenoh

    joints, _t = short_take()
    rig = default_rig(n_motes)
    take = tmp_path / "take.mcap"
    rec = Recorder(take)
    server = Server(rig, reconstructor=Reconstructor(), recorder=rec)
    net = SimNetwork(drop=0.1, jitter_ms=5.0, offsets_ms=(0.0, 20.0, -7.0, 3.0), phases_ms=(0.0, 2.0, -3.0, 1.0),
                     kill={n_motes - 1: (0.8, 1.3)}, seed=n_motes)
    received = []
    with LiveServer(server, session="e2e", listen=[endpoint]):
        with zenoh.open(_client(endpoint)) as client:
            sub = client.declare_subscriber("samba/e2e/pose", lambda s: received.append(s.payload.to_bytes()))
            sub_json = client.declare_subscriber("samba/e2e/pose/json", lambda s: received.append(s.payload.to_bytes()))
            calib = [r.ok.payload.to_bytes() for r in client.get("samba/e2e/calibration", timeout=3.0) if r.ok]
            sim = SimMotes(rig, joints, 60.0, "e2e", [endpoint], net)
            assert sim.open_all()
            sim.start()
            assert sim.done.wait(30)
            time.sleep(0.3)
            sim.stop()
            deadline = time.monotonic() + 60
            while server._queue.qsize() and time.monotonic() < deadline:
                time.sleep(0.1)
            time.sleep(0.5)
            sub.undeclare()
            sub_json.undeclare()
    rec.close()
    assert calib and calib[0] == server.calibration_toml
    # the stream went on: nearly one pose per captured frame despite loss and the dead mote
    poses = server.poses
    assert len(poses) >= 0.85 * len(joints), (len(poses), len(joints))
    # (a packet put just before a mote's session is killed may be lost in flight)
    assert sim.dropped > 0 and sum(server.sync.motes[m].received for m in server.sync.motes) >= sim.sent - 2
    assert server.sync.motes[rig.names[-1]].restarts >= 1  # the restarted mote is picked up again
    m_err, j_err = _errors(poses, sim, joints)
    assert np.median(m_err) < 0.01 and np.percentile(m_err, 95) < 0.03
    # with 2 motes the dead one leaves a single view: no 3D point until it is back and the
    # markers are identified again, so fewer frames are solved right after the gap
    assert len(j_err) > (0.7 if n_motes == 4 else 0.5) * (len(joints) - 30 - 52)
    # 2 views leave every occlusion unrecoverable; 4 views are the intended setup
    assert np.mean(j_err) < (0.03 if n_motes == 4 else 0.07), np.mean(j_err)
    # clients got binary and JSON poses
    binary = [decode_pose(b) for b in received if b[:4] == b"SMBP"]
    js = [pose_from_json(b) for b in received if b[:1] == b"{"]
    assert len(binary) >= 0.9 * len(poses) and len(js) >= 0.9 * len(poses)
    # the recording is complete and readable, and replays to the very same poses
    reader = TakeReader(take)
    recorded = list(reader)
    assert not reader.truncated
    assert sum(1 for m in recorded if m.mote_id) == server.stats.packets
    assert sum(1 for m in recorded if m.topic == POSE_TOPIC) == len(poses)
    again = Server(default_rig(n_motes), calibration_toml=take_calibration(take), reconstructor=Reconstructor())
    replay_into(again, take)
    assert len(again.poses) == len(poses)
    for a, b in zip(poses, again.poses):
        assert a.t_ns == b.t_ns and a.flags == b.flags
        np.testing.assert_allclose(b.markers, a.markers, atol=1e-9, rtol=0, equal_nan=True)
        np.testing.assert_allclose(b.joints, a.joints, atol=1e-9, rtol=0, equal_nan=True)


def _client(endpoint):
    from samba_common.zenoh_util import make_config

    return make_config(mode="client", connect=[endpoint])
