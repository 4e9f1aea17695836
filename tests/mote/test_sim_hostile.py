"""Simulator as hostile as real takes: stance, walk from the pose place, blackout, lossy codecs,
occlusion, CLI warnings and exit codes."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from samba_common.body import bone_lengths
from samba_common.calib import default_rig
from samba_common.skeleton import BONE_TYPES, BONES, JOINT_NAMES, J, MARKER_JOINT
from samba_mote.cli.sim import main as sim_main
from samba_mote.sim import SimConfig, load_motion, make_take, prepare_motion, tpose
from samba_mote.sim.motion import DEFAULT_LENGTHS
from samba_mote.sim.render import occluded
from tests.shared_data import CMU_DIR, CMU_SKIP

CMU = CMU_DIR
WALK = CMU / "002_01.bvh"  # a 2.85 s straight walk: its centred first frame is ~1.9 m from the origin
needs_walk = pytest.mark.skipif(not WALK.exists(), reason=CMU_SKIP)


def _hip_mid(j: np.ndarray) -> np.ndarray:
    return 0.5 * (j[..., J["left_hip"], :] + j[..., J["right_hip"], :])


def _read(path: Path, grey: bool = True) -> np.ndarray:
    cap = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) if grey and f.ndim == 3 else f)
    cap.release()
    return np.asarray(frames)


# ------------------------------------------------------------------ stance


def test_default_config_is_hostile() -> None:
    cfg = SimConfig()
    assert cfg.tpose_stance == 0.0 and cfg.pose_at == (0.0, 0.0) and cfg.occlusion
    assert cfg.blackout == () and cfg.codec == "ffv1"


@pytest.mark.parametrize("stance", ["hip", 0.0, "apart", "together", -0.03])
def test_tpose_stance_keeps_bone_lengths(stance) -> None:
    pose = tpose(DEFAULT_LENGTHS, (0.3, -0.2), 0.08, stance)
    np.testing.assert_allclose(bone_lengths(pose[None])[0], DEFAULT_LENGTHS, atol=1e-9)
    hip_w = DEFAULT_LENGTHS[BONE_TYPES.index("hip_width")]
    gap = pose[J["right_ankle"], 0] - pose[J["left_ankle"], 0]
    want = {"hip": hip_w, 0.0: hip_w, "apart": hip_w + 0.24, "together": 0.12, -0.03: hip_w - 0.06}[stance]
    assert gap == pytest.approx(want, abs=1e-9)
    assert np.allclose(pose[[J["left_ankle"], J["right_ankle"]], 2], 0.08)
    # straight legs: the knee lies on the hip-ankle line, below the hip
    for side in ("left", "right"):
        h, k, a = pose[J[f"{side}_hip"]], pose[J[f"{side}_knee"]], pose[J[f"{side}_ankle"]]
        assert np.linalg.norm(np.cross(k - h, a - h)) < 1e-9 and a[2] < k[2] < h[2]


def test_tpose_rejects_crossed_legs() -> None:
    with pytest.raises(ValueError, match="crosses"):
        tpose(DEFAULT_LENGTHS, stance=-0.2)
    with pytest.raises(ValueError, match="stance"):
        tpose(DEFAULT_LENGTHS, stance="wide")


@pytest.mark.parametrize("stance, lo, hi", [("hip", 0.15, 0.25), ("together", 0.10, 0.15), ("apart", 0.38, 0.50)])
def test_take_stance_sets_the_ankle_gap(stance, lo, hi) -> None:
    take = make_take("unused", None, rig=2, seconds=0.2, config=SimConfig(tpose_stance=stance), write=False)
    j = take.joints[: int(SimConfig().tpose_hold * 60)]
    gap = np.linalg.norm(j[:, J["left_ankle"]] - j[:, J["right_ankle"]], axis=1)
    hip_w = np.linalg.norm(j[:, J["left_hip"]] - j[:, J["right_hip"]], axis=1)
    assert np.all((gap > lo) & (gap < hi))
    if stance == "hip":
        np.testing.assert_allclose(gap, hip_w, atol=1e-6)  # ankles straight below the hips
    assert take.stance == pytest.approx({"hip": 0.0, "apart": 0.12}.get(stance, -(hip_w[0] / 2 - 0.06)), abs=1e-6)


# ------------------------------------------------------------------ lead-in: walk from the pose place


@needs_walk
@pytest.mark.parametrize("pose_at", [(0.0, 0.0), (1.5, -1.0)])
def test_lead_in_walks_from_the_pose_place_without_jumps(pose_at) -> None:
    cfg = SimConfig(pose_at=pose_at)
    joints, t, _ = load_motion(WALK)
    j, tt, n = prepare_motion(joints, t, cfg)
    hip = _hip_mid(j)
    start = hip[n, :2]
    dist = float(np.linalg.norm(start - pose_at))
    assert dist > 1.5  # the clip starts far from where the pose stood
    n_hold = int(round(cfg.tpose_hold * cfg.fps))
    np.testing.assert_allclose(hip[:n_hold, :2], np.broadcast_to(pose_at, (n_hold, 2)), atol=1e-9)
    assert n >= n_hold + int(dist / 1.0 * cfg.fps) - 1  # walking pace (<= 1 m/s on average)
    # the hips move along the straight line from the pose place to the clip's start
    d = (start - np.asarray(pose_at)) / dist
    rel = hip[n_hold:n, :2] - np.asarray(pose_at)
    assert np.abs(rel[:, 0] * d[1] - rel[:, 1] * d[0]).max() < 1e-6
    along = rel @ d
    assert np.all(np.diff(along) >= -1e-9) and along[-1] <= dist
    # no marker faster than ~3 m/s from the first frame into the first clip frame
    m = j[: n + 1, list(MARKER_JOINT)]
    speed = np.linalg.norm(np.diff(m, axis=0), axis=2) * cfg.fps
    assert speed.max() < 3.0


@needs_walk
@pytest.mark.parametrize("pose_at", [(0.0, 0.0), (1.5, -1.0)])
def test_lead_in_keeps_the_body_rigid(pose_at) -> None:
    """From the standard pose (arms straight out) into the clip's first frame (arms hanging)
    every bone keeps its length: a person does not shrink on the way (blending the joint
    positions shortened the upper arms by 25 %, and the labelling's rigid checks failed there)."""
    joints, t, _ = load_motion(WALK)
    j, _tt, n = prepare_motion(joints, t, SimConfig(pose_at=pose_at))
    for a, b in BONES:
        length = np.linalg.norm(j[: n + 1, a] - j[: n + 1, b], axis=1)
        lo, hi = sorted((length[0], length[n]))  # the pose's and the clip's (sides averaged in the pose)
        assert lo - 1e-9 <= length.min() and length.max() <= hi + 1e-9, (JOINT_NAMES[a], JOINT_NAMES[b])
    arm = np.linalg.norm(j[: n + 1, J["right_elbow"]] - j[: n + 1, J["right_shoulder"]], axis=1)
    assert np.ptp(arm) < 0.01 and not np.allclose(j[n, J["right_wrist"]], j[0, J["right_wrist"]], atol=0.3)


@needs_walk
def test_pose_at_none_stands_where_the_clip_starts(tmp_path) -> None:
    joints, t, _ = load_motion(WALK, seconds=1.0)
    j, _, n = prepare_motion(joints, t, SimConfig(pose_at=None, tpose_stance="apart"))
    np.testing.assert_allclose(_hip_mid(j[0])[:2], _hip_mid(j[n])[:2], atol=1e-9)
    assert n == 96  # 1 s of pose + 0.6 s of blend, as before


@needs_walk
def test_a_take_starting_up_on_a_structure_has_its_standard_pose_on_the_floor() -> None:
    """A climb that starts 1.7 m up (CMU 001_14) put the standard pose in mid-air, the upper
    body above every camera: the pose stands on the take's floor and the lead-in climbs."""
    joints, t, _ = load_motion(WALK)
    ankles = [J["left_ankle"], J["right_ankle"]]
    floor = float(np.percentile(joints[:, ankles, 2].min(axis=1), 2))
    lifted = joints.copy()
    lifted[:30, :, 2] += 1.7 * np.linspace(1.0, 0.0, 30)[:, None]  # steps down off a 1.7 m block
    cfg = SimConfig()
    j, _, n = prepare_motion(lifted, t, cfg)
    assert j[0, ankles, 2].min() == pytest.approx(floor, abs=0.01)
    speed = np.linalg.norm(np.diff(j[: n + 1, list(MARKER_JOINT)], axis=0), axis=2) * cfg.fps
    assert speed.max() < 3.0
    # a take that starts on its floor keeps the first frame's ankle height
    j0, _, _ = prepare_motion(joints, t, cfg)
    assert j0[0, ankles, 2].min() == pytest.approx(joints[0, ankles, 2].min(), abs=1e-9)


@needs_walk
def test_walk_take_on_disk_keeps_n_tpose(tmp_path) -> None:
    take = make_take(tmp_path, WALK, rig=2, seconds=1.0, config=SimConfig(pose_at=(1.0, 1.0)))
    truth = np.load(tmp_path / "truth2d.npz")
    assert int(truth["n_tpose"]) == take.n_tpose > 96
    assert truth["blackout"].shape == take.t.shape and not truth["blackout"].any()
    assert str(truth["codec"]) == "ffv1" and str(truth["fourcc"]) == "FFV1"


# ------------------------------------------------------------------ blackout


def test_blackout_hides_every_marker_in_every_camera(tmp_path) -> None:
    window = (1.8, 0.3)  # in take time, lead-in (1.6 s) included
    base = make_take("unused", None, rig=2, seconds=1.0, seed=4, write=False)
    empty = make_take("unused", None, rig=2, seconds=1.0, seed=4, config=SimConfig(blackout=((0.0, 99.0),)),
                      write=False)  # the same noise and clutter, no marker at all
    take = make_take(tmp_path, None, rig=2, seconds=1.0, seed=4, config=SimConfig(blackout=(window,)))
    k = np.arange(len(take.t))
    dark = (k >= 108) & (k < 126)
    truth = np.load(tmp_path / "truth2d.npz")
    assert np.array_equal(truth["blackout"], dark) and np.array_equal(take.blackout, dark)
    assert not truth["visible"][:, dark].any()
    np.testing.assert_array_equal(truth["visible"][:, ~dark], np.stack([c.visible for c in base.cameras])[:, ~dark])
    for cb, ce, ct in zip(base.cameras, empty.cameras, take.cameras):
        frames = _read(tmp_path / f"{ct.name}.avi")
        assert np.array_equal(frames, ct.frames)
        assert np.array_equal(frames[~dark], cb.frames[~dark])
        assert np.array_equal(frames[dark], ce.frames[dark])  # noise and distractors, no marker blob
        lit = 0
        for f in np.flatnonzero(dark):
            for (u, v), ok in zip(cb.uv[f], cb.visible[f]):
                if ok:
                    x, y = int(round(u)), int(round(v))
                    win = np.s_[f, max(y - 1, 0):y + 2, max(x - 1, 0):x + 2]
                    lit = max(lit, int(cb.frames[win].max()) - int(frames[win].max()))
        assert lit > 100  # without the blackout the blobs are there


def test_blackout_outside_the_take_is_a_warning_not_silence() -> None:
    """A blackout asked for past the end of the take (a clip shorter than the user thought)
    renders nothing, or only its start: the take says so instead of passing it silently."""
    said: list[str] = []
    windows = ((0.5, 0.2), (2.4, 1.0), (9.0, 1.0))  # inside, running past the end, past the end
    take = make_take("unused", None, rig=2, seconds=1.0, seed=4, config=SimConfig(blackout=windows),
                     write=False, on_warning=said.append)
    end = len(take.t) / 60.0  # 2.6 s lead-in and motion
    assert said == take.notes and len(said) == 2
    assert said[0] == f"blackout 2.4+1 s runs past the take (0-{end:.2f} s): {end - 2.4:.2f} s blacked out"
    assert said[1] == f"blackout 9+1 s lies outside the take (0-{end:.2f} s): no frame blacked out"
    assert take.blackout.sum() == 12 + round((end - 2.4) * 60)


# ------------------------------------------------------------------ codecs


def test_mjpg_take_decodes_close_to_the_lossless_frames(tmp_path) -> None:
    take = make_take(tmp_path, None, rig=2, seconds=0.3, seed=2, config=SimConfig(codec="mjpg"))
    assert take.fourcc == "MJPG" and [p.name for p in take.videos] == ["cam0.avi", "cam1.avi"]
    cap = cv2.VideoCapture(str(tmp_path / "cam0.avi"))
    assert int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little") == b"MJPG"
    cap.release()
    bgr = _read(tmp_path / "cam0.avi", grey=False)  # default conversion: BGR
    assert bgr.shape == (len(take.t), 120, 160, 3)
    grey = cv2.cvtColor(bgr.reshape(-1, 160, 3), cv2.COLOR_BGR2GRAY).reshape(len(take.t), 120, 160)
    diff = np.abs(grey.astype(int) - take.cameras[0].frames)
    assert 0 < diff.mean() < 4.0  # lossy, but close (about 2.4 grey levels)
    truth = np.load(tmp_path / "truth2d.npz")
    assert str(truth["codec"]) == "mjpg" and str(truth["fourcc"]) == "MJPG"


def test_h264_writes_a_decodable_file_or_names_the_codec(tmp_path) -> None:
    try:
        take = make_take(tmp_path, None, rig=2, seconds=0.2, config=SimConfig(codec="h264"))
    except OSError as exc:
        assert "h264" in str(exc)
        return
    assert take.fourcc in ("avc1", "H264", "X264", "mp4v")
    assert take.video("cam1") == take.videos[1] and take.videos[1].exists()
    frames = _read(take.videos[0])
    assert len(frames) == len(take.t)
    assert np.abs(frames.astype(int) - take.cameras[0].frames).mean() < 6.0


def test_unknown_codec_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="codec"):
        make_take("unused", None, rig=2, seconds=0.1, config=SimConfig(codec="vp9"))


# ------------------------------------------------------------------ occlusion


def test_torso_hides_the_far_wrist_from_the_side() -> None:
    pose = tpose(DEFAULT_LENGTHS, stance="hip")
    ln = dict(zip(BONE_TYPES, DEFAULT_LENGTHS))
    for side in ("left", "right"):  # arms hanging at the sides
        sh = pose[J[f"{side}_shoulder"]]
        pose[J[f"{side}_elbow"]] = sh - (0, 0, ln["upper_arm"])
        pose[J[f"{side}_wrist"]] = sh - (0, 0, ln["upper_arm"] + ln["forearm"])
    cfg = SimConfig(limb_radius=0.0)  # the torso alone
    wrist_z = pose[J["left_wrist"], 2]
    side = occluded(pose[None], np.array([5.0, 0.0, wrist_z]), cfg)[0]
    assert side[2] and not side[3]  # from the subject's right: the left wrist is behind the torso
    back = occluded(pose[None], np.array([0.0, -5.0, 2.1]), SimConfig())[0]
    assert not back.any()  # from behind, every marker is in plain view


@pytest.mark.skipif(not (CMU / "005_01.bvh").exists(), reason=CMU_SKIP)
def test_walk_hides_some_markers_in_some_views() -> None:
    take = make_take("unused", CMU / "005_01.bvh", rig=default_rig(4), seconds=2.0, write=False)
    n = take.n_tpose
    vis = np.stack([c.visible[n:] for c in take.cameras])
    inside = np.stack([(c.uv[n:, :, 0] > 0) & (c.uv[n:, :, 0] < 160) & (c.uv[n:, :, 1] > 0) & (c.uv[n:, :, 1] < 120)
                       for c in take.cameras])
    hidden = (inside & ~vis).sum() / inside.sum()
    assert 0.02 < hidden < 0.4
    assert (inside & ~vis).any(axis=(1, 2)).all()  # in every camera


# ------------------------------------------------------------------ CLI


@needs_walk
def test_cli_warns_about_a_short_clip_and_reports(tmp_path, capsys) -> None:
    out = tmp_path / "take"
    rc = sim_main([str(out), "--bvh", str(WALK), "--seconds", "10", "--cameras", "2", "--fps", "30",
                   "--stance", "together", "--pose-at=-1,0.5", "--blackout", "2:0.5", "--blackout", "3:0.2"])
    err = capsys.readouterr().err
    assert rc == 0
    assert "samba-sim: clip is only 2.85 s; rendered all of it\n" in err
    lines = err.strip().splitlines()
    assert len(lines) == 2 and lines[1].startswith(f"wrote {out}: ")
    assert "x 2 cameras (ffv1, stance together" in lines[1] and "blackout 2+0.5 s 3+0.2 s)" in lines[1]
    truth = np.load(out / "truth2d.npz")
    assert truth["blackout"].sum() == 15 + 6 and not truth["visible"][:, truth["blackout"]].any()


def test_cli_exit_codes(tmp_path, capsys) -> None:
    out = str(tmp_path / "take")
    assert sim_main([out, "--bvh", str(tmp_path / "missing.bvh")]) == 1
    assert sim_main([out, "--joints", str(tmp_path / "missing.npz")]) == 1
    assert sim_main([out, "--calibration", str(tmp_path / "missing.toml")]) == 1
    assert "file not found" in capsys.readouterr().err
    for bad in (["--stance", "wide"], ["--stance", "2"], ["--pose-at", "1"], ["--blackout", "2"],
                ["--blackout", "1:0"], ["--codec", "vp9"], ["--seconds", "0"], ["--fps", "-5"]):
        with pytest.raises(SystemExit) as exc:
            sim_main([out, *bad])
        assert exc.value.code == 2, bad
    if WALK.exists():
        assert sim_main([out, "--bvh", str(WALK), "--start", "10"]) == 2  # nothing there
    assert not (tmp_path / "take").exists()


def test_cli_help_documents_the_hostile_options(capsys) -> None:
    with pytest.raises(SystemExit) as exc:
        sim_main(["--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for word in ("--stance", "hip|apart|together", "--pose-at", "--blackout", "START:SECONDS", "--codec", "mjpg"):
        assert word in text


def test_codec_without_encoder_is_a_clear_error(tmp_path, monkeypatch, capsys) -> None:
    from samba_mote.sim import take as take_mod

    monkeypatch.setitem(take_mod._CODEC_TRIES, "h264", [("zzzz", ".avi", True), ("zzzz", ".mp4", True)])
    with pytest.raises(OSError, match="cannot write h264 video.*zzzz"):
        make_take(tmp_path / "a", None, rig=2, seconds=0.1, config=SimConfig(codec="h264"))
    assert sim_main([str(tmp_path / "b"), "--codec", "h264", "--seconds", "0.1", "--cameras", "2"]) == 1
    assert "samba-sim: cannot write h264 video" in capsys.readouterr().err


def test_a_marker_in_front_of_a_lamp_is_hidden_in_the_truth():
    """A marker drawn on the large lamp near the top of an image is part of the lamp's blob (no
    camera could see it): the 2D truth calls it hidden there, and visible when it moves off."""
    from samba_mote.sim.render import make_distractors, render_camera

    cam = default_rig(4).cameras[0]
    cfg = SimConfig(occlusion=False)
    u, v, _r = make_distractors(cam.size, cfg, np.random.default_rng(7)).lamps[0]  # render_camera's first draw
    ray = cam.R.T @ np.r_[cam.undistort_normalized(np.array([[u, v]]))[0], 1.0]
    on_lamp = cam.center + 4.0 * ray / np.linalg.norm(ray)
    pose = tpose(DEFAULT_LENGTHS)
    joints = np.repeat(pose[None], 2, axis=0)
    joints[0, J["left_wrist"]] = on_lamp
    joints[1, J["left_wrist"]] = on_lamp + np.array([0.0, 0.0, -1.0])  # well below the lamp
    rendered = render_camera(cam, joints, cfg, seed=7)
    m = list(MARKER_JOINT).index(J["left_wrist"])
    assert np.hypot(*(rendered.uv[0, m] - (u, v))) < 0.5
    assert not rendered.visible[0, m]
    assert rendered.visible[1, m]
