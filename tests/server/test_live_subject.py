"""Skin markers live: the server measures the subject after the standard pose and solves with it.

A simulated take with the markers on skin landmarks (offsets unlike the typical ones) goes as
2D marker packets of 4 cameras through the server (3D labelling, live solver); no subject given.
"""

from __future__ import annotations

import numpy as np
import pytest

from samba_common.calib import default_rig
from samba_common.markerset import markers_from_joints, vary_offsets
from samba_common.skeleton import MARKER_JOINT
from samba_common.subject import Subject, load_subject_text
from samba_common.wire import encode_packet
from samba_server.record import Recorder, TakeReader
from samba_server.recon.reconstruct import ReconstructConfig, Reconstructor
from samba_server.recon.db import load_default_db
from samba_server.recon.subject_fit import calibrate_subject
from samba_server.replay import recorded_subjects, replay_into
from samba_server.server import Server
from samba_server.simmotes import make_packet, project_take

from .conftest import short_take

FPS = 60.0
STANDARD_END_S = 1.6  # short_take's standard pose (with the blend into the clip)


@pytest.fixture(scope="module")
def skin_take():
    joints, t = short_take(seconds=5.0, fps=FPS)
    offsets = vary_offsets(np.random.default_rng(21), scale=0.25)
    markers = markers_from_joints(joints, offsets)
    shown = joints.copy()
    shown[:, list(MARKER_JOINT)] = markers  # the cameras see the landmarks
    rig = default_rig(4)
    uv, vis = project_take(rig, shown)
    return joints, t, offsets, markers, rig, uv, vis


def _run(take, reconstructor, record=None):
    """Feed the take's packets to a server; returns (joints (F, 13, 3), subject version per pose, server)."""
    joints, _t, _off, _m, rig, uv, vis = take
    rng = np.random.default_rng(0)
    server = Server(rig, reconstructor=reconstructor, recorder=Recorder(record) if record else None)
    versions: list[int] = []
    server.pose_listeners.append(lambda msg: versions.append(getattr(reconstructor, "subject_version", 0)))
    for k in range(len(joints)):
        t_ns = 1_000_000_000 + int(round(k * 1e9 / FPS))
        for c, name in enumerate(rig.names):
            pkt = make_packet(name, k, t_ns, uv[c, k], vis[c, k], (160, 120), rng, 0.05)
            server.ingest(name, encode_packet(pkt), arrival_ns=t_ns + 2_000_000)
        server.process_pending()
    server.finish()
    if server.recorder is not None:
        server.recorder.close()
    est = np.stack([p.joints for p in server.poses])
    return est, np.array(versions), server


def _err(est: np.ndarray, truth: np.ndarray) -> float:
    return float(np.nanmean(np.linalg.norm(est - truth[: len(est)], axis=2)))


def test_server_measures_skin_offsets_after_the_standard_pose_and_replay_repeats_it(skin_take, tmp_path):
    joints, t, offsets, markers, _rig, _uv, _vis = skin_take
    db = load_default_db()
    rec = Reconstructor(db)
    est, versions, server = _run(skin_take, rec, tmp_path / "take.mcap")
    assert len(est) == len(joints)
    subject = server.subject
    assert subject is not None and subject.placement == "skin"
    # typical offsets at the body swap, then the first calibration, then the refinement
    assert rec.subject_version == 3, rec.subject_version
    first_calibrated = int(np.argmax(versions >= 2))
    assert t[first_calibrated] <= STANDARD_END_S + 1.5, t[first_calibrated]
    assert subject.offsets_sigma is not None and np.all(subject.offsets_sigma > 0)

    # the same take solved with the subject given (calibrated offline from the true markers)
    given = calibrate_subject(markers, t, db).subject
    est_given, _v, _s = _run(skin_take, Reconstructor(db, lengths=given.lengths, offsets=given.offsets))
    # and with the markers taken for joint centres
    est_naive, _v, _s = _run(skin_take, Reconstructor(db, ReconstructConfig(placement="joint_centres")))
    after = slice(first_calibrated, None)
    e_live, e_given, e_naive = (_err(e[after], joints[after]) for e in (est, est_given, est_naive))
    print(f"after {t[first_calibrated]:.2f} s: live {100 * e_live:.2f} cm, --subject {100 * e_given:.2f} cm, "
          f"as joint centres {100 * e_naive:.2f} cm")
    assert e_live <= e_given + 0.004
    assert e_live < e_naive - 0.01

    # recorded: every subject change (event + metadata), and the replay gives the same poses
    events = recorded_subjects(tmp_path / "take.mcap")
    assert [seq for seq, _toml in events] == [int(np.argmax(versions >= v)) for v in (1, 2, 3)]
    last = load_subject_text(events[-1][1])
    assert np.allclose(last.offsets, subject.offsets, atol=1e-5)
    reader = TakeReader(tmp_path / "take.mcap")
    for _m in reader:
        pass
    assert "samba.subject" in reader.metadata
    again = Server(server.rig, reconstructor=Reconstructor(db))
    replay_into(again, tmp_path / "take.mcap")
    replayed = np.stack([p.joints for p in again.poses])
    np.testing.assert_array_equal(replayed, est)
    assert np.array_equal(again.subject.offsets, subject.offsets)


def test_joint_centre_markers_stay_joint_centres_live():
    """The same motion with the markers on the joint centres: auto placement keeps zero offsets."""
    joints, _t = short_take(seconds=1.0, fps=FPS)
    rec = Reconstructor(load_default_db())
    for k, m in enumerate(joints[:, list(MARKER_JOINT)]):
        rec.solve(m, k / FPS)
    assert rec.subject is not None and rec.subject.placement == "joint_centres"
    assert not np.any(rec.offsets) and isinstance(rec.subject, Subject)
