"""Camera model, calibration.toml IO and default rigs (samba_common.calib)."""

from __future__ import annotations

import math
import sys

import cv2
import numpy as np
import pytest

from samba_common.calib import (
    CalibrationError,
    Camera,
    CameraRig,
    default_rig,
    rodrigues,
    rotation_to_rvec,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


def _body_points() -> np.ndarray:
    """Extremes of a subject standing within 1.5 m of the origin, (N, 3) metres."""
    offsets = [(0, 0, 0.07), (0, 0, 1.8), (0.85, 0, 1.45), (-0.85, 0, 1.45), (0.2, 0.15, 0.07), (-0.2, -0.15, 1.8)]
    pts = []
    for ang in np.linspace(0, 2 * np.pi, 24, endpoint=False):
        for r in (0.0, 0.75, 1.5):
            o = np.array([r * np.cos(ang), r * np.sin(ang), 0.0])
            pts += [o + np.array(p) for p in offsets]
    return np.array(pts)


@pytest.mark.parametrize("n", [2, 4])
def test_default_rig_geometry_and_coverage(n: int) -> None:
    rig = default_rig(n)
    assert rig.names == [f"cam{i}" for i in range(n)]
    pts = _body_points()
    for cam, uv in zip(rig, rig.project(pts)):
        assert cam.size == (160, 120)
        assert abs(cam.matrix[0, 0] - 140) < 10
        d = np.linalg.norm(cam.center)
        assert 3.5 <= d <= 5.5
        assert np.all(cam.in_image(uv)), cam.name
        # optical axis points at ~1 m height above the origin
        axis = cam.R[2]
        s = -cam.center[:2] @ axis[:2] / (axis[:2] @ axis[:2])
        assert 0.7 < (cam.center + s * axis)[2] < 1.2
    if n == 2:  # both in front of a subject facing +Y
        assert all(c.center[1] > 0 for c in rig)


def test_default_rig_rejects_other_counts() -> None:
    with pytest.raises(ValueError):
        default_rig(3)


def test_projection_matches_opencv_and_undistort_inverts_it() -> None:
    rng = np.random.default_rng(1)
    cam = Camera("c", (160, 120), [[150.0, 0.3, 81.0], [0, 148.0, 58.0], [0, 0, 1]],
                 [-0.12, 0.03, 0.001, -0.002, 0.004], [0.1, -2.0, 0.3], [0.2, 0.9, 4.0])
    X = rng.uniform(-1.5, 1.5, (200, 3))
    uv = cam.project(X)
    K0 = cam.matrix.copy()
    K0[0, 1] = 0.0  # OpenCV ignores skew; ours keeps it (consistent with P below)
    ref, _ = cv2.projectPoints(X, cam.rvec, cam.tvec, K0, cam.dist)
    np.testing.assert_allclose(Camera("c0", cam.size, K0, cam.dist, cam.rvec, cam.tvec).project(X), ref[:, 0], atol=1e-9)
    Xc = cam.to_camera(X)
    ideal = (Xc[:, :2] / Xc[:, 2:]) @ cam.matrix[:2, :2].T + cam.matrix[:2, 2]
    np.testing.assert_allclose(cam.undistort(uv), ideal, atol=1e-9)
    # P matches K[R|t]
    h = np.c_[X, np.ones(len(X))] @ cam.P.T
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], ideal, atol=1e-9)


def test_project_behind_camera_is_nan_and_undistort_keeps_nan() -> None:
    cam = default_rig(2).cameras[0]
    behind = cam.center + 2.0 * (cam.center - np.array([0, 0, 0.9]))
    uv = cam.project(np.array([[0, 0, 1.0], behind]))
    assert np.all(np.isfinite(uv[0])) and np.all(np.isnan(uv[1]))
    und = cam.undistort(np.array([[np.nan, np.nan], [80.0, 60.0]]))
    assert np.all(np.isnan(und[0])) and np.all(np.isfinite(und[1]))


def test_center_and_rotation_helpers() -> None:
    rng = np.random.default_rng(2)
    for _ in range(50):
        r = rng.normal(size=3)
        r *= rng.uniform(0, math.pi - 1e-6) / np.linalg.norm(r)
        R = rodrigues(r)
        np.testing.assert_allclose(R, cv2.Rodrigues(r)[0], atol=1e-12)
        np.testing.assert_allclose(rodrigues(rotation_to_rvec(R)), R, atol=1e-12)
    # angle exactly pi and zero
    R = np.diag([1.0, -1.0, -1.0])
    np.testing.assert_allclose(rodrigues(rotation_to_rvec(R)), R, atol=1e-12)
    np.testing.assert_allclose(rotation_to_rvec(np.eye(3)), 0, atol=1e-15)
    cam = default_rig(4).cameras[2]
    np.testing.assert_allclose(cam.R @ cam.center + cam.tvec, 0, atol=1e-12)


def test_toml_round_trip_is_exact(tmp_path) -> None:
    rig = default_rig(4)
    rig.cameras[1].dist = np.array([-0.1234567890123, 1e-5, 3.3e-20, -7e-300, 0.0])
    rig.cameras[2].matrix[0, 2] = 80.00000000000001
    path = tmp_path / "calibration.toml"
    rig.save(path)
    back = CameraRig.load(path)
    assert back.names == rig.names
    for a, b in zip(rig, back):
        assert a.size == b.size
        for f in ("matrix", "dist", "rvec", "tvec"):
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
    text = path.read_text()
    assert "[cam_0]" in text and 'name = "cam0"' in text and "distortions = [" in text
    assert back.metadata["units"] == "m"
    assert CameraRig.loads(text.encode()).names == rig.names


def test_load_anipose_written_file(tmp_path) -> None:
    path = tmp_path / "anipose.toml"
    path.write_text(
        '[cam_0]\nname = "A"\nsize = [ 1280, 1024,]\nmatrix = [ [ 1000.5, 0.0, 640.0,], [ 0.0, 1001.0, 512.0,], '
        "[ 0.0, 0.0, 1.0,],]\ndistortions = [ -0.2, 0.1, 0.0, 0.0, 0.0,]\nrotation = [ 0.1, 0.2, 0.3,]\n"
        'translation = [ 1.0, 2.0, 3.0,]\n\n[cam_1]\nname = "B"\nsize = [ 1280, 1024,]\n'
        "matrix = [ [ 1000.0, 0.0, 640.0,], [ 0.0, 1000.0, 512.0,], [ 0.0, 0.0, 1.0,],]\n"
        "distortions = [ 0.0, 0.0, 0.0, 0.0, 0.0,]\nrotation = [ 0.0, 0.0, 0.0,]\ntranslation = [ 0.0, 0.0, 0.0,]\n\n"
        '[metadata]\nadjusted = false\nerror = 0.5\n'
    )
    rig = CameraRig.load(path)
    assert rig.names == ["A", "B"]
    assert rig.camera("A").matrix[0, 0] == 1000.5
    with pytest.raises(KeyError):
        rig.camera("C")


GOOD = (
    '[cam_0]\nname = "cam0"\nsize = [160, 120]\nmatrix = [[140.0, 0.0, 80.0], [0.0, 140.0, 60.0], [0.0, 0.0, 1.0]]\n'
    "distortions = [0.0, 0.0, 0.0, 0.0, 0.0]\nrotation = [0.0, 0.0, 0.0]\ntranslation = [0.0, 0.0, 3.0]\n"
)


@pytest.mark.parametrize(
    "text, key, msg",
    [
        (GOOD.replace("matrix = [[140.0, 0.0, 80.0], [0.0, 140.0, 60.0], [0.0, 0.0, 1.0]]\n", ""), "cam_0.matrix", "missing"),
        (GOOD.replace("[0.0, 0.0, 1.0]]", "]"), "cam_0.matrix", "shape"),
        (GOOD.replace("[[140.0", "[[-140.0"), "cam_0.matrix", "positive"),
        (GOOD.replace("[0.0, 0.0, 3.0]", "[0.0, nan, 3.0]"), "cam_0.translation", "non-finite"),
        (GOOD.replace("rotation = [0.0, 0.0, 0.0]", "rotation = [0.0, 0.0]"), "cam_0.rotation", "shape"),
        (GOOD.replace("[0.0, 0.0, 0.0, 0.0, 0.0]", "[0.0, inf, 0.0, 0.0, 0.0]"), "cam_0.distortions", "non-finite"),
        (GOOD.replace("[0.0, 0.0, 0.0, 0.0, 0.0]", '"none"'), "cam_0.distortions", "k1"),
        (GOOD.replace("[160, 120]", "[160, 0]"), "cam_0.size", "positive"),
        (GOOD.replace('"cam0"', '""'), "cam_0.name", "non-empty"),
        (GOOD + GOOD.replace("cam_0", "cam_1"), "cam_1.name", "duplicate"),
        ("[metadata]\nunits = 'm'\n", None, "no [cam_N]"),
        ("[cam_0\n", None, "invalid TOML"),
    ],
)
def test_invalid_files_name_file_and_key(tmp_path, text: str, key: str | None, msg: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(CalibrationError) as ei:
        CameraRig.load(path)
    err = str(ei.value)
    assert str(path) in err and msg in err
    if key:
        assert f"[{key}]" in err
        assert ei.value.key == key


def test_missing_file_and_good_file(tmp_path) -> None:
    with pytest.raises(CalibrationError, match="file not found"):
        CameraRig.load(tmp_path / "nope.toml")
    (tmp_path / "ok.toml").write_text(GOOD)
    cam = CameraRig.load(tmp_path / "ok.toml").camera("cam0")
    np.testing.assert_allclose(cam.center, [0, 0, -3.0])


def test_save_rejects_non_finite_and_duplicates(tmp_path) -> None:
    rig = default_rig(2)
    rig.cameras[0].tvec = np.array([0.0, np.nan, 1.0])
    with pytest.raises(CalibrationError, match="cam_0.translation"):
        rig.save(tmp_path / "x.toml")
    assert not (tmp_path / "x.toml").exists()
    cams = default_rig(2).cameras
    cams[1].name = "cam0"
    with pytest.raises(CalibrationError, match="duplicate"):
        CameraRig(cams)


def test_replace_camera() -> None:
    rig = default_rig(2)
    cam = Camera("cam1", (160, 120), np.diag([150.0, 150.0, 1.0]))
    new = rig.replace(cam)
    assert new.camera("cam1").matrix[0, 0] == 150.0 and rig.camera("cam1").matrix[0, 0] == 140.0
    assert new.replace(Camera("cam9", (160, 120), np.eye(3))).names == ["cam0", "cam1", "cam9"]


def _aniposelib_text(rig: CameraRig, units: str | None, scale: float) -> str:
    """calibration.toml the way aniposelib's ``CameraGroup.dump`` (the ``toml`` package) writes
    it, translations multiplied by ``scale``; ``units`` in [metadata] when given."""

    def arr(v) -> str:
        v = np.asarray(v, dtype=float)
        if v.ndim == 2:
            return "[ " + " ".join(arr(r) + "," for r in v) + "]"
        return "[ " + " ".join(f"{x!r}," for x in v.tolist()) + "]"

    parts = []
    for i, c in enumerate(rig.cameras):
        parts.append(f'[cam_{i}]\nname = "{c.name}"\nsize = [ {c.size[0]}, {c.size[1]},]\nmatrix = {arr(c.matrix)}\n'
                     f"distortions = {arr(c.dist)}\nrotation = {arr(c.rvec)}\ntranslation = {arr(c.tvec * scale)}\n")
    meta = "[metadata]\nadjusted = true\nerror = 0.41\n" + (f'units = "{units}"\n' if units else "")
    return "\n".join(parts) + "\n" + meta


@pytest.mark.parametrize("units, scale", [("mm", 1000.0), ("cm", 100.0), ("m", 1.0), (None, 1.0)])
def test_units_in_metadata_scale_translations_to_metres(tmp_path, units, scale) -> None:
    rig = default_rig(4)
    path = tmp_path / "calibration.toml"
    path.write_text(_aniposelib_text(rig, units, scale))
    back = CameraRig.load(path)
    assert back.metadata["units"] == "m" and back.metadata["error"] == 0.41
    for a, b in zip(rig, back):
        np.testing.assert_allclose(b.tvec, a.tvec, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(b.center, a.center, atol=1e-9)  # metres: ~5 m, not 5 km
        assert np.array_equal(a.matrix, b.matrix) and np.array_equal(a.rvec, b.rvec)
    X = np.array([[0.3, -0.2, 1.1], [0.0, 0.5, 0.2]])
    np.testing.assert_allclose(back.project(X), rig.project(X), atol=1e-9)  # same pixels
    # saving writes metres (and says so); reloading gives the same rig
    out = tmp_path / "saved.toml"
    back.save(out)
    assert tomllib.loads(out.read_text())["metadata"]["units"] == "m"
    again = CameraRig.load(out)
    for a, b in zip(back, again):
        assert np.array_equal(a.tvec, b.tvec)


def test_unknown_units_name_file_and_key(tmp_path) -> None:
    for bad in ('"inch"', '"MM"', "1000"):
        path = tmp_path / "calibration.toml"
        path.write_text(GOOD + f"\n[metadata]\nunits = {bad}\n")
        with pytest.raises(CalibrationError) as ei:
            CameraRig.load(path)
        assert ei.value.key == "metadata.units"
        assert str(path) in str(ei.value) and "[metadata.units]" in str(ei.value) and "'mm'" in str(ei.value)


def test_millimetres_without_units_are_flagged(tmp_path, caplog) -> None:
    path = tmp_path / "calibration.toml"
    path.write_text(_aniposelib_text(default_rig(2), None, 1000.0))
    CameraRig.load(path)  # cannot know: loads as metres, but says what to do
    assert 'units = "mm"' in caplog.text and str(path) in caplog.text


def test_rig_metadata_units_never_mislabel_a_saved_file(tmp_path) -> None:
    rig = default_rig(2)
    rig.metadata["units"] = "mm"  # tvec is metres in memory whatever this says
    rig.save(tmp_path / "c.toml")
    back = CameraRig.load(tmp_path / "c.toml")
    np.testing.assert_allclose(back.cameras[0].tvec, rig.cameras[0].tvec)
