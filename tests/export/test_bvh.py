"""BVH export: FK of the written file reproduces the take, axes/units as Blender expects,
NaN frames held, twist continuous, and the lead's BVH loader reads it back."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from samba_common.bvh import BvhError, read_bvh
from samba_common.skeleton import J
from samba_server.export.bvh import fk_positions, write_bvh
from samba_server.export.take import ExportTake, TakeError
from tests.shared_data import CMU_DIR, CMU_SKIP

CMU = CMU_DIR / "002_01.bvh"


def _take(joints, t, name="synthetic"):
    return ExportTake(np.asarray(joints, float), np.asarray(t, float), None, name)


def test_fk_of_written_file_reproduces_positions_within_1mm(tmp_path, walk):
    joints, t = walk
    out = tmp_path / "walk.bvh"
    report = write_bvh(out, _take(joints, t))
    back = fk_positions(read_bvh(out))
    assert back.shape == joints.shape
    err = np.linalg.norm(back - joints, axis=-1)
    assert err.max() < 1e-3, f"max FK error {err.max() * 1e3:.3f} mm"
    assert report.max_error_m < 1e-3 and report.n_held == 0
    # the skeleton carries the subject's bone lengths (cm in the file)
    assert report.bone_lengths_cm["left_thigh"] == pytest.approx(44.0, abs=0.01)
    assert report.bone_lengths_cm["sh_width"] == pytest.approx(36.0, abs=0.01)


def test_lead_loader_reads_export_back(tmp_path, walk):
    bvh = pytest.importorskip("samba_common.bvh")
    joints, t = walk
    out = tmp_path / "walk.bvh"
    write_bvh(out, _take(joints, t))
    take = bvh.load_bvh(out)  # auto-detects the CMU-style names, infers centimetres
    assert take.joints.shape == joints.shape
    assert take.fps == pytest.approx(60.0, rel=1e-6)
    assert np.abs(take.joints - joints).max() < 1e-3


def test_axes_units_y_up_centimetres_facing_minus_z(tmp_path, walk):
    joints, t = walk
    out = tmp_path / "walk.bvh"
    write_bvh(out, _take(joints, t))
    f = read_bvh(out)
    assert f.frame_time == pytest.approx(1 / 60, rel=1e-6)
    off = {j.name: j.offset for j in f.joints}
    assert off["LeftUpLeg"][0] < 0 < off["RightUpLeg"][0]  # left is -X
    assert off["Chest"][1] == pytest.approx(52.0, abs=0.01)  # torso up +Y, in cm
    assert off["LeftLeg"][1] == pytest.approx(-44.0, abs=0.01)
    root = f.motion[:, :3]
    hipmid = 0.5 * (joints[:, J["left_hip"]] + joints[:, J["right_hip"]])
    np.testing.assert_allclose(root[:, 1], 100 * hipmid[:, 2], atol=1e-4)   # height -> Y
    np.testing.assert_allclose(root[:, 2], -100 * hipmid[:, 1], atol=1e-4)  # forward +Y -> -Z
    text = out.read_text()
    assert text.startswith("HIERARCHY\nROOT Hips") and "Frames: 120" in text


def test_twist_is_continuous(tmp_path, walk):
    """No joint's local rotation jumps more than 20 degrees between frames of a smooth walk."""
    joints, t = walk
    out = tmp_path / "walk.bvh"
    write_bvh(out, _take(joints, t))
    f = read_bvh(out)
    for j in f.joints:
        start = j.first + (3 if j.parent < 0 else 0)
        R = Rotation.from_euler("ZXY", f.motion[:, start:start + 3], degrees=True)
        jump = np.degrees((R[1:] * R[:-1].inv()).magnitude()).max()
        assert jump < 20.0, f"{j.name} jumps {jump:.1f} deg"


def test_nan_frames_hold_last_pose(tmp_path, walk, caplog):
    joints, t = walk
    j = joints.copy()
    j[:3] = np.nan          # leading gap: takes the first complete pose
    j[40:50] = np.nan       # whole frames unsolved
    j[70, J["left_elbow"]] = np.nan  # one joint missing
    out = tmp_path / "gaps.bvh"
    with caplog.at_level("WARNING"):
        report = write_bvh(out, _take(j, t))
    assert report.n_held == 14 and "holding the last complete pose" in caplog.text
    back = fk_positions(read_bvh(out))
    assert back.shape[0] == 120  # never drop frames
    np.testing.assert_allclose(back[0], joints[3], atol=1e-3)
    np.testing.assert_allclose(back[45], joints[39], atol=1e-3)
    np.testing.assert_allclose(back[70], joints[69], atol=1e-3)
    ok = np.all(np.isfinite(j), axis=(1, 2))
    assert np.abs(back[ok] - joints[ok]).max() < 1e-3


def test_all_nan_take_is_refused(tmp_path, walk):
    joints, t = walk
    with pytest.raises(TakeError, match="nothing to export"):
        write_bvh(tmp_path / "x.bvh", _take(np.full_like(joints, np.nan), t))
    assert not (tmp_path / "x.bvh").exists()


@pytest.mark.skipif(not CMU.exists(), reason=CMU_SKIP)
def test_real_clip_legs_exact_and_error_reported(tmp_path):
    """A real CMU clip: its spine bends, so torso length varies; legs keep their lengths."""
    from samba_common.bvh import load_bvh

    src = load_bvh(CMU)
    out = tmp_path / "cmu.bvh"
    report = write_bvh(out, _take(src.joints, src.t, str(CMU)))
    back = fk_positions(read_bvh(out))
    legs = [J[n] for n in ("left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")]
    assert np.abs(back[:, legs] - src.joints[:, legs]).max() < 1e-3
    err = np.linalg.norm(back - src.joints, axis=-1).max()
    assert report.max_error_m == pytest.approx(err, abs=1e-6)
    assert err < 0.01  # the residual from a varying torso stays small on this walk


def test_parse_rejects_garbage(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0\n")
    with pytest.raises(BvhError, match="bad.bvh"):
        read_bvh(bad)
    bad.write_text("not a bvh")
    with pytest.raises(BvhError, match="HIERARCHY"):
        read_bvh(bad)
