"""The subject a take was solved with travels into its exports: C3D parameters (read back by the
independent pure-Python reader), a subject.toml next to BVH/TRC/CSV, from joints.npz and take.mcap."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from samba_common.formats import save_joints
from samba_common.markerset import vary_offsets
from samba_common.skeleton import BONE_TYPES, MARKER_NAMES
from samba_common.subject import Subject, load_subject
from samba_server.cli.export import main as export_main
from samba_server.record import Recorder

from .conftest import synthetic_joints

c3d = pytest.importorskip("c3d")


def _subject() -> Subject:
    lengths = np.array([0.36, 0.26, 0.52, 0.24, 0.29, 0.26, 0.44, 0.42])
    return Subject(lengths, vary_offsets(np.random.default_rng(3)), np.full((8, 3), 0.004), "skin")


def test_joints_npz_subject_goes_into_c3d_parameters_and_sidecars(tmp_path, capsys):
    joints, t = synthetic_joints(30)
    subject = _subject()
    src = tmp_path / "joints.npz"
    save_joints(src, joints, t, **subject.metadata())
    assert export_main([str(src), "--out", str(tmp_path / "take.c3d")]) == 0
    with open(tmp_path / "take.c3d", "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = c3d.Reader(fh)
        assert r.get("SAMBA:SUBJECT_PLACEMENT").string_value.strip() == "skin"
        assert [s.strip() for s in r.get("SAMBA:BONE_TYPES").string_array] == list(BONE_TYPES)
        np.testing.assert_allclose(r.get("SAMBA:BONE_LENGTHS").float_array, 1000 * subject.lengths, atol=1e-3)
        assert [s.strip() for s in r.get("SAMBA:OFFSET_MARKERS").string_array] == list(MARKER_NAMES)
        np.testing.assert_allclose(r.get("SAMBA:MARKER_OFFSETS").float_array, 1000 * subject.offsets, atol=1e-3)
        np.testing.assert_allclose(r.get("SAMBA:OFFSET_SIGMA").float_array, 4.0, atol=1e-3)
    assert not (tmp_path / "take.subject.toml").exists()  # C3D carries it inside
    for fmt in ("bvh", "trc", "csv"):
        out = tmp_path / f"{fmt}_take.{fmt}"
        assert export_main([str(src), "--out", str(out)]) == 0
        side = load_subject(tmp_path / f"{fmt}_take.subject.toml")
        np.testing.assert_allclose(side.offsets, subject.offsets, atol=1e-5)
        np.testing.assert_allclose(side.lengths, subject.lengths, atol=1e-5)
    assert (tmp_path / "csv_take.csv").read_text().startswith("t,head_x")  # the CSV itself unchanged


def test_mcap_take_exports_its_last_recorded_subject(tmp_path, capsys):
    from samba_common.pose_wire import PoseMessage, encode_pose

    joints, t = synthetic_joints(10)
    first, second = _subject(), _subject()
    second.offsets = second.offsets + 0.003
    path = tmp_path / "take.mcap"
    with Recorder(path, calibration_toml=b"") as rec:
        for k in range(len(t)):
            t_ns = 1_000_000_000 + int(k * 1e9 / 60)
            if k in (2, 6):
                s = first if k == 2 else second
                rec.write_event(json.dumps({"event": "subject", "t_ns": t_ns, "seq": k,
                                            "subject_toml": s.to_toml()}).encode(), t_ns)
            msg = PoseMessage(seq=k, t_ns=t_ns, joints=joints[k], residual_m=0.001, n_markers=8, n_views=4, flags=1)
            rec.write_pose(encode_pose(msg), t_ns, t_ns, k)
    assert export_main([str(path), "--out", str(tmp_path / "take.bvh")]) == 0
    got = load_subject(tmp_path / "take.subject.toml")
    np.testing.assert_allclose(got.offsets, second.offsets, atol=1e-5)
