"""The viewer's HTTP + WebSocket behaviour, driven by a real websocket client on loopback."""

from __future__ import annotations

import json
import socket
import time
import urllib.error
import urllib.request

import numpy as np
import pytest
from websockets.sync.client import connect

from samba_server.viewer import Viewer, ViewerError

from .conftest import Publisher, standing_pose


def _ws(viewer):
    return connect(f"ws://127.0.0.1:{viewer.port}/ws", open_timeout=5)


def _until(ws, kind, timeout=5.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        msg = json.loads(ws.recv(timeout=max(0.05, end - time.monotonic())))
        if msg["type"] == kind:
            return msg
    raise AssertionError(f"no {kind} message within {timeout} s")


def test_serves_page_and_vendored_three(viewer):
    base = viewer.url
    page = urllib.request.urlopen(base, timeout=5).read().decode()
    assert "viewer.js" in page and "pose-count" in page
    js = urllib.request.urlopen(base + "static/three.module.min.js", timeout=5)
    assert js.headers["Content-Type"].startswith("text/javascript")
    assert b"Three.js Authors" in js.read(400)
    lic = urllib.request.urlopen(base + "static/LICENSE.three.txt", timeout=5).read()
    assert b"MIT" in lic or b"Permission is hereby granted" in lic
    for bad in ("static/../server.py", "static/nope.js", "etc/passwd"):
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(base + bad, timeout=5)
        assert exc.value.code == 404


def test_poses_blobs_status_reach_a_client(viewer):
    with _ws(viewer) as ws:
        hello = _until(ws, "hello")
        assert len(hello["joint_names"]) == 13 and len(hello["bones"]) == 10
        joints = standing_pose(3)
        joints[4] = np.nan  # an unsolved joint -> null
        viewer.publish_pose(1.5, joints, joints[[1, 2, 5, 6, 9, 10, 11, 12]], {"residual_m": np.float32(0.002)})
        pose = _until(ws, "pose")
        assert pose["t"] == 1.5 and pose["joints"][4] is None
        np.testing.assert_allclose(pose["joints"][0], joints[0], atol=1e-5)
        assert pose["quality"]["residual_m"] == pytest.approx(0.002)
        viewer.publish_blobs("cam7", np.array([[10.5, 20.0], [np.nan, np.nan]]), np.array([3, 255]), (160, 120))
        blobs = _until(ws, "blobs")
        assert blobs == {"type": "blobs", "mote": "cam7", "size": [160, 120],
                         "uv": [[10.5, 20.0], None], "labels": [3, 255]}
        viewer.publish_status({"fps": 59.5, "latency_ms": float("nan"), "recording": True})
        st = _until(ws, "status")
        assert st["fps"] == 59.5 and st["latency_ms"] is None and st["recording"] is True


def test_record_buttons_call_back_and_bad_messages_are_counted(viewer):
    with _ws(viewer) as ws:
        _until(ws, "hello")
        ws.send(json.dumps({"type": "record", "start": True}))
        ws.send("not json")
        ws.send(json.dumps({"type": "record", "start": "yes"}))
        ws.send(json.dumps({"type": "record", "start": False}))
        end = time.monotonic() + 5
        while len(viewer.calls) < 2 and time.monotonic() < end:
            time.sleep(0.01)
    assert viewer.calls == [True, False]
    assert viewer.stats.bad_client_messages == 2


def test_fast_publisher_is_coalesced_not_queued(viewer):
    """1000 poses published in a burst: the client ends on the newest one and receives only a
    few (at most max_rate per second), never a backlog of 1000."""
    with _ws(viewer) as ws:
        _until(ws, "hello")
        t0 = time.monotonic()
        for k in range(1000):
            viewer.publish_pose(k, standing_pose(k))
        burst = time.monotonic() - t0
        received = []
        while not received or received[-1]["seq"] < 1000:
            received.append(_until(ws, "pose"))
    assert received[-1]["seq"] == viewer.stats.poses_published == 1000
    assert received[-1]["t"] == 999
    assert len(received) <= 60 * burst + 5


def test_late_client_gets_last_status_and_survives_client_drop(viewer):
    viewer.publish_status({"fps": 30.0, "recording": True})
    with _ws(viewer) as ws:
        assert _until(ws, "hello")["recording"] is True
        assert _until(ws, "status")["fps"] == 30.0
    with Publisher(viewer, seconds=5.0) as pub, _ws(viewer) as ws2:
        assert _until(ws2, "pose")["joints"][0] is not None
        assert pub.count > 0
    assert viewer.stats.clients in (0, 1)


def test_port_taken_and_stop_releases_it():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(ViewerError, match=str(port)):
            Viewer("127.0.0.1", port).start()
    v = Viewer("127.0.0.1", 0).start()
    port = v.port
    v.stop()
    v.stop()  # idempotent
    v.publish_pose(0.0, standing_pose(0))  # no-op after stop
    with socket.socket() as s:
        s.bind(("127.0.0.1", port))  # released


def test_bridge_from_wire_types(viewer):
    from samba_common import pose_wire, wire
    from samba_server.viewer import packet_to_viewer, pose_to_viewer

    j = standing_pose(0)
    pose = pose_wire.PoseMessage(seq=1, t_ns=2_500_000_000, joints=j.astype(np.float32), latency_ms=3.0,
                                 residual_m=0.004, n_markers=7, n_views=3, flags=pose_wire.FLAG_SOLVED)
    flags = np.array([wire.FLAG_TRACKED, wire.FLAG_PREDICTED, wire.FLAG_MERGED], np.uint8)
    pk = wire.MarkerPacket("cam3", 5, 1, 320, 240, 128, np.array([0, 1, 255], np.uint8),
                           np.array([[1, 2], [3, 4], [5, 6]], np.float32), np.array([4, 0, 9], np.uint16), flags)
    with _ws(viewer) as ws:
        _until(ws, "hello")
        pose_to_viewer(viewer, pose)
        msg = _until(ws, "pose")
        assert msg["t"] == 2.5 and msg["quality"]["n_markers"] == 7 and msg["quality"]["solved"] is True
        assert msg["markers"] == [None] * 8
        packet_to_viewer(viewer, pk)
        blobs = _until(ws, "blobs")
    assert blobs["mote"] == "cam3" and blobs["size"] == [320, 240]
    assert blobs["uv"] == [[1.0, 2.0], [5.0, 6.0]] and blobs["labels"] == [0, 255]  # predicted one left out


def test_bad_published_data_is_dropped_and_counted(viewer):
    with _ws(viewer) as ws:
        _until(ws, "hello")
        viewer.publish_pose(0.0, np.zeros((5, 3)))  # wrong shape
        end = time.monotonic() + 5
        while viewer.stats.bad_published == 0 and time.monotonic() < end:
            time.sleep(0.01)
        assert viewer.stats.bad_published == 1
        viewer.publish_pose(1.0, standing_pose(1))  # the viewer keeps serving
        assert _until(ws, "pose")["t"] == 1.0
