"""C3D files of any length read back with two independent readers: ezc3d (C++) and the
pure-Python ``c3d`` package. Points to 1e-4 m, frame count, rate, time stamps, missing points."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from samba_common.skeleton import JOINT_NAMES, MARKER_NAMES
from samba_server.export.c3d import frame_times, write_c3d
from samba_server.export.take import ExportTake

ezc3d = pytest.importorskip("ezc3d")
c3d = pytest.importorskip("c3d")

LABELS = list(JOINT_NAMES) + [f"{m}_marker" for m in MARKER_NAMES]


def _take(n_frames: int, fps: float = 120.0, t0: float = 3.25, seed: int = 0) -> ExportTake:
    rng = np.random.default_rng(seed)
    joints = rng.uniform(-2.0, 2.0, (n_frames, 13, 3))
    markers = rng.uniform(-2.0, 2.0, (n_frames, 8, 3))
    if n_frames > 3:
        joints[2] = np.nan  # an unsolved frame
        markers[1:3, 5] = np.nan  # one marker unseen for two frames
    return ExportTake(joints, t0 + np.arange(n_frames) / fps, markers, "synthetic/joints.npz")


def _read_ezc3d(path):
    c = ezc3d.c3d(str(path))
    pts = np.transpose(c["data"]["points"][:3], (2, 1, 0)) / 1000.0  # (F, P, 3) m
    res = c["data"]["meta_points"]["residuals"][0].T  # (F, P)
    par = c["parameters"]
    return c, pts, res, par


def _read_c3d(path):
    """Everything through the pure-Python reader, residual words as stored (no NaN check)."""
    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "No analog data found in file."
        r = c3d.Reader(fh)
        frames = [(i, p.copy()) for i, p, _ in r.read_frames(check_nan=False)]
        meta = dict(
            rate=r.point_rate, count=r.frame_count, first=r.first_frame, scale=r.point_scale,
            labels=[s.strip() for s in r.point_labels],
            units=r.get("POINT:UNITS").string_value.strip(),
            t0=r.get("SAMBA:T0").float_value, t_error=r.get("SAMBA:T_ERROR").float_value,
            source=r.get("SAMBA:SOURCE").string_value.strip())
    numbers = [i for i, _ in frames]
    data = np.stack([p for _, p in frames])  # (F, P, 5): x y z residual cameras
    return meta, numbers, data


@pytest.mark.parametrize("n_frames", [1, 255, 256, 10_000])
def test_any_length_reads_back_with_both_readers(tmp_path, n_frames, capsys):
    take = _take(n_frames)
    out = tmp_path / "take.c3d"
    assert write_c3d(out, take) == 21
    fps = 120.0 if n_frames > 1 else 1.0  # a single frame has no time step: 1 Hz
    assert f"wrote {out}: {n_frames} frames x 21 points at {fps:g} Hz" in capsys.readouterr().err
    truth = np.concatenate([take.joints, take.markers], axis=1)
    missing = ~np.all(np.isfinite(truth), axis=-1)  # (F, P)

    # ezc3d
    c, pts, res, par = _read_ezc3d(out)
    assert pts.shape == (n_frames, 21, 3)
    assert par["POINT"]["LABELS"]["value"] == LABELS
    assert par["POINT"]["UNITS"]["value"] == ["mm"]
    rate = float(par["POINT"]["RATE"]["value"][0])
    assert rate == pytest.approx(fps)
    np.testing.assert_allclose(pts, truth, atol=1e-4, equal_nan=True)
    assert np.array_equal(np.isnan(pts).any(-1), missing)  # missing -> NaN
    assert np.array_equal(res == -1, missing)
    t0 = float(par["SAMBA"]["T0"]["value"][0])
    np.testing.assert_allclose(frame_times(t0, rate, n_frames), take.t, atol=1e-6)
    assert float(par["SAMBA"]["T_ERROR"]["value"][0]) < 1e-6
    assert par["SAMBA"]["SOURCE"]["value"] == ["joints.npz"]

    # the independent pure-Python reader
    meta, numbers, data = _read_c3d(out)
    assert meta["count"] == n_frames and numbers == list(range(1, n_frames + 1))
    assert meta["rate"] == pytest.approx(fps) and meta["units"] == "mm" and meta["scale"] < 0  # float data
    assert meta["labels"] == LABELS and meta["source"] == "joints.npz"
    # the C3D convention for a missing point: residual -1 (coordinates carry no meaning, here 0)
    assert np.array_equal(data[..., 3] == -1, missing)
    assert np.all(data[missing][:, :3] == 0.0)
    np.testing.assert_allclose(data[~missing][:, :3] / 1000.0, truth[~missing], atol=1e-4)
    np.testing.assert_allclose(frame_times(meta["t0"], meta["rate"], n_frames), take.t, atol=1e-6)
    assert meta["t_error"] < 1e-6


def test_irregular_time_stamps_are_flagged(tmp_path, caplog):
    take = _take(300, fps=60.0, t0=0.0)
    take.t[150:] += 0.05  # a 50 ms gap (3 dropped frames)
    out = tmp_path / "gap.c3d"
    write_c3d(out, take)
    assert "irregular" in caplog.text
    meta, numbers, _ = _read_c3d(out)
    assert len(numbers) == 300 and meta["rate"] == pytest.approx(60.0)
    assert meta["t_error"] == pytest.approx(0.05, abs=2e-3)
    t = frame_times(meta["t0"], meta["rate"], 300)
    assert np.abs(t - take.t).max() == pytest.approx(meta["t_error"], abs=1e-5)


def test_more_frames_than_the_header_counts(tmp_path, caplog):
    """> 65535 frames: TRIAL:ACTUAL_*_FIELD carry the count (the pure-Python reader uses them)."""
    n = 70_000
    rng = np.random.default_rng(3)
    joints = rng.uniform(-1.0, 1.0, (n, 13, 3))
    take = ExportTake(joints, np.arange(n) / 60.0, None, "long.npz")
    out = tmp_path / "long.c3d"
    assert write_c3d(out, take) == 13
    assert "65535" in caplog.text
    meta, numbers, data = _read_c3d(out)
    assert meta["count"] == n and numbers[-1] == n
    np.testing.assert_allclose(data[:, :, :3] / 1000.0, joints, atol=1e-4)


def test_samba_export_cli_long_take(tmp_path, capsys):
    """The reported case: ``samba-export joints.npz --out take.c3d`` of more than 255 frames."""
    from samba_common.formats import save_joints
    from samba_server.cli.export import main

    from .conftest import synthetic_joints

    joints, t = synthetic_joints(n_frames=341, fps=60.0)
    npz = tmp_path / "joints.npz"
    save_joints(npz, joints, t)
    out = tmp_path / "take.c3d"
    assert main([str(npz), "--out", str(out)]) == 0
    assert f"wrote {out}: 341 frames" in capsys.readouterr().err
    _, pts, _, par = _read_ezc3d(out)
    np.testing.assert_allclose(pts, joints, atol=1e-4)
    meta, numbers, _ = _read_c3d(out)
    assert len(numbers) == 341 and meta["rate"] == pytest.approx(60.0)
