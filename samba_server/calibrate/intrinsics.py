"""Intrinsics (K, distortion) from checkerboard or ChArUco views: OpenCV calibrateCamera.

Board specs (command line ``--board``):

* ``checkerboard:COLSxROWS:SQUARE`` - inner corners per row x per column, square side in m
  (``checkerboard:9x6:0.025``);
* ``charuco:SQX x SQY:SQUARE:MARKER[:DICT]`` - squares, square and marker side in m, ArUco
  dictionary name (default ``DICT_4X4_50``), e.g. ``charuco:5x7:0.04:0.03``.

SOURCE is a directory of images, a video file (every ``step``-th frame) or a glob pattern.
"""

from __future__ import annotations

import glob
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Iterator

import cv2
import numpy as np

from samba_common.calib import Camera

log = logging.getLogger(__name__)

#: board views used at most (evenly spread over those found). The principal point, which sets
#: each camera's rotation in the wand step (1 px ~ 0.4 deg at fx 140), needs them: on rendered
#: 160x120 boards its error is ~0.3-0.5 px from 40 views, ~0.1-0.2 px from 400, and the wand
#: calibration's rotations go from 0.14-0.22 deg to <= 0.074 deg (benchmarks/calibration.py).
#: OpenCV's dense adjustment grows fast with the views: ~1.7 s for 200, ~12 s for 400 (with the
#: detection in 600 frames, one camera).
MAX_VIEWS = 500

_IMAGE_EXT = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm"}


class BoardError(ValueError):
    """A board specification is malformed."""


@dataclass(frozen=True)
class Board:
    kind: str  #: "checkerboard" or "charuco"
    cols: int  #: inner corners (checkerboard) or squares (charuco) along x
    rows: int
    square: float  #: m
    marker: float = 0.0  #: m (charuco)
    dictionary: str = "DICT_4X4_50"

    @classmethod
    def parse(cls, spec: str) -> "Board":
        parts = spec.split(":")
        try:
            kind = parts[0].lower()
            cols, rows = (int(v) for v in parts[1].lower().split("x"))
            square = float(parts[2])
            if kind == "checkerboard" and len(parts) == 3:
                board = cls(kind, cols, rows, square)
            elif kind == "charuco" and len(parts) in (4, 5):
                board = cls(kind, cols, rows, square, float(parts[3]), parts[4] if len(parts) == 5 else "DICT_4X4_50")
            else:
                raise ValueError
        except (ValueError, IndexError):
            raise BoardError(f"bad board {spec!r}: expected checkerboard:COLSxROWS:SQUARE or "
                             "charuco:SQXxSQY:SQUARE:MARKER[:DICT]") from None
        if min(board.cols, board.rows) < 2 or board.square <= 0:
            raise BoardError(f"bad board {spec!r}: need >= 2x2 and a positive square size")
        if kind == "charuco" and not 0 < board.marker < board.square:
            raise BoardError(f"bad board {spec!r}: marker size must be between 0 and the square size")
        if kind == "charuco" and not hasattr(cv2.aruco, board.dictionary):
            raise BoardError(f"bad board {spec!r}: unknown ArUco dictionary {board.dictionary}")
        return board

    def object_points(self) -> np.ndarray:
        """Checkerboard inner corners (N, 3) m in the board plane, OpenCV order."""
        g = np.mgrid[0:self.cols, 0:self.rows].T.reshape(-1, 2)
        return np.hstack([g * self.square, np.zeros((len(g), 1))]).astype(np.float32)


def iter_frames(source: str | os.PathLike, step: int = 1) -> Iterator[tuple[str, np.ndarray]]:
    """(name, (H, W) uint8 grey) for a directory of images, a video or a glob pattern."""
    p = Path(source)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in _IMAGE_EXT)
    elif p.is_file() and p.suffix.lower() in _IMAGE_EXT:
        files = [p]
    elif p.is_file():
        cap = cv2.VideoCapture(str(p))
        if not cap.isOpened():
            raise FileNotFoundError(f"{p}: cannot open as a video")
        i = 0
        try:
            while True:
                ok, img = cap.read()
                if not ok:
                    break
                if i % step == 0:
                    yield f"{p.name}#{i}", img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
                i += 1
        finally:
            cap.release()
        return
    else:
        files = [Path(f) for f in sorted(glob.glob(str(source)))]
    if not files:
        raise FileNotFoundError(f"{source}: no images found")
    for f in files[::step]:
        img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
        if img is None:
            log.warning("%s: not an image, skipped", f)
            continue
        yield f.name, img


def detect(board: Board, img: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Board corners in one image -> (object points (N, 3), image points (N, 2)) or None."""
    if board.kind == "checkerboard":
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        ok, corners = cv2.findChessboardCorners(img, (board.cols, board.rows), flags=flags)
        if not ok:
            return None
        corners = cv2.cornerSubPix(img, corners, (3, 3), (-1, -1),
                                   (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3))
        return board.object_points(), corners.reshape(-1, 2)
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, board.dictionary))
    cb = cv2.aruco.CharucoBoard((board.cols, board.rows), board.square, board.marker, d)
    corners, ids, _, _ = cv2.aruco.CharucoDetector(cb).detectBoard(img)
    if ids is None or len(ids) < 6:
        return None
    obj = cb.getChessboardCorners()[ids.ravel()]
    return obj.astype(np.float32), corners.reshape(-1, 2)


@dataclass
class IntrinsicsResult:
    camera: Camera
    rms_px: float  #: calibrateCamera reprojection rms
    n_views: int  #: views with a detected board
    n_frames: int  #: frames read
    coverage: float  #: fraction of 8x6 image cells holding a detected corner
    #: standard deviations (9,) of fx, fy, cx, cy (px), k1, k2, p1, p2, k3 (OpenCV's estimate
    #: from the corner residuals)
    std: np.ndarray = field(default_factory=lambda: np.full(9, np.nan))
    #: covariance (9, 9) of the same parameters (:func:`intrinsics_covariance`; rows and
    #: columns of fixed coefficients are 0); the wand step uses it as its prior
    cov: np.ndarray = field(default_factory=lambda: np.full((9, 9), np.nan))


def intrinsics_covariance(objs: list[np.ndarray], imgs: list[np.ndarray], K: np.ndarray, dist: np.ndarray,
                          rvecs, tvecs, fix_k3: bool = True) -> np.ndarray:
    """Covariance (9, 9) of [fx, fy, cx, cy, k1, k2, p1, p2, k3] (px, px, px, px, 1...) of a
    board calibration, the views' poses marginalised (Schur complement): ``s^2 (J^T J)^-1``
    with s^2 the corner residuals' sum of squares over the degrees of freedom, as OpenCV's
    standard deviations (whose squares are its diagonal). The off-diagonal terms matter:
    k1 and k2 are strongly anticorrelated (the board fixes the radial profile far better than
    either), and a prior built from the standard deviations alone lets the wand step trade
    the profile against the principal point (0.1-0.2 deg of camera rotation).

    objs: per view (N, 3) board points m; imgs: per view (N, 2) corners px; K (3, 3), dist
    (>= 5,), rvecs/tvecs per view, from ``cv2.calibrateCamera*``."""
    d = np.zeros(5)
    dd = np.asarray(dist, float).ravel()[:5]
    d[:len(dd)] = dd
    free = np.array([True] * 8 + [not fix_k3])
    info = np.zeros((9, 9))
    ss, n_res, n_par = 0.0, 0, int(free.sum())
    for o, im, rv, tv in zip(objs, imgs, rvecs, tvecs):
        proj, jac = cv2.projectPoints(np.asarray(o, np.float64), rv, tv, K, d)
        r = proj.reshape(-1, 2) - np.asarray(im, np.float64).reshape(-1, 2)
        ss += float(np.sum(r * r))
        n_res += r.size
        n_par += 6
        Jp, Ji = jac[:, :6], jac[:, 6:15]  # pose; fx, fy, cx, cy, k1, k2, p1, p2, k3
        A = Jp.T @ Jp
        B = Jp.T @ Ji
        info += Ji.T @ Ji - B.T @ np.linalg.solve(A, B)
    cov = np.zeros((9, 9))
    sigma2 = ss / max(n_res - n_par, 1)
    cov[np.ix_(free, free)] = sigma2 * np.linalg.inv(info[np.ix_(free, free)])
    return cov


def calibrate_intrinsics(name: str, source: str | os.PathLike, board: Board, step: int = 1,
                         max_views: int = MAX_VIEWS, fix_k3: bool = True, progress=None) -> IntrinsicsResult:
    """Calibrate one camera's K and distortion from the board views of a video or image
    folder (every ``step``-th frame); raises ValueError when the board was found in fewer than
    4 views."""
    frames = (img for _, img in iter_frames(source, step))
    return calibrate_frames(name, frames, board, max_views, fix_k3, progress, what=str(source))


def calibrate_frames(name: str, frames: Iterable[np.ndarray], board: Board, max_views: int = MAX_VIEWS,
                     fix_k3: bool = True, progress=None, what: str = "board views") -> IntrinsicsResult:
    """Calibrate one camera's K and distortion from images (H, W) of the board (at most
    ``max_views`` of those where it is found, evenly spread); ``what`` names them in errors.
    Raises ValueError when the board was found in fewer than 4 views."""
    objs, imgs, size, n = [], [], None, 0
    for img in frames:
        n += 1
        size = (img.shape[1], img.shape[0])
        got = detect(board, img)
        if got is not None:
            objs.append(got[0])
            imgs.append(got[1].astype(np.float32))
        if progress is not None:
            progress(n)
    if size is None:
        raise ValueError(f"{what}: no frames")
    if len(objs) < 4:
        raise ValueError(f"{what}: board found in {len(objs)} of {n} frames; need >= 4 views at varied angles")
    if len(objs) > max_views:
        keep = np.linspace(0, len(objs) - 1, max_views).round().astype(int)
        objs, imgs = [objs[k] for k in keep], [imgs[k] for k in keep]
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    rms, K, dist, rvecs, tvecs, std, _, _ = cv2.calibrateCameraExtended(objs, imgs, size, None, None, flags=flags)
    w, h = size
    allp = np.concatenate(imgs)
    cells = {(int(u * 8 // w), int(v * 6 // h)) for u, v in allp if 0 <= u < w and 0 <= v < h}
    cam = Camera(name, size, K, np.asarray(dist, float).ravel()[:5])
    log.info("%s: rms %.3f px from %d views, coverage %.0f %%", name, rms, len(objs), 100 * len(cells) / 48)
    sd = np.full(9, np.nan)
    got = np.asarray(std, float).ravel()[:9]
    sd[:len(got)] = got
    cov = intrinsics_covariance(objs, imgs, K, dist, rvecs, tvecs, fix_k3)
    return IntrinsicsResult(cam, float(rms), len(objs), n, len(cells) / 48.0, sd, cov)


def render_board_views(camera: Camera, board: Board, n_views: int = 12, seed: int = 0,
                       supersample: int = 2) -> list[np.ndarray]:
    """Synthetic checkerboard images (H, W) uint8 seen by ``camera`` (with its distortion),
    the board at varied poses 0.6-1.2 m away; for tests and ``simulate board``."""
    from samba_common.calib import rodrigues

    rng = np.random.default_rng(seed)
    w, h = camera.size
    s = supersample
    uu, vv = np.meshgrid((np.arange(w * s) + 0.5) / s - 0.5, (np.arange(h * s) + 0.5) / s - 0.5)
    xy = camera.undistort_normalized(np.stack([uu.ravel(), vv.ravel()], axis=1))
    rays = np.hstack([xy, np.ones((len(xy), 1))])
    bw, bh = (board.cols + 1) * board.square, (board.rows + 1) * board.square
    out = []
    for _ in range(n_views):
        R = rodrigues(rng.uniform(-0.5, 0.5, 3) * [1, 1, 0.4])
        dist = rng.uniform(0.5, 0.8) * board.square / 0.025 * 0.35
        shift = rng.uniform(-0.12, 0.12, 2) * dist
        t = np.array([shift[0], shift[1], dist])
        # board plane point: X = R @ (b - c) + t with b in board coords, c = board centre
        n = R[:, 2]
        lam = (n @ t) / (rays @ n)
        P = rays * lam[:, None] - t
        b = P @ R  # board coordinates relative to the centre
        bx, by = b[:, 0] + bw / 2 - board.square, b[:, 1] + bh / 2 - board.square
        ix, iy = np.floor(bx / board.square + 1), np.floor(by / board.square + 1)
        inside = (ix >= 0) & (ix <= board.cols) & (iy >= 0) & (iy <= board.rows) & (lam > 0)
        val = np.where(inside, np.where((ix + iy) % 2 == 0, 20.0, 230.0), 230.0)
        margin = (bx > -1.6 * board.square) & (bx < bw - 0.4 * board.square) & (by > -1.6 * board.square) & (by < bh - 0.4 * board.square)
        val = np.where(margin | inside, val, 90.0)
        img = val.reshape(h * s, w * s).reshape(h, s, w, s).mean(axis=(1, 3))
        out.append(np.clip(np.rint(img + rng.normal(0, 1.0, img.shape)), 0, 255).astype(np.uint8))
    return out
