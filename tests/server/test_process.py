"""samba-process on simulated videos: the offline path reaches the accuracy of the
reconstruction from clean markers within +0.5 cm, and says (and lets the user say) where the
markers sit."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.formats import load_joints
from samba_common.skeleton import MARKER_JOINT
from samba_mote.sim.render import render_take
from samba_server.cli.process import legs_warnings, main, unnamed_warnings
from samba_server.cli.replay import main as replay_main
from samba_server.recon import reconstruct_take
from samba_server.record import TakeReader

from .conftest import short_take

FPS = 30.0


def _write_videos(tmp_path, rig, joints, t):
    paths = []
    for cam in render_take(joints, t, rig, seed=3):
        p = tmp_path / f"{cam.name}.avi"
        out = cv2.VideoWriter(str(p), cv2.VideoWriter_fourcc(*"FFV1"), FPS, cam.frames.shape[2:0:-1], isColor=False)
        for f in cam.frames:
            out.write(f)
        out.release()
        paths.append(p)
    return paths


def _run_process(tmp_path, capsys):
    joints, t = short_take(seconds=2.0, fps=FPS)
    rig = default_rig(4)
    calib = tmp_path / "calibration.toml"
    rig.save(calib)
    videos = _write_videos(tmp_path, rig, joints, t)
    out, take = tmp_path / "joints.npz", tmp_path / "take.mcap"
    assert main([str(calib), *map(str, videos), "--out", str(out), "--fps", "30", "--record", str(take)]) == 0
    # markers on the joint centres: the standard pose says so, the summary tells the user, the
    # file carries the subject solved with; a good take prints no warning
    err = capsys.readouterr().err
    assert "marker placement: joint centres (auto: standard pose" in err and "WARNING" not in err
    assert str(np.load(out)["subject_placement"]) == "joint_centres"
    # the user overrides it: --placement skin is what the solver uses, and a replay of the
    # recording places the markers as the recording server did; --one-pass output is the live
    # one, so the replay equals it
    told, told_take, replayed = tmp_path / "told.npz", tmp_path / "told.mcap", tmp_path / "replayed.npz"
    assert main([str(calib), *map(str, videos), "--out", str(told), "--fps", "30", "--placement", "skin",
                 "--record", str(told_take), "--one-pass"]) == 0
    assert "from_backward" not in np.load(told)
    assert np.load(told)["legs_unsure"].shape == (len(joints),)  # the live pass's doubt, one-pass too
    assert not np.load(out)["legs_unsure"][-int(0.3 * FPS):].any()  # legs apart, tracked: sure
    assert "marker placement: skin (given: --placement" in capsys.readouterr().err
    assert str(np.load(told)["subject_placement"]) == "skin"
    assert replay_main([str(told_take), "--out", str(replayed)]) == 0
    assert str(np.load(replayed)["subject_placement"]) == "skin"
    np.testing.assert_array_equal(load_joints(replayed).joints, load_joints(told).joints)
    got = load_joints(out)
    assert np.load(out)["from_backward"].shape == (len(joints),)  # labelled from both ends by default
    # every solved joint carries its bound; the markers' joints are measured, so confident
    bound = np.load(out)["joint_bound"]
    solved_rows = np.isfinite(load_joints(out).joints).all(axis=(1, 2))
    assert bound.shape == (len(joints), 13) and np.isfinite(bound[solved_rows]).all()
    assert np.median(bound[solved_rows][:, list(MARKER_JOINT)]) < 0.05
    np.testing.assert_array_equal(np.load(replayed)["joint_bound"], np.load(told)["joint_bound"])
    assert got.joints.shape == joints.shape  # one row per video frame
    np.testing.assert_allclose(got.t, np.arange(len(joints)) / FPS)
    clean, _ = reconstruct_take(joints[:, list(MARKER_JOINT)], t)
    body = slice(int(1.6 * FPS), None)  # after the standard pose and the blend into the clip
    err = np.nanmean(np.linalg.norm(got.joints[body] - joints[body], axis=2))
    ref = np.nanmean(np.linalg.norm(clean[body] - joints[body], axis=2))
    solved = np.isfinite(got.joints[body]).all(axis=(1, 2)).mean()
    print(f"samba-process {100 * err:.2f} cm vs clean markers {100 * ref:.2f} cm, solved {solved:.0%}")
    assert solved > 0.95
    assert sum(1 for m in TakeReader(take) if m.mote_id) == 4 * len(joints)
    return err, ref


def test_process_videos_close_to_clean_markers(tmp_path, capsys):
    """Rendered videos -> mote pipeline -> server pipeline (3D-first labelling): within +2 cm of
    the reconstruction from the true markers. The target is +0.5 cm; the 3D labelling measured
    +1.6 cm on this take (merged blobs bias the points; docs/BENCHMARKS.md), so this guards
    against regressions, not the target. On the same videos: the marker placement decided from
    the standard pose is printed and written into joints.npz, ``--placement`` overrides it, and
    a replay of that recording places the markers the same way (equal joints)."""
    err, ref = _run_process(tmp_path, capsys)
    assert err <= ref + 0.02


def test_a_labelling_error_costs_its_frame_not_the_take(tmp_path, capsys, monkeypatch):
    """A bug in the labelling (here: an exception on one frame of each pass) leaves that frame
    unnamed, logged and counted; samba-process still writes every frame, solves the rest and
    says so loudly (it crashed before, losing the whole take)."""
    from samba_server.labelling.labeller import Labeller
    joints, t = short_take(seconds=2.0, fps=FPS)
    rig = default_rig(4)
    calib = tmp_path / "calibration.toml"
    rig.save(calib)
    videos = _write_videos(tmp_path, rig, joints, t)
    label = Labeller._label
    calls = {"n": 0}

    def failing(self, packets, t_s):
        calls["n"] += 1
        if calls["n"] % len(joints) == 45:  # frame 45 forwards, frame 14 backwards
            raise RuntimeError("injected labelling bug")
        return label(self, packets, t_s)

    monkeypatch.setattr(Labeller, "_label", failing)
    out = tmp_path / "joints.npz"
    assert main([str(calib), *map(str, videos), "--out", str(out), "--fps", "30"]) == 0
    err = capsys.readouterr().err
    assert "WARNING: the labelling failed on 2 frame(s)" in err
    got = load_joints(out)
    assert got.joints.shape == joints.shape
    assert np.isfinite(got.joints[int(1.6 * FPS):]).all(axis=(1, 2)).mean() > 0.95


@pytest.mark.parametrize("one_pass", [False, True])
def test_two_cameras_flag_every_left_right_joint_as_a_guess(tmp_path, caplog, one_pass):
    """With two cameras a naming and its mirror image fit bodies alike: samba-process (both
    passes, and the live one) gives every shoulder, elbow, wrist, knee and ankle a bound at
    least its distance from the other side's, so a left joint drawn where the right one is
    is not a confident joint. The warning says that 3 cameras are needed."""
    from samba_common.skeleton import JOINT_NAMES

    joints, t = short_take(seconds=1.0, fps=FPS)
    rig = default_rig(2)
    calib = tmp_path / "calibration.toml"
    rig.save(calib)
    videos = _write_videos(tmp_path, rig, joints, t)
    out = tmp_path / "joints.npz"
    with caplog.at_level("WARNING", logger="samba_server.app"):
        assert main([str(calib), *map(str, videos), "--out", str(out), "--fps", "30"]
                    + (["--one-pass"] if one_pass else [])) in (0, 1)
    assert any("use 3 or more cameras" in r.getMessage() for r in caplog.records)
    z = np.load(out)
    got, bound = z["joints"], z["joint_bound"]
    solved = np.isfinite(got).all(axis=(1, 2))
    assert solved.mean() > 0.5
    for side in ("shoulder", "elbow", "wrist", "knee", "ankle"):
        left, right = JOINT_NAMES.index(f"left_{side}"), JOINT_NAMES.index(f"right_{side}")
        apart = np.linalg.norm(got[solved, left] - got[solved, right], axis=1)
        assert (bound[solved, left] >= apart - 1e-9).all() and (bound[solved, right] >= apart - 1e-9).all()
    assert (bound[solved, JOINT_NAMES.index("left_shoulder")] >= 0.2).mean() > 0.9  # shoulders 0.3-0.4 m apart


def test_process_bad_inputs(tmp_path, capsys):
    rig = default_rig(2)
    calib = tmp_path / "calibration.toml"
    rig.save(calib)
    assert main([str(calib), str(tmp_path / "cam0.avi"), "--out", str(tmp_path / "o.npz"), "--fps", "30"]) == 1
    assert "not found" in capsys.readouterr().err
    (tmp_path / "cam9.avi").write_bytes(b"junk")
    assert main([str(calib), str(tmp_path / "cam9.avi"), "--out", str(tmp_path / "o.npz"), "--fps", "30"]) == 1
    with pytest.raises(SystemExit) as exc:
        main([str(calib)])
    assert exc.value.code == 2


def test_a_limb_the_solver_guessed_in_many_frames_is_reported():
    """A marker left unnamed in more than a tenth of the frames with a pose gets a warning
    naming the limb the solver guessed; frames without a pose (a blackout) do not count, and a
    marker hidden now and then (every take has some) is not reported."""
    F = 100
    joints = np.zeros((F, 13, 3))
    markers = np.zeros((F, 8, 3))
    joints[80:] = np.nan  # a blackout: no pose
    markers[80:] = np.nan
    markers[:5, 0] = np.nan  # left shoulder hidden in 5 of 80 posed frames: usual
    assert unnamed_warnings(markers, joints) == []
    markers[10:25, 2] = np.nan  # left wrist in 15 of 80
    (line,) = unnamed_warnings(markers, joints)
    assert line.startswith("left wrist unnamed in 15 of 80 frames with a pose (19 %)") and "left arm" in line
    markers[:30, 7] = np.nan  # and the right ankle in 30
    assert [w.split(" unnamed")[0] for w in unnamed_warnings(markers, joints)] == ["left wrist", "right ankle"]
    assert "right leg" in unnamed_warnings(markers, joints)[1]


def test_hands_together_are_reported_apart_from_guessed_limbs():
    """Both wrists left unnamed because no view saw them apart (hands together) are not the
    solver's guess: one line says so, and the wrists are not reported as guessed limbs there;
    a wrist unnamed in other frames still is."""
    F = 100
    joints = np.zeros((F, 13, 3))
    markers = np.zeros((F, 8, 3))
    together = np.zeros(F, bool)
    together[20:60] = True
    markers[20:60, 2:4] = np.nan
    lines = unnamed_warnings(markers, joints, together)
    assert len(lines) == 1 and lines[0].startswith("both wrists unnamed in 40 of 100 frames") and "apart" in lines[0]
    markers[70:90, 2] = np.nan  # the left wrist hidden elsewhere: guessed there
    lines = unnamed_warnings(markers, joints, together)
    assert len(lines) == 2 and lines[1].startswith("left wrist unnamed in 20 of 100 frames")
    assert [w.split(" unnamed")[0] for w in unnamed_warnings(markers, joints)] == ["left wrist", "right wrist"]


def test_legs_unsure_of_their_side_for_half_a_second_are_reported():
    """Legs whose left and right were unsure (legs_unsure) in frames with a pose for 0.5 s or
    more get one warning with the longest stretch; a shorter doubt, or one only in frames
    without a pose, is not reported."""
    F, fps = 300, 60.0
    t = np.arange(F) / fps
    joints = np.zeros((F, 13, 3))
    joints[100:160] = np.nan  # a blackout
    unsure = np.zeros(F, bool)
    unsure[100:160] = True  # unsure only where there is no pose
    unsure[170:190] = True  # and for a third of a second
    assert legs_warnings(unsure, joints, t) == []
    unsure[240:270] = True  # and half a second more
    (line,) = legs_warnings(unsure, joints, t)
    assert line.startswith("left and right legs unsure in 50 of 240 frames with a pose (longest 4.00-4.48 s)")
    assert legs_warnings(None, joints, t) == []
