"""Simulator: take files on disk, T-pose lead-in, ground truth consistency, CLI, sim: source."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from samba_common.calib import CameraRig
from samba_common.formats import load_joints, load_markers
from samba_common.skeleton import J, MARKER_JOINT
from samba_mote.sim import SimConfig, make_take
from samba_mote.cli.sim import main as sim_main
from samba_mote.sources import open_source
from tests.shared_data import CMU_DIR, CMU_SKIP

BVH = CMU_DIR / "005_03.bvh"


def test_take_files_round_trip(small_take) -> None:
    d = small_take.out_dir
    joints = load_joints(d / "joints.npz")
    markers = load_markers(d / "markers.npz")
    rig = CameraRig.load(d / "calibration.toml")
    assert rig.names == ["cam0", "cam1"]
    n = len(small_take.t)
    assert joints.joints.shape == (n, 13, 3) and markers.markers.shape == (n, 8, 3)
    np.testing.assert_allclose(markers.markers, joints.joints[:, list(MARKER_JOINT)])
    np.testing.assert_allclose(np.diff(joints.t), 1 / 60, atol=1e-9)
    cap = cv2.VideoCapture(str(d / "cam0.avi"))
    cap.set(cv2.CAP_PROP_CONVERT_RGB, 0)
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f if f.ndim == 2 else f[..., 0])
    assert len(frames) == n
    assert np.array_equal(np.asarray(frames), small_take.cameras[0].frames)  # FFV1 is lossless
    truth = np.load(d / "truth2d.npz")
    np.testing.assert_allclose(truth["uv"][0], rig.camera("cam0").project(markers.markers.reshape(-1, 3)).reshape(n, 8, 2))


def test_tpose_lead_in(small_take) -> None:
    j = small_take.joints
    n_hold = int(SimConfig().tpose_hold * SimConfig().fps)
    first = j[0]
    # arms straight out sideways at shoulder height, facing +Y: right hand toward +X
    assert abs(first[J["right_wrist"], 2] - first[J["right_shoulder"], 2]) < 1e-9
    assert first[J["right_wrist"], 0] > first[J["right_shoulder"], 0] + 0.4
    assert first[J["left_wrist"], 0] < first[J["left_shoulder"], 0] - 0.4
    assert np.allclose(first[:, 1], first[0, 1])  # every joint in one frontal plane
    assert np.allclose(j[:n_hold], first)
    # no jump into the take: frame-to-frame joint speed stays human
    speed = np.linalg.norm(np.diff(j, axis=0), axis=2).max() * 60
    assert speed < 8.0


def test_bvh_take_stays_in_view(tmp_path) -> None:
    if not BVH.exists():
        pytest.skip(CMU_SKIP)
    take = make_take(tmp_path, BVH, rig=4, seconds=1.0, write=False)
    vis = np.stack([c.visible for c in take.cameras])
    inside = np.stack([(c.uv[..., 0] > 0) & (c.uv[..., 0] < 160) & (c.uv[..., 1] > 0) & (c.uv[..., 1] < 120)
                       for c in take.cameras])
    assert inside.all()  # centred: every marker projects into every image
    assert vis[:, :60].all()  # nothing hides a marker during the T-pose


def test_occlusion_hides_markers_behind_the_body() -> None:
    from samba_mote.sim.motion import DEFAULT_LENGTHS
    from samba_mote.sim.render import occluded
    from samba_mote.sim.tpose import tpose

    pose = tpose(DEFAULT_LENGTHS)[None]  # facing +Y, right hand toward +X
    side = occluded(pose, np.array([5.0, 0.0, pose[0, J["right_wrist"], 2]]), SimConfig())[0]
    # seen from the subject's right at shoulder height: the left arm and shoulder are behind
    # the right arm (which also hides its own shoulder), the right wrist is in plain view
    assert side[2] and side[0] and side[1]
    assert not side[3]
    front = occluded(pose, np.array([0.0, 5.0, 1.2]), SimConfig())[0]
    assert not front.any()


def test_cli_writes_take_and_rig(tmp_path) -> None:
    assert sim_main([str(tmp_path / "rig"), "--rig-only", "--cameras", "2"]) == 0
    assert CameraRig.load(tmp_path / "rig" / "calibration.toml").names == ["cam0", "cam1"]
    out = tmp_path / "take"
    assert sim_main([str(out), "--cameras", "2", "--seconds", "0.5", "--noise", "4"]) == 0
    assert {p.name for p in out.iterdir()} >= {"cam0.avi", "cam1.avi", "joints.npz", "markers.npz", "calibration.toml"}
    assert sim_main([str(out), "--bvh", str(tmp_path / "missing.bvh")]) == 1  # a missing input: runtime error


def test_sim_source_streams_the_rendered_frames() -> None:
    src = open_source("sim:?cam=cam1&cameras=2&seconds=0.5&realtime=0&seed=5")
    take = make_take("unused", None, rig=2, seconds=0.5, seed=5, write=False)
    frames = []
    while (item := src.read()) is not None:
        frames.append(item[1])
    assert np.array_equal(np.asarray(frames), take.cameras[1].frames)
    t0 = open_source("sim:?seconds=0.2&realtime=1")
    import time

    start = time.monotonic()
    n = 0
    while t0.read() is not None:
        n += 1
    assert time.monotonic() - start >= (n - 1) / 60.0 * 0.9  # paced in real time
