"""The page's time, poor-pose sign and per-mote status columns, from the server's own data.

Unit part: :func:`pose_quality` names the reasons a pose is poor and ``Status.snapshot`` fills
each mote's fps / blobs / drops from a real :class:`Server` fed with real packets. Browser
part (headless Chromium, skipped without it): a take on the Unix-epoch clock shows the time
since its first pose, and a 5-marker pose is shown as poor with its reasons and its guessed
joints.
"""

from __future__ import annotations

import re
import threading
import time

import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.pose_wire import FLAG_SOLVED, PoseMessage
from samba_common.skeleton import MARKER_JOINT
from samba_common.wire import encode_packet
from samba_server.app import Status
from samba_server.server import Server, ServerConfig
from samba_server.simmotes import make_packet
from samba_server.viewer.bridge import PoorPose, pose_quality

from .conftest import standing_pose
from .test_browser import CHROMIUM, dump_dom

T_UNIX = 1_795_481_354.15  # a capture clock in Unix seconds, as live motes stamp


def _pose(n_markers=8, residual=0.004, mode="identified", margin=0.2, solved=True, seq=0, t=T_UNIX,
          guessed=()) -> PoseMessage:
    j = standing_pose(seq)
    bound = np.full(13, 0.05)
    bound[list(guessed)] = 0.3
    return PoseMessage(seq, int(t * 1e9), j, 3.0, residual, n_markers, 4, FLAG_SOLVED if solved else 0,
                       j[list(MARKER_JOINT)], 0xFF, margin, mode, bound)


def test_pose_quality_reasons():
    assert pose_quality(_pose())["poor"] == []
    q = pose_quality(_pose(n_markers=5))
    assert q["poor"] == ["markers 5/8"] and q["flags"] == ["solved"] and q["label_mode"] == "identified"
    assert pose_quality(_pose(residual=0.035))["poor"] == ["residual 35 mm"]
    assert pose_quality(_pose(mode="lost"))["poor"] == ["labels lost"]
    assert pose_quality(_pose(margin=0.01))["poor"] == ["ambiguous labels (margin 10 mm)"]
    assert pose_quality(_pose(solved=False, n_markers=0))["poor"] == ["unsolved", "markers 0/8"]
    # the thresholds are settings
    assert pose_quality(_pose(n_markers=5), PoorPose(min_markers=4))["poor"] == []
    # joints whose bound is 20 cm or more are named as guessed
    assert pose_quality(_pose())["unsure"] == []
    assert pose_quality(_pose(guessed=(3, 8)))["unsure"] == ["left_elbow", "right_hip"]


def test_status_fills_per_mote_fps_blobs_drops():
    rig = default_rig(2)
    server = Server(rig, config=ServerConfig(keep_history=False))
    status = Status(server, {"cam0", "cam1"})
    status.snapshot()  # starts the per-mote rate window
    rng = np.random.default_rng(0)
    X = standing_pose(0)[list(MARKER_JOINT)]
    t0 = time.time_ns()
    for k in range(30):
        for c, cam in enumerate(rig.cameras):
            if c == 1 and k % 3:  # cam1 sends every third frame only
                continue
            uv = cam.project(X)
            vis = np.ones(8, bool)
            if c == 0:
                vis[7] = False  # cam0 sees 7 blobs
            pkt = make_packet(cam.name, k, t0 + k * 16_666_667, uv, vis, (160, 120), rng, 0.0)
            server.ingest(cam.name, encode_packet(pkt), arrival_ns=t0 + k * 16_666_667 + 2_000_000)
        server.process_pending()
    time.sleep(0.05)
    server.finish()
    snap = status.snapshot()
    m0, m1 = snap["motes"]["cam0"], snap["motes"]["cam1"]
    assert m0["blobs"] == 7 and m1["blobs"] == 8
    assert m0["fps"] > 0 and m1["fps"] > 0 and m0["fps"] > 2 * m1["fps"] * 0.9
    assert isinstance(m0["drops"], int) and isinstance(m1["drops"], int)
    assert m0["alive"] and m1["alive"]


class _TakePublisher:
    """Poses on the Unix clock (the second half with 5 markers) and a status, for ``seconds``."""

    def __init__(self, viewer, seconds: float = 30.0, rate: float = 30.0):
        self.viewer, self.seconds, self.rate = viewer, seconds, rate
        self.count = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        from samba_server.viewer import pose_to_viewer

        end = time.monotonic() + self.seconds
        while not self._stop.is_set() and time.monotonic() < end:
            poor = self.count >= 20
            pose_to_viewer(self.viewer, _pose(n_markers=5 if poor else 8, seq=self.count, t=T_UNIX + self.count / self.rate,
                                              guessed=(3,) if poor else ()))
            if self.count % 10 == 0:
                self.viewer.publish_status({"motes": {"cam0": {"alive": True, "fps": 59.8, "blobs": 7, "drops": 2}},
                                            "fps": 59.9, "latency_ms": 2.5, "drops": 2, "recording": False})
            self.count += 1
            time.sleep(1.0 / self.rate)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(5.0)


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install -y chromium)")
def test_page_shows_take_time_poor_pose_and_mote_columns(tmp_path, viewer):
    with _TakePublisher(viewer, seconds=90.0):
        time.sleep(1.0)  # the good poses go first: the session starts at a 8-marker pose
        proc = dump_dom(tmp_path, viewer.url, lambda dom: 'data-pose-quality="poor"' in dom)
    body = re.search(r"<body[^>]*>", proc.stdout).group(0)
    assert 'data-pose-quality="poor"' in body
    assert re.search(r'id="pose-poor">[^<]*poor pose: markers 5/8<', proc.stdout)
    assert re.search(r'id="hud" class="poor"', proc.stdout)
    assert re.search(r'id="pose-unsure" class="dim">guessed: left elbow<', proc.stdout)
    t_shown = float(re.search(r'id="pose-t">([-\d.]+)<', proc.stdout).group(1))
    assert 0.5 < t_shown < 60.0, f"the top bar shows t = {t_shown} s, not the time since the start"
    row = re.search(r"<tr><td>cam0</td>(.*?)</tr>", proc.stdout).group(1)
    cells = re.findall(r"<td[^>]*>([^<]*)</td>", row)
    assert cells == ["yes", "59.8", "7", "2"], cells
