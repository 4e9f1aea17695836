"""Scoring a take's names against its ground truth (samba_server/labelling/score.py), as the
labelling benchmark reports them."""

from __future__ import annotations

import numpy as np

from samba_common.skeleton import MARKER_JOINT
from samba_mote.sim.motion import synthetic_motion
from samba_server.labelling.rigid import LK, RK, RW
from samba_server.labelling.score import score_take


def test_a_name_between_two_merged_markers_is_right_and_one_on_a_far_ghost_is_wrong():
    """Three frames of a walk, every marker visible. Frame 0 named exactly; frame 1 the left
    knee named by the two knees' midpoint (merged, no view parts them), 14 cm from each, a
    little nearer its own: right; frame 2 the right wrist named on a point 33 cm from it and farther
    still from every other marker (a ghost): wrong, though no other marker is
    nearer (it used to count right)."""
    joints, _t = synthetic_motion(1.0, 60.0)
    joints = joints[:3]
    truth = joints[:, list(MARKER_JOINT)]
    named = truth.copy()
    knees = truth[1, [LK, RK]]
    apart = knees[0] - knees[1]
    named[1, LK] = knees.mean(axis=0) + 0.005 * apart / np.linalg.norm(apart)  # a little nearer the left knee
    assert 0.08 < np.linalg.norm(named[1, LK] - knees[0]) < 0.16  # beyond tol_m: right as the nearest
    away = np.cross(truth[2, RW] - truth[2, LK], [0.0, 0.0, 1.0])
    named[2, RW] = truth[2, RW] + 0.33 * away / np.linalg.norm(away)
    assert np.linalg.norm(np.delete(truth[2], RW, axis=0) - named[2, RW], axis=1).min() > 0.33
    visible = np.ones((3, 8), bool)
    s = score_take(named, joints, joints, visible, np.zeros(3, bool), 60.0)
    assert s.frames == 3
    assert s.wrong_frames == 1
    assert np.isclose(s.correct, 2 / 3)


def test_frames_not_all_right_after_a_teleport_of_the_ground_truth_are_counted_apart():
    """A walk whose right knee, in the truth itself, swings 35 cm in one frame at frame 30 and
    back at frame 40 (CMU subject 005's glitch): the names that stay where the knee was for
    frames 30-34 (wrong) count as frames after a teleport; a wrong wrist at frame 80, long after
    the knee came back, and one at frame 20, before it jumped, do not."""
    joints, _t = synthetic_motion(2.0, 60.0)
    joints = joints[:100].copy()
    knee = MARKER_JOINT[RK]
    joints[30:40, knee] += [0.35, 0.0, 0.0]
    truth = joints[:, list(MARKER_JOINT)]
    named = truth.copy()
    named[30:35, RK] = truth[29, RK]  # the name stays where the knee was
    named[[20, 80], RW] += [0.0, 0.3, 0.0]
    s = score_take(named, joints, joints, np.ones((100, 8), bool), np.zeros(100, bool), 60.0)
    assert s.frames == 100 and s.wrong_frames == 7
    assert s.near_teleport == 5
    smooth = joints.copy()
    smooth[30:40, knee] -= [0.35, 0.0, 0.0]
    assert score_take(named, smooth, smooth, np.ones((100, 8), bool), np.zeros(100, bool), 60.0).near_teleport == 0
