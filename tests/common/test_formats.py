import numpy as np
import pytest

from samba_common.formats import FormatError, load_joints, load_markers, save_joints, save_markers
from samba_common.skeleton import JOINT_NAMES, MARKER_NAMES


def test_markers_round_trip_keeps_nan(tmp_path):
    m = np.random.default_rng(0).normal(size=(5, 8, 3))
    m[2, 3] = np.nan
    t = np.arange(5) / 30
    save_markers(tmp_path / "m.npz", m, t)
    take = load_markers(tmp_path / "m.npz")
    np.testing.assert_array_equal(take.markers, m)
    np.testing.assert_array_equal(take.t, t)


def test_joints_round_trip_with_extra_keys(tmp_path):
    j = np.zeros((3, 13, 3))
    save_joints(tmp_path / "j.npz", j, np.arange(3.0), residual=np.ones(3))
    take = load_joints(tmp_path / "j.npz")
    assert take.joints.shape == (3, 13, 3)
    np.testing.assert_array_equal(take.extra["residual"], np.ones(3))


@pytest.mark.parametrize("broken, key", [
    (dict(markers=np.zeros((4, 7, 3))), "markers"),
    (dict(t=np.arange(3.0)), "t"),
    (dict(t=np.array([0.0, 2.0, 1.0, 3.0])), "t"),
    (dict(marker_names=np.array(MARKER_NAMES[::-1])), "marker_names"),
    (dict(markers=np.full((4, 8, 3), "x")), "markers"),
])
def test_bad_markers_name_the_file_and_key(tmp_path, broken, key):
    data = dict(markers=np.zeros((4, 8, 3)), t=np.arange(4.0), marker_names=np.array(MARKER_NAMES))
    data.update(broken)
    p = tmp_path / "bad.npz"
    np.savez(p, **data)
    with pytest.raises(FormatError) as err:
        load_markers(p)
    assert str(p) in str(err.value) and f"[{key}]" in str(err.value)


def test_missing_key_and_garbage_file(tmp_path):
    p = tmp_path / "j.npz"
    np.savez(p, joints=np.zeros((2, 13, 3)), t=np.arange(2.0))
    with pytest.raises(FormatError, match=r"\[joint_names\]"):
        load_joints(p)
    g = tmp_path / "garbage.npz"
    g.write_bytes(b"not a zip")
    with pytest.raises(FormatError, match="not a readable"):
        load_markers(g)
    with pytest.raises(FormatError, match="not found"):
        load_markers(tmp_path / "nope.npz")


def test_joint_names_are_the_contract():
    assert JOINT_NAMES[0] == "head" and JOINT_NAMES[-1] == "right_ankle" and len(JOINT_NAMES) == 13
