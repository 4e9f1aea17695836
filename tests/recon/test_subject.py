"""Skin markers: the marker model, subject.toml, calibration from a take, reconstruction through the model."""

import numpy as np
import pytest

from samba_common.body import prepend_standard_pose, standard_pose
from samba_common.markerset import (TYPICAL_OFFSETS, markers_from_joints, segment_frames_body, vary_offsets)
from samba_common.body import standard_dirs
from samba_common.skeleton import MARKER_JOINT
from samba_common.subject import Subject, SubjectError, load_subject
from samba_mote.sim.motion import synthetic_motion
from samba_server.cli.subject import main as subject_main
from samba_server.recon.db import load_default_db
from samba_server.recon.evaluate import mpjpe, observe
from samba_server.recon.reconstruct import reconstruct_take
from samba_server.recon.subject_fit import calibrate_subject
from samba_common.formats import save_markers


def _take(standard: bool, seed: int = 4):
    joints, t = synthetic_motion(6.0, 30.0)
    if standard:
        joints = prepend_standard_pose(joints, 30.0)
    t = np.arange(len(joints)) / 30.0
    rng = np.random.default_rng(seed)
    offsets = vary_offsets(rng)
    noise = observe(np.zeros_like(joints), rng, missing=0.03)
    return joints, t, offsets, markers_from_joints(joints, offsets) + noise, joints[:, list(MARKER_JOINT)] + noise


def test_segment_frames_are_rotations_and_typical_landmarks_sit_where_anatomy_says():
    F = segment_frames_body(standard_dirs())
    for i in range(8):
        assert np.allclose(F[i].T @ F[i], np.eye(3), atol=1e-9)
    lengths = load_default_db().mean_lengths
    joints = standard_pose(lengths)[None]
    m = markers_from_joints(joints, TYPICAL_OFFSETS)[0]
    c = joints[0, list(MARKER_JOINT)]
    assert np.allclose(m[:2] - c[:2], [[0, 0, 0.045]] * 2, atol=1e-9)  # acromion above the shoulder
    assert np.allclose(m[4] - c[4], [-0.05, 0, 0], atol=1e-9)   # left knee: lateral = -X facing +Y
    assert np.allclose(m[5] - c[5], [0.05, 0, 0], atol=1e-9)
    assert np.allclose(m[6] - c[6], [-0.035, 0, -0.01], atol=1e-9)  # lateral malleolus, a little below
    assert np.allclose(m[2] - c[2], [0, 0, 0.025], atol=1e-9)   # back of the wrist up, palms down
    assert np.array_equal(markers_from_joints(joints, None), joints[:, list(MARKER_JOINT)])


def test_subject_file_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(0)
    s = Subject(load_default_db().mean_lengths, vary_offsets(rng), np.full((8, 3), 0.004), "skin")
    s.save(tmp_path / "subject.toml")
    back = load_subject(tmp_path / "subject.toml")
    assert np.allclose(back.lengths, s.lengths, atol=1e-5) and np.allclose(back.offsets, s.offsets, atol=1e-5)
    assert np.allclose(back.offsets_sigma, s.offsets_sigma, atol=1e-5) and back.placement == "skin"
    bad = tmp_path / "bad.toml"
    bad.write_text(s.to_toml().replace("left_knee = [", "left_knee = [0.1, "))
    with pytest.raises(SubjectError, match="subject.offsets.left_knee"):
        load_subject(bad)
    bad.write_text(s.to_toml().replace("shin =", "shinbone ="))
    with pytest.raises(SubjectError, match="bone_lengths"):
        load_subject(bad)


def test_offsets_recovered_and_skin_markers_cost_little_on_a_simulated_take(tmp_path, capsys):
    joints, t, true_off, skin, centres = _take(standard=True)
    db = load_default_db()
    report = calibrate_subject(skin, t, db)
    err = np.abs(report.subject.offsets - true_off)
    # a synthetic walk barely informs the acromion (this seed's typical offset is already 11 mm
    # off): the arms must stay within 12 mm or within 2 mm of the typical offsets' error
    typical_arm_err = np.abs(TYPICAL_OFFSETS - true_off)[:4].max()
    assert err[4:].max() < 0.01 and err[:4].max() < max(0.012, typical_arm_err + 0.002), np.round(1000 * err, 1)
    est_c, _ = reconstruct_take(centres, t, db)
    est_naive, _ = reconstruct_take(skin, t, db)  # skin markers taken for joint centres
    est_s, info = reconstruct_take(skin, t, db, lengths=report.subject.lengths, offsets=report.subject.offsets)
    e_c, e_naive, e_s = mpjpe(est_c, joints), mpjpe(est_naive, joints), mpjpe(est_s, joints)
    assert e_s < e_naive - 0.01 and e_s < e_c + 0.006, (e_c, e_naive, e_s)
    assert np.isfinite(info["residual"]).mean() > 0.95
    # the CLI writes the same subject file, which samba-reconstruct --subject reads
    save_markers(tmp_path / "m.npz", skin, t)
    assert subject_main(["calibrate", str(tmp_path / "m.npz"), "--out", str(tmp_path / "s.toml")]) == 0
    assert "marker offsets" in capsys.readouterr().out
    assert np.allclose(load_subject(tmp_path / "s.toml").offsets, report.subject.offsets, atol=1e-4)


def test_a_take_without_a_standard_pose_still_calibrates_from_motion():
    joints, t, true_off, skin, _centres = _take(standard=False, seed=9)
    db = load_default_db()
    report = calibrate_subject(skin, t, db)
    assert report.frames_used > 0.9 * len(t)
    err = np.abs(report.subject.offsets - true_off)
    assert err.max() < 0.015, np.round(1000 * err, 1)
    est_naive, _ = reconstruct_take(skin, t, db)
    est_s, _ = reconstruct_take(skin, t, db, lengths=report.subject.lengths, offsets=report.subject.offsets)
    assert mpjpe(est_s, joints) < mpjpe(est_naive, joints) - 0.01


def test_auto_placement_tells_skin_from_joint_centres_without_the_files_key(tmp_path, capsys):
    """The same simulated take, markers on the landmarks and on the joint centres, markers.npz
    without marker_placement: samba-reconstruct --placement auto picks right both times and says why."""
    from samba_server.cli.reconstruct import main as reconstruct_main

    joints, t, _off, skin, centres = _take(standard=True, seed=11)
    for name, markers, want in (("skin", skin, "skin"), ("centres", centres, "joint_centres")):
        path = tmp_path / f"{name}.npz"
        save_markers(path, markers, t)
        assert "marker_placement" not in np.load(path).files
        out = tmp_path / f"{name}_joints.npz"
        assert reconstruct_main([str(path), "--out", str(out), "-q"]) == 0
        assert str(np.load(out)["subject_placement"]) == want, name
        capsys.readouterr()
    assert reconstruct_main([str(tmp_path / "centres.npz"), "--out", str(tmp_path / "j.npz")]) == 0
    assert "placement (auto, from the standard pose): joint centres" in capsys.readouterr().out


def test_guess_placement_from_motion_alone(monkeypatch):
    """Without a standard pose the motion decides: skin markers stay skin (with the calibration
    reused), and the reason names the residuals of both models."""
    from samba_server.recon import subject_fit, subject_model

    monkeypatch.setattr(subject_model, "standard_pose_frames", lambda m, arm: np.zeros(len(m), bool))
    _joints, t, _off, skin, centres = _take(standard=False, seed=12)
    db = load_default_db()
    g = subject_fit.guess_placement(skin, t, db)
    assert g.evidence == "motion" and g.placement == "skin" and g.report is not None, g.reason
    assert "mm as joint centres" in g.reason
    g = subject_fit.guess_placement(centres, t, db)
    assert g.evidence == "motion" and g.placement in ("skin", "joint_centres"), g.reason
