import numpy as np
import pytest

from samba_common.body import bone_lengths, decompose, fk, prepend_standard_pose, standard_pose
from samba_common.bvh import BvhError, load_bvh, put_on_floor, resample
from samba_common.skeleton import J

from .bvh_factory import write_cmu_bvh


def test_classic_cmu_naming_is_mapped_and_converted(tmp_path):
    take = load_bvh(write_cmu_bvh(tmp_path / "walk.bvh"))
    assert take.mapping == "cmu_classic" and take.joints.shape == (40, 13, 3)
    j = take.joints[0]
    assert j[J["head"], 2] > j[J["left_hip"], 2] > j[J["left_ankle"], 2]      # Z is up
    # units inferred: 42 cm shin -> metres
    assert np.isclose(np.linalg.norm(j[J["left_knee"]] - j[J["left_ankle"]]), 0.42, atol=1e-6)
    assert np.isclose(take.fps, 60.0, rtol=1e-4)
    # the root moved along BVH +Z (forward), which is Samba -Y
    assert take.joints[-1, J["head"], 1] < take.joints[0, J["head"], 1]


def test_shared_clip_has_the_documented_body(cmu_dir):
    take = load_bvh(cmu_dir / "002_01.bvh")
    assert take.mapping == "cc_base"
    sw = np.linalg.norm(take.joints[:, J["left_shoulder"]] - take.joints[:, J["right_shoulder"]], axis=1)
    assert np.allclose(sw, 0.367, atol=0.003)   # README: shoulder width about 36.7 cm


def test_bad_bvh_files(tmp_path):
    p = tmp_path / "x.bvh"
    p.write_text("")
    with pytest.raises(BvhError, match="empty"):
        load_bvh(p)
    p.write_text("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0\n")
    with pytest.raises(BvhError, match="malformed"):
        load_bvh(p)
    good = write_cmu_bvh(tmp_path / "g.bvh").read_text()
    p.write_text(good.replace("LeftUpLeg", "Thing"))
    with pytest.raises(BvhError, match="no mapping fits"):
        load_bvh(p)


def test_fk_decompose_round_trip_and_standard_pose(tmp_path):
    take = load_bvh(write_cmu_bvh(tmp_path / "w.bvh"))
    lens = np.median(bone_lengths(take.joints), axis=0)
    o, R, d = decompose(take.joints)
    back = fk(o, R, d, lens)
    assert np.abs(back - take.joints).max() < 1e-9  # symmetric synthetic body
    sp = standard_pose(lens, (1.0, 2.0))
    assert np.isclose(sp[J["left_ankle"], 2], 0.08) and sp[J["left_wrist"], 0] < sp[J["right_wrist"], 0]
    full = prepend_standard_pose(put_on_floor(take.joints), 60.0)
    assert len(full) == 40 + 60 + 30
    assert np.allclose(bone_lengths(full), lens, atol=1e-9)
    r, t = resample(take.joints, take.t, 30.0)
    assert len(t) == 20 and np.allclose(r[1], take.joints[2], atol=1e-4)
