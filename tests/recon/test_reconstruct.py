from dataclasses import replace

import numpy as np
import pytest

from samba_common.body import bone_lengths, prepend_standard_pose
from samba_common.bvh import load_bvh, resample
from samba_common.markerset import TYPICAL_OFFSETS, markers_from_joints
from samba_common.skeleton import JOINT_NAMES, MARKER_JOINT, UNOBSERVED_JOINTS
from samba_server.recon.db import load_default_db
from samba_server.recon.evaluate import mpjpe, observe, vary_body
from samba_server.recon.proportions import ProportionError, estimate_lengths
from samba_server.recon.reconstruct import PoseResult, Reconstructor, merge_passes, reconstruct_take


@pytest.fixture(scope="module")
def held_out(cmu_dir):
    """Subject 6's walk on a body unlike the database's, and a database without subject 6."""
    rng = np.random.default_rng(11)
    take = load_bvh(cmu_dir / "006_01.bvh")
    joints, _t = resample(take.joints, take.t, 30.0)
    truth, lengths = vary_body(joints[:120], rng)
    truth = prepend_standard_pose(truth, 30.0)
    t = np.arange(len(truth)) / 30.0
    db = load_default_db().without(lambda n: n.startswith("006_"))
    return truth, lengths, t, db, observe(truth, rng)


def test_held_out_walk_is_accurate_with_its_own_proportions(held_out):
    truth, lengths, t, db, markers = held_out
    est, info = reconstruct_take(markers, t, db)
    assert est.shape == truth.shape and np.all(info["status"] == "solved")
    assert mpjpe(est, truth) < 0.025
    assert mpjpe(est, truth, UNOBSERVED_JOINTS) < 0.045
    # the subject's proportions, not the database body's
    got = np.median(bone_lengths(est), axis=0)
    assert np.all(np.abs(got - lengths)[[0, 7]] < 0.005)            # shoulder width, shin: observed
    assert abs(got[4] + got[5] - lengths[4] - lengths[5]) < 0.015     # whole arm: observed when straight
    assert np.ptp(bone_lengths(est), axis=0).max() < 1e-6         # lengths fixed over the take


def test_missing_markers_short_gaps_bridged_long_gaps_nan(held_out):
    truth, _lengths, t, db, markers = held_out
    m = markers.copy()
    m[70:73] = np.nan          # 0.1 s: bridged by the temporal model
    m[100:125] = np.nan        # 0.83 s: too long, NaN after max_gap
    m[130, [0, 2, 4]] = np.nan  # a few markers missing: still solved
    # causal (as live): a gap is bridged for max_gap (0.3 s = 9 frames) after the last good frame
    est, info = reconstruct_take(m, t, db, both_ways=False)
    assert len(est) == len(t)
    assert list(info["status"][70:73]) == ["bridged"] * 3
    assert np.all(np.isfinite(est[70:73])) and mpjpe(est[70:73], truth[70:73]) < 0.08
    assert np.all(np.isfinite(est[100:108])) and set(info["status"][100:108]) == {"bridged"}
    assert np.all(np.isnan(est[110:125])) and set(info["status"][110:125]) == {"unsolved"}
    assert info["status"][130] == "solved" and mpjpe(est[130:131], truth[130:131]) < 0.05
    assert np.all(np.isfinite(est[125:]))  # recovers after the gap
    # offline, both ways: still bridged forwards only; a backward bridge would invent poses up to
    # max_gap before the markers return, deep into a blackout
    est2, info2 = reconstruct_take(m, t, db)
    assert len(est2) == len(t)
    assert np.all(np.isfinite(est2[100:108])) and set(info2["status"][100:108]) == {"bridged"}
    assert np.all(np.isnan(est2[110:125])) and set(info2["status"][110:125]) == {"unsolved"}
    assert np.all(np.isfinite(est2[125:]))
    both = np.all(np.isfinite(est), axis=(1, 2)) & np.all(np.isfinite(est2), axis=(1, 2))
    assert mpjpe(est2[both], truth[both]) <= mpjpe(est[both], truth[both]) + 0.002


def test_a_solver_error_on_one_frame_leaves_that_frame_unsolved_not_the_take(held_out, monkeypatch, caplog):
    """A frame the solver raises on (a bug, a numerical failure) is logged and left NaN in both
    passes; the take is still reconstructed around it."""
    truth, _lengths, t, db, markers = held_out
    solve = Reconstructor.solve

    def failing(self, m, tt, loose=None):
        if abs(abs(tt) - t[80]) < 1e-9:
            raise FloatingPointError("injected")
        return solve(self, m, tt, loose)

    monkeypatch.setattr(Reconstructor, "solve", failing)
    est, info = reconstruct_take(markers, t, db)
    assert np.isnan(est[80]).all() and info["status"][80] == "unsolved"
    ok = np.ones(len(t), bool)
    ok[80] = False
    assert np.isfinite(est[ok]).all() and mpjpe(est[ok], truth[ok]) < 0.03
    assert "solver failed" in caplog.text


def test_live_solver_estimates_the_body_from_the_standard_pose(held_out):
    truth, lengths, t, db, markers = held_out
    rec = Reconstructor(db)
    out = np.array([rec.solve(markers[i], t[i]).joints for i in range(len(t))])
    assert rec.lengths is not None and abs(rec.lengths[7] - lengths[7]) < 0.01
    assert mpjpe(out[40:], truth[40:]) < 0.03


def test_solve_is_deterministic(held_out):
    _truth, lengths, t, db, markers = held_out
    a = [Reconstructor(db, lengths=lengths).solve(markers[i], t[i]).joints for i in range(3)]
    rec = Reconstructor(db, lengths=lengths)
    b = [rec.solve(markers[i], t[i]).joints for i in range(3)]
    np.testing.assert_array_equal(a[0], b[0])


def test_take_without_enough_body_is_a_clear_error(held_out):
    m = np.full((10, 8, 3), np.nan)
    with pytest.raises(ProportionError, match="never seen"):
        estimate_lengths(m, load_default_db().mean_lengths)
    markers = held_out[4]
    with pytest.raises(ProportionError, match="millimetres"):
        estimate_lengths(markers * 1000.0, load_default_db().mean_lengths)


def test_single_frame_and_sparse_takes_keep_every_frame(held_out):
    truth, _lengths, t, db, markers = held_out
    est, info = reconstruct_take(markers[40:41], t[40:41], db)
    assert est.shape == (1, 13, 3) and mpjpe(est, truth[40:41]) < 0.08
    sparse = np.full_like(markers, np.nan)
    sparse[::30] = markers[::30]           # one frame a second, nothing between
    est, info = reconstruct_take(sparse, t, db)
    assert est.shape == truth.shape
    assert np.all(np.isfinite(est[30::30])) and set(info["status"][30::30]) == {"solved"}
    assert np.all(np.isfinite(est[32::30])) and set(info["status"][32::30]) == {"bridged"}  # 67 ms away
    assert np.all(np.isnan(est[15::30])) and set(info["status"][15::30]) == {"unsolved"}    # 0.5 s away


def _rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_merging_two_passes_keeps_the_limbs_both_put_in_the_same_place(held_out):
    """The two passes may turn the torso differently and still put a limb at the same place in
    the world: the merged limb stays there (its bones are averaged as world directions, not in
    two different torso frames)."""
    truth, lengths, t, db, markers = held_out
    rec = Reconstructor(db, lengths=lengths)
    a = [rec.solve(markers[i], t[i]) for i in range(40)][-1]
    R, o, d = a.state
    Rb = R @ _rot_z(12.0)
    db_ = d @ R.T @ Rb  # the same world bone directions, in b's torso frame
    b = PoseResult(a.joints, a.residual, a.n_markers, a.iterations, "solved", (Rb, o, db_))
    joints, _ = merge_passes([a], [b], lengths)
    for lo, hi in (("left_elbow", "left_wrist"), ("right_knee", "right_ankle")):
        i, j = JOINT_NAMES.index(lo), JOINT_NAMES.index(hi)
        np.testing.assert_allclose(joints[0, j] - joints[0, i], a.joints[j] - a.joints[i], atol=1e-9)


def test_a_merge_that_fits_neither_pass_keeps_a_pass_and_its_bounds_cover_both(held_out):
    """Two passes that split a pose differently average to bone directions that may fit
    neither: the merged pose must not move a marker joint off its marker (a climber's knee
    went 18 cm off under a 3 cm bound), and the bounds of what is kept cover the other pass."""
    truth, lengths, t, db, markers = held_out
    rec = Reconstructor(db, lengths=lengths)
    fwd = [rec.solve(markers[i], t[i]) for i in range(100)]
    a, b = fwd[60], fwd[99]  # b: another pose of the walk, as a pass that went its own way
    b = replace(b, bounds=np.full(13, 0.03))
    m = markers[60:61]
    joints, results = merge_passes([a], [b], lengths, m)
    seen = np.isfinite(m[0]).all(axis=1)
    off = np.linalg.norm(joints[0][list(MARKER_JOINT)] - m[0], axis=1)[seen]
    a_off = np.linalg.norm(a.joints[list(MARKER_JOINT)] - m[0], axis=1)[seen]
    assert off.max() <= a_off.max() + 0.05
    np.testing.assert_allclose(joints[0], a.joints)  # b fits frame 60's markers far worse
    gap = np.linalg.norm(a.joints - b.joints, axis=1)
    assert gap.max() > 0.2
    np.testing.assert_array_less(b.bounds + gap - 1e-9, results[0].bounds + 1e-9)
    # skin markers: the fit is judged on the model's markers (joint centres plus offsets)
    skin = markers_from_joints(a.joints[None], TYPICAL_OFFSETS)
    joints, _ = merge_passes([a], [b], lengths, skin, TYPICAL_OFFSETS)
    np.testing.assert_allclose(joints[0], a.joints)
    # passes that agree merge as before, their bounds barely grow
    joints, results = merge_passes([a], [replace(a)], lengths, m)
    np.testing.assert_allclose(joints[0], a.joints, atol=1e-6)
    np.testing.assert_allclose(results[0].bounds, a.bounds, atol=1e-6)


def test_a_hidden_wrist_is_filled_from_the_nearer_end_of_its_gap(held_out):
    """Offline, a wrist hidden for 0.4 s is solved from both ends, each pass trusted more near
    the end of the gap where it last saw the wrist: much nearer the truth than the live
    (forwards) guess."""
    truth, _lengths, t, db, markers = held_out
    m = truth[:, list(MARKER_JOINT)].copy()
    gap = slice(60, 72)
    m[gap, 2] = np.nan  # left wrist
    lw = JOINT_NAMES.index("left_wrist")
    both = np.linalg.norm(reconstruct_take(m, t, db)[0][gap, lw] - truth[gap, lw], axis=-1).mean()
    live = np.linalg.norm(reconstruct_take(m, t, db, both_ways=False)[0][gap, lw] - truth[gap, lw], axis=-1).mean()
    assert both < 0.6 * live


def test_loose_markers_pull_the_pose_less(held_out):
    """Markers the labelling found only in merged blobs weigh ``sigma_loose``: both knees named
    on the one point their merged blobs make (the midpoint) for 20 frames are solved nearer
    their true places than when that point is taken as exact for both."""
    truth, lengths, t, db, markers = held_out
    off = markers.copy()
    k = slice(60, 80)
    knees = [4, 5]  # MARKER_NAMES order
    off[k, 4] = off[k, 5] = 0.5 * (markers[k, 4] + markers[k, 5])
    loose = np.zeros(off.shape[:2], bool)
    loose[k, 4] = loose[k, 5] = True
    joints = [MARKER_JOINT[m] for m in knees]
    err = {}
    for name, flags in (("exact", None), ("loose", loose)):
        rec = Reconstructor(db, lengths=lengths)
        est = np.array([rec.solve(off[i], t[i], None if flags is None else flags[i]).joints for i in range(len(t))])
        err[name] = float(np.linalg.norm(est[k][:, joints] - truth[k][:, joints], axis=-1).mean())
    assert err["exact"] > 0.05  # the solver puts both knees on the point
    assert err["loose"] < err["exact"] - 0.01, err
