import numpy as np
import pytest

from samba_common.align import AlignmentError, align, align_batch, marker_frame, unalign
from samba_common.body import STANDARD_R, fk, standard_dirs, standard_pose
from samba_common.skeleton import MARKER_JOINT

LENGTHS = np.array([0.37, 0.19, 0.5, 0.14, 0.25, 0.26, 0.47, 0.45])


def _markers(joints):
    return joints[list(MARKER_JOINT)]


def test_round_trip_random_poses():
    rng = np.random.default_rng(0)
    for _ in range(20):
        m = rng.normal(size=(8, 3))
        f = marker_frame(m)
        back = unalign(align(m, f), f)
        np.testing.assert_allclose(back, m, atol=1e-12)
        assert np.isclose(np.linalg.det(f.R), 1.0)


def test_standard_pose_frame_and_scale():
    m = _markers(standard_pose(LENGTHS))
    f = marker_frame(m)
    a = align(m, f)
    np.testing.assert_allclose(a[0], [0.5 * LENGTHS[0] / LENGTHS[7], 0, 0], atol=1e-12)  # left shoulder on +x
    np.testing.assert_allclose(f.R[:, 2], [0, 1, 0], atol=1e-12)   # z forward = world +Y
    np.testing.assert_allclose(f.R[:, 1], [0, 0, 1], atol=1e-12)   # y up
    assert np.isclose(np.linalg.norm(a[4] - a[6]), 1.0)           # shin = 1


def test_arms_along_shoulder_line_do_not_degenerate():
    """The thesis' wrist-based y axis fails in a T-pose; ours must not."""
    m = _markers(standard_pose(LENGTHS))
    assert np.all(np.isfinite(align(m, marker_frame(m))))


def test_feet_on_the_shoulder_line_fall_back_to_knees_then_world():
    m = _markers(standard_pose(LENGTHS))
    o = 0.5 * (m[0] + m[1])
    x = m[0] - m[1]
    m[6] = o + 2 * x   # both ankles on the shoulder line
    m[7] = o + 2 * x
    f = marker_frame(m)
    np.testing.assert_allclose(f.R[:, 1], [0, 0, 1], atol=1e-9)  # knees below: still upright
    m[4] = m[5] = o + 3 * x
    f = marker_frame(m)
    assert np.all(np.isfinite(f.R)) and np.isclose(np.linalg.det(f.R), 1.0)


def test_lying_subject_uses_its_own_up():
    R_lying = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]) @ STANDARD_R  # rotated 90 deg about x
    j = fk(np.array([0, 0, 0.3]), R_lying, standard_dirs(), LENGTHS)
    f = marker_frame(_markers(j))
    assert np.allclose(f.R[:, 1], R_lying[:, 1], atol=1e-9)


def test_missing_shoulder_or_no_shin_is_an_error():
    m = _markers(standard_pose(LENGTHS))
    bad = m.copy()
    bad[0] = np.nan
    with pytest.raises(AlignmentError):
        marker_frame(bad)
    bad = m.copy()
    bad[[4, 5]] = np.nan
    with pytest.raises(AlignmentError):
        marker_frame(bad)
    assert np.all(np.isfinite(marker_frame(bad, scale=1.0).R))


def test_batch_matches_single():
    rng = np.random.default_rng(3)
    ms = rng.normal(size=(6, 8, 3))
    out = align_batch(ms)
    for i in range(6):
        np.testing.assert_allclose(out[i], align(ms[i], marker_frame(ms[i], scale=1.0)), atol=1e-12)
