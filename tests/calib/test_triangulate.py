"""Triangulation from the default rigs with noise, missing views and outlier views."""

from __future__ import annotations

import numpy as np
import pytest

from samba_common.calib import Camera, CameraRig, default_rig
from samba_server.triangulate import TriangulateConfig, Triangulator, triangulate


def _points(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform([-1.2, -1.2, 0.05], [1.2, 1.2, 1.8], (n, 3))


@pytest.mark.parametrize("n_cams", [2, 4])
def test_exact_observations_give_exact_points(n_cams: int) -> None:
    rig = default_rig(n_cams)
    X = _points(np.random.default_rng(0), 50)
    res = triangulate(rig, rig.project(X))
    assert res.points.shape == (50, 3)
    np.testing.assert_allclose(res.points, X, atol=2e-5)  # undistortion table: ~1e-4 px
    assert np.all(res.error < 1e-3)
    assert np.all(res.n_views == n_cams) and res.used.all()


def test_without_distortion_exact_to_machine_precision() -> None:
    rig = default_rig(4)
    for c in rig:
        c.dist = np.zeros(5)
    X = _points(np.random.default_rng(1), 20)
    res = Triangulator(rig, TriangulateConfig(iterations=3)).triangulate(rig.project(X))
    np.testing.assert_allclose(res.points, X, atol=1e-10)


@pytest.mark.parametrize("n_cams, limit_mm", [(2, 25.0), (4, 15.0)])
def test_noise_gives_small_errors_and_refinement_beats_linear(n_cams: int, limit_mm: float) -> None:
    rng = np.random.default_rng(2)
    rig = default_rig(n_cams)
    X = _points(rng, 400)
    uv = rig.project(X) + rng.normal(0, 0.2, (n_cams, 400, 2))
    res = Triangulator(rig).triangulate(uv)
    err = np.linalg.norm(res.points - X, axis=1)
    assert err.mean() * 1000 < limit_mm / 2 and np.percentile(err, 95) * 1000 < limit_mm
    # error reported is the reprojection rms: about the noise level
    assert 0.05 < np.median(res.error) < 0.3
    lin = Triangulator(rig, TriangulateConfig(refine=False)).triangulate(uv)
    # the refined solution has the smaller reprojection error for (nearly) every point
    assert np.mean(res.error <= lin.error + 1e-9) > 0.99
    conv = Triangulator(rig, TriangulateConfig(iterations=5)).triangulate(uv)
    assert np.abs(conv.points - res.points).max() < 1e-4


def test_missing_views_single_view_and_empty() -> None:
    rig = default_rig(4)
    X = _points(np.random.default_rng(3), 6)
    uv = rig.project(X)
    uv[:, 0] = np.nan  # nobody sees point 0
    uv[1:, 1] = np.nan  # only camera 0 sees point 1
    uv[2:, 2] = np.nan  # two views
    uv[0, 3, 0] = np.nan  # half-NaN observation counts as unseen
    res = triangulate(rig, uv)
    assert np.all(np.isnan(res.points[:2])) and np.all(np.isnan(res.error[:2]))
    assert list(res.n_views) == [0, 0, 2, 3, 4, 4]
    np.testing.assert_allclose(res.points[2:], X[2:], atol=2e-5)
    assert not res.used[:, :2].any() and not res.used[0, 3]
    empty = triangulate(rig, np.zeros((4, 0, 2)))
    assert empty.points.shape == (0, 3)
    with pytest.raises(ValueError, match="shape"):
        triangulate(rig, np.zeros((3, 5, 2)))


def test_outlier_view_is_rejected_with_three_or_more_views() -> None:
    rng = np.random.default_rng(4)
    rig = default_rig(4)
    X = _points(rng, 40)
    uv = rig.project(X) + rng.normal(0, 0.1, (4, 40, 2))
    bad_cam = rng.integers(0, 4, 40)
    bad_cam[:10] = rng.integers(0, 3, 10)  # the bad view is one of the 3 seen
    uv[bad_cam, np.arange(40)] += rng.choice([-1, 1], (40, 2)) * rng.uniform(3, 8, (40, 2))
    uv[3, :10] = np.nan  # 3 views for the first 10 points, one of them bad
    res = triangulate(rig, uv)
    err = np.linalg.norm(res.points - X, axis=1)
    dropped = ~res.used & ~np.isnan(uv[..., 0])
    assert np.all(res.n_views == np.where(np.arange(40) < 10, 2, 3))
    assert np.all(res.error < 2.0)
    # with 4 views the bad one is always found; with 3, two views always agree along
    # their epipolar line, so a bad view displaced along it can win: most are found
    assert np.array_equal(np.argmax(dropped, axis=0)[10:], bad_cam[10:])
    assert err[10:].max() < 0.02
    assert np.mean(np.argmax(dropped, axis=0)[:10] == bad_cam[:10]) >= 0.7
    # with only 2 views nothing can be rejected: the point is solved, with a large error
    uv2 = uv[:2].copy()
    uv2[0, 0] += 6.0
    r2 = triangulate(CameraRig(rig.cameras[:2]), uv2)
    assert r2.n_views[0] == 2 and r2.error[0] > 1.0


def test_point_behind_a_camera_is_rejected() -> None:
    rig = CameraRig([
        Camera("a", (160, 120), [[140, 0, 80], [0, 140, 60], [0, 0, 1]], np.zeros(5), [0, 0, 0], [0, 0, 0]),
        Camera("b", (160, 120), [[140, 0, 80], [0, 140, 60], [0, 0, 1]], np.zeros(5), [0, 0, 0], [-1.0, 0, 0]),
    ])
    # parallel cameras; disparity of the wrong sign puts the point behind both
    uv = np.array([[[80.0, 60.0]], [[100.0, 60.0]]])
    res = triangulate(rig, uv)
    assert np.isnan(res.points[0]).all() and res.n_views[0] == 0


def test_single_camera_rig_gives_nan_not_an_error() -> None:
    rig = CameraRig(default_rig(2).cameras[:1])
    res = Triangulator(rig).triangulate(rig.project(np.zeros((3, 3)) + [0, 0, 1.0]))
    assert np.isnan(res.points).all() and list(res.n_views) == [0, 0, 0]
    with pytest.raises(ValueError):
        Triangulator(CameraRig([]))


def test_two_views_from_one_centre_give_nan_not_an_error() -> None:
    """Two cameras at the same centre see a point along one ray: no depth, a NaN point (the
    compiled solver returns IEEE results, it never raises on a singular system)."""
    cam = Camera("a", (160, 120), [[140, 0, 80], [0, 140, 60], [0, 0, 1]], np.zeros(5), [0, 0, 0], [0, 0, 0])
    rig = CameraRig([cam, Camera("b", cam.size, cam.matrix, np.zeros(5), [0, 0, 0], [0, 0, 0])])
    res = Triangulator(rig).triangulate(np.array([[[80.0, 60.0], [90.0, 61.0]], [[80.0, 60.0], [90.0, 61.0]]]))
    assert res.points.shape == (2, 3) and list(res.n_views) == [0, 0]
    assert np.isnan(res.points).all()


@pytest.mark.parametrize("distorted", [True, False])
def test_rig_projection_and_undistortion_agree_with_each_cameras_model(distorted: bool) -> None:
    """The compiled rig-wide lens model the labelling uses every frame gives each camera's own
    pixels (Camera.project), NaN behind a camera, and undistorts them back to that camera's
    normalised coordinates (the table to ~1e-4 px; NaN for NaN and far outside the image)."""
    rig = default_rig(4)
    if not distorted:
        rig = CameraRig([Camera(c.name, c.size, c.matrix, np.zeros(5), c.rvec, c.tvec) for c in rig.cameras])
    tri = Triangulator(rig)
    rng = np.random.default_rng(5)
    X = np.vstack([_points(rng, 200), rig.cameras[0].center + [0.0, 0.0, 0.0], [np.nan, 0.0, 1.0]])
    uv, depth = tri.project(X)
    for c, cam in enumerate(rig.cameras):
        front = (cam.R @ (X - cam.center).T)[2] > 1e-9
        np.testing.assert_allclose(uv[c, front], cam.project(X[front]), atol=1e-9)
        assert np.isnan(uv[c, ~front]).all()
    assert np.isnan(uv[:, -1]).all() and np.isnan(depth[:, -1]).all()
    pix = uv[:, :200]  # inside or near the images
    pix[0, :3] = [np.nan, 5.0], [-50.0, 60.0], [80.0, 1e6]  # NaN, far outside the table
    xy = tri.undistort_normalized(pix)
    exact = tri.undistort_normalized_exact(pix)
    usable = np.isfinite(xy).all(axis=2)
    assert not usable[0, 0] and (not usable[0, 1:3].any()) == distorted  # the table ends past the image
    assert usable.sum() > 0.9 * usable.size
    px = (xy - exact)[usable] * tri.K[np.nonzero(usable)[0], 0, 0][:, None]  # (M, 2) px
    assert np.abs(px).max() < (1e-3 if distorted else 1e-12)
