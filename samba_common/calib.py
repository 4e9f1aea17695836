"""Camera model and ``calibration.toml`` IO (anipose layout, FORMATS.md), plus default rigs.

Conventions: world frame Z up, metres. A camera maps a world point ``X`` (3,) to camera
coordinates ``x_cam = R @ X + t`` (OpenCV: x right, y down, z forward), then to pixels with
the OpenCV pinhole + distortion model (``k1, k2, p1, p2, k3``). Pure numpy: neither cv2 nor
scipy is needed (the mote imports this module). A file's translations may be in other units
(``[metadata] units = "mm"`` or ``"cm"``, anipose's board units): they are metres once loaded,
and files are always written in metres.
"""

from __future__ import annotations

import json
import logging
import math
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

log = logging.getLogger(__name__)

__all__ = [
    "CalibrationError",
    "Camera",
    "UNITS_TO_METRES",
    "CameraRig",
    "default_rig",
    "distort",
    "look_at",
    "rodrigues",
    "rotation_to_rvec",
]


class CalibrationError(ValueError):
    """A calibration file or camera is invalid. ``str(err)`` names the file and the key."""

    def __init__(self, path: str | os.PathLike | None, key: str | None, message: str):
        self.path = None if path is None else str(path)
        self.key = key
        where = self.path or "<calibration>"
        if key:
            where += f" [{key}]"
        super().__init__(f"{where}: {message}")


# --------------------------------------------------------------------------- rotations


def rodrigues(rvec: np.ndarray) -> np.ndarray:
    """Rodrigues vector (3,) (axis * angle, radians) -> rotation matrix (3, 3)."""
    r = np.asarray(rvec, dtype=float).reshape(3)
    theta = math.sqrt(float(r @ r))
    K = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    if theta < 1e-8:
        # second-order expansion: exact to double precision for tiny angles
        return np.eye(3) + K + 0.5 * (K @ K)
    a = math.sin(theta) / theta
    b = (1.0 - math.cos(theta)) / (theta * theta)
    return np.eye(3) + a * K + b * (K @ K)


def distort(x: np.ndarray, y: np.ndarray, k1, k2, p1, p2, k3) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's lens model: ideal normalised coordinates x, y -> distorted ones. The
    coefficients are scalars or arrays that broadcast with x (one per camera of a rig)."""
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y)


def rotation_to_rvec(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) -> Rodrigues vector (3,), angle in [0, pi]. Robust near 0 and pi."""
    R = np.asarray(R, dtype=float).reshape(3, 3)
    # quaternion (w, x, y, z) by Shepperd's method, then axis-angle
    tr = np.trace(R)
    if tr > max(R[0, 0], R[1, 1], R[2, 2]):
        s = math.sqrt(tr + 1.0) * 2.0
        q = np.array([0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s])
    elif R[0, 0] >= R[1, 1] and R[0, 0] >= R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2.0
        q = np.array([(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s])
    elif R[1, 1] >= R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2.0
        q = np.array([(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s])
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2.0
        q = np.array([(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s])
    if q[0] < 0:
        q = -q
    v = q[1:]
    nv = float(np.linalg.norm(v))
    if nv < 1e-15:
        return np.zeros(3)
    angle = 2.0 * math.atan2(nv, q[0])
    return v / nv * angle


def look_at(center: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """World -> camera rotation (3, 3) for a camera at ``center`` looking at ``target`` (metres).

    Camera axes follow OpenCV: x right, y down (towards -up), z forward.
    """
    c, tgt, u = (np.asarray(a, dtype=float).reshape(3) for a in (center, target, up))
    z = tgt - c
    z /= np.linalg.norm(z)
    x = np.cross(z, u)
    nx = np.linalg.norm(x)
    if nx < 1e-9:
        raise ValueError("look_at: viewing direction is parallel to 'up'")
    x /= nx
    y = np.cross(z, x)
    return np.stack([x, y, z])


# --------------------------------------------------------------------------- camera


@dataclass
class Camera:
    """One calibrated camera.

    name: mote id; size: (width, height) pixels; matrix: (3, 3) intrinsics K;
    dist: (5,) OpenCV distortion (k1, k2, p1, p2, k3); rvec: (3,) Rodrigues world -> camera;
    tvec: (3,) metres, ``x_cam = R @ x_world + t``.
    """

    name: str
    size: tuple[int, int]
    matrix: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    rvec: np.ndarray = field(default_factory=lambda: np.zeros(3))
    tvec: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        self.size = (int(self.size[0]), int(self.size[1]))
        self.matrix = np.asarray(self.matrix, dtype=float).reshape(3, 3)
        d = np.asarray(self.dist, dtype=float).ravel()
        if d.size < 5:
            d = np.concatenate([d, np.zeros(5 - d.size)])
        self.dist = d
        self.rvec = np.asarray(self.rvec, dtype=float).reshape(3)
        self.tvec = np.asarray(self.tvec, dtype=float).reshape(3)

    # ---- geometry
    @property
    def R(self) -> np.ndarray:
        """World -> camera rotation matrix (3, 3)."""
        return rodrigues(self.rvec)

    @property
    def P(self) -> np.ndarray:
        """Projection matrix (3, 4) = K [R | t] (ideal pinhole, without distortion)."""
        return self.matrix @ np.hstack([self.R, self.tvec[:, None]])

    @property
    def center(self) -> np.ndarray:
        """Camera centre (3,) in world metres: ``-R.T @ t``."""
        return -self.R.T @ self.tvec

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist != 0.0))

    def to_camera(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) metres -> camera coordinates (N, 3) metres."""
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        return X @ self.R.T + self.tvec

    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalised coordinates (N, 2) -> distorted normalised coordinates (N, 2)."""
        return np.stack(distort(xy[:, 0], xy[:, 1], *self.dist[:5]), axis=-1)

    def project(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) metres -> pixels (N, 2) with distortion; NaN behind the camera."""
        Xc = self.to_camera(X)
        z = Xc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = Xc[:, :2] / z[:, None]
        xy[~(z > 1e-9)] = np.nan
        xyd = self.distort_normalized(xy)
        K = self.matrix
        u = K[0, 0] * xyd[:, 0] + K[0, 1] * xyd[:, 1] + K[0, 2]
        v = K[1, 1] * xyd[:, 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def undistort_normalized(self, uv: np.ndarray, iterations: int = 20) -> np.ndarray:
        """Raw pixels (N, 2) -> ideal normalised image coordinates (N, 2) (NaN stays NaN).

        Inverts the distortion with vectorised Newton steps (exact to ~1e-12 for the
        moderate distortion of real lenses, unlike a fixed-point loop).
        """
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        K = self.matrix
        yd = (uv[:, 1] - K[1, 2]) / K[1, 1]
        xd = (uv[:, 0] - K[0, 2] - K[0, 1] * yd) / K[0, 0]
        if not self.has_distortion:
            return np.stack([xd, yd], axis=-1)
        k1, k2, p1, p2, k3 = self.dist[:5]
        x, y = xd.copy(), yd.copy()
        for _ in range(iterations):
            r2 = x * x + y * y
            rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            drad = k1 + 2.0 * k2 * r2 + 3.0 * k3 * r2 * r2  # d rad / d r2
            fx = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
            fy = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
            a = rad + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
            b = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
            d = rad + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
            det = a * d - b * b
            with np.errstate(divide="ignore", invalid="ignore"):
                dx = (d * fx - b * fy) / det
                dy = (a * fy - b * fx) / det
            x = x - dx
            y = y - dy
            step = np.nanmax(np.abs(np.concatenate([dx, dy]))) if dx.size else 0.0
            if not np.isfinite(step) or step < 1e-14:
                break
        return np.stack([x, y], axis=-1)

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Raw pixels (N, 2) -> ideal pinhole pixels (N, 2) of the same K (NaN stays NaN)."""
        xy = self.undistort_normalized(uv)
        K = self.matrix
        u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
        v = K[1, 1] * xy[:, 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """(N,) bool: pixel positions (N, 2) inside the image, ``margin`` px from the border."""
        w, h = self.size
        u, v = uv[:, 0], uv[:, 1]
        with np.errstate(invalid="ignore"):
            return (u >= margin - 0.5) & (u <= w - 0.5 - margin) & (v >= margin - 0.5) & (v <= h - 0.5 - margin)

    # ---- dict IO (anipose layout)
    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "size": [int(self.size[0]), int(self.size[1])],
            "matrix": self.matrix.tolist(),
            "distortions": self.dist.tolist(),
            "rotation": self.rvec.tolist(),
            "translation": self.tvec.tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], path: str | os.PathLike | None = None, key: str = "cam") -> "Camera":
        """Build from one anipose table; raise CalibrationError naming ``path`` and ``key.field``."""
        if not isinstance(d, dict):
            raise CalibrationError(path, key, "expected a table")

        def arr(field_name: str, shape: tuple[int, ...]) -> np.ndarray:
            if field_name not in d:
                raise CalibrationError(path, f"{key}.{field_name}", "missing")
            try:
                a = np.asarray(d[field_name], dtype=float)
            except (TypeError, ValueError):
                raise CalibrationError(path, f"{key}.{field_name}", "expected numbers") from None
            if a.shape != shape:
                raise CalibrationError(path, f"{key}.{field_name}", f"expected shape {shape}, got {a.shape}")
            if not np.all(np.isfinite(a)):
                raise CalibrationError(path, f"{key}.{field_name}", "contains non-finite values")
            return a

        name = d.get("name", key)
        if not isinstance(name, str) or not name.strip():
            raise CalibrationError(path, f"{key}.name", "expected a non-empty string")
        size = d.get("size")
        if size is None:
            raise CalibrationError(path, f"{key}.size", "missing")
        if (
            not isinstance(size, list)
            or len(size) != 2
            or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)
        ):
            raise CalibrationError(path, f"{key}.size", f"expected [width, height] positive integers, got {size!r}")
        K = arr("matrix", (3, 3))
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationError(path, f"{key}.matrix", f"focal lengths must be positive, got {K[0, 0]}, {K[1, 1]}")
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise CalibrationError(path, f"{key}.matrix", "expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
        if "distortions" not in d:
            raise CalibrationError(path, f"{key}.distortions", "missing")
        dist = np.asarray(d["distortions"], dtype=float) if isinstance(d["distortions"], list) else None
        if dist is None or dist.ndim != 1 or dist.size not in (4, 5):
            raise CalibrationError(path, f"{key}.distortions", "expected [k1, k2, p1, p2, k3]")
        if not np.all(np.isfinite(dist)):
            raise CalibrationError(path, f"{key}.distortions", "contains non-finite values")
        rvec = arr("rotation", (3,))
        tvec = arr("translation", (3,))
        return cls(name=name, size=(size[0], size[1]), matrix=K, dist=dist, rvec=rvec, tvec=tvec)


# --------------------------------------------------------------------------- rig

#: ``[metadata] units`` of calibration.toml -> metres per unit (translations are scaled on load)
UNITS_TO_METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001}

#: a camera farther than this from the origin (metres) in a file without ``units`` is suspect
_FAR_CAMERA_M = 100.0


def _fmt_float(x: float) -> str:
    """TOML float literal that parses back to exactly ``x`` (shortest repr)."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"non-finite value {x}")
    s = repr(x)
    if "e" in s and "." not in s.split("e")[0]:
        mant, exp = s.split("e")
        s = f"{mant}.0e{exp}"
    return s


def _fmt_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return _fmt_float(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_fmt_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


@dataclass
class CameraRig:
    """All cameras of a capture setup (order = table order in calibration.toml)."""

    cameras: list[Camera]
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.cameras = list(self.cameras)
        names = [c.name for c in self.cameras]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise CalibrationError(None, None, f"duplicate camera names {dup}")

    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self):
        return iter(self.cameras)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.cameras]

    def camera(self, name: str) -> Camera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise KeyError(f"no camera named {name!r}; cameras: {self.names}")

    def index(self, name: str) -> int:
        return self.names.index(name)

    def project(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) metres -> pixels (C, N, 2) with distortion, NaN behind a camera."""
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        return np.stack([c.project(X) for c in self.cameras]) if self.cameras else np.zeros((0, len(X), 2))

    def projection_matrices(self) -> np.ndarray:
        """(C, 3, 4) ideal pinhole projection matrices K [R | t]."""
        return np.stack([c.P for c in self.cameras])

    def replace(self, camera: Camera) -> "CameraRig":
        """New rig with ``camera`` replacing the one of the same name (or appended)."""
        cams = [camera if c.name == camera.name else c for c in self.cameras]
        if camera.name not in self.names:
            cams.append(camera)
        return CameraRig(cams, dict(self.metadata))

    # ---- TOML IO
    def dumps(self) -> str:
        """calibration.toml text (anipose layout); floats round-trip exactly."""
        lines: list[str] = []
        for i, cam in enumerate(self.cameras):
            d = cam.to_dict()
            for k, v in d.items():
                try:
                    _fmt_value(v)
                except ValueError as exc:
                    raise CalibrationError(None, f"cam_{i}.{k}", str(exc)) from None
            lines.append(f"[cam_{i}]")
            lines += [f"{k} = {_fmt_value(v)}" for k, v in d.items()]
            lines.append("")
        # translations are metres in memory, whatever units the file was loaded from
        meta = {"units": "m", **{k: v for k, v in self.metadata.items() if k != "units"}}
        lines.append("[metadata]")
        for k, v in meta.items():
            if isinstance(v, dict):
                continue  # nested tables are not written
            lines.append(f"{json.dumps(str(k))} = {_fmt_value(v)}")
        return "\n".join(lines) + "\n"

    def save(self, path: str | os.PathLike) -> None:
        """Write calibration.toml atomically (temp file + rename)."""
        p = Path(path)
        text = self.dumps()
        tmp = p.with_name(p.name + ".tmp")
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, p)

    @classmethod
    def loads(cls, text: str | bytes, path: str | os.PathLike | None = None) -> "CameraRig":
        """Parse calibration.toml text; ``path`` only names the source in errors.

        ``[metadata] units`` ("m", "cm" or "mm"; "m" when absent) is the unit of the
        translations, as with anipose, whose translations are in the board's units: they are
        scaled to metres and the loaded rig's ``metadata["units"]`` is "m". Other units are a
        CalibrationError naming the file and ``metadata.units``.
        """
        if isinstance(text, bytes):
            try:
                text = text.decode("utf-8")
            except UnicodeDecodeError:
                raise CalibrationError(path, None, "not UTF-8 text") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise CalibrationError(path, None, f"invalid TOML ({exc})") from None
        meta = data.get("metadata", {})
        meta = dict(meta) if isinstance(meta, dict) else {}
        units = meta.get("units", "m")
        scale = UNITS_TO_METRES.get(units) if isinstance(units, str) else None
        if scale is None:
            raise CalibrationError(path, "metadata.units", f"unknown units {units!r}: expected one of "
                                   f"{', '.join(repr(u) for u in UNITS_TO_METRES)} (the unit of the translations)")
        keys = [k for k in data if k.startswith("cam_")]
        other = [k for k in data if k not in keys and k != "metadata"]
        if other:
            log.debug("%s: ignoring tables %s", path, other)

        def order(k: str) -> tuple[int, str]:
            suffix = k[4:]
            return (int(suffix), k) if suffix.isdigit() else (1 << 30, k)

        keys.sort(key=order)
        if not keys:
            raise CalibrationError(path, None, "no [cam_N] tables")
        cams = [Camera.from_dict(data[k], path, k) for k in keys]
        seen: dict[str, str] = {}
        for k, c in zip(keys, cams):
            if c.name in seen:
                raise CalibrationError(path, f"{k}.name", f"duplicate camera name {c.name!r} (also in {seen[c.name]})")
            seen[c.name] = k
        if scale != 1.0:
            for c in cams:
                c.tvec = c.tvec * scale
            log.info("%s: translations converted from %s to metres", path or "<calibration>", units)
        elif "units" not in meta:
            far = max(float(np.linalg.norm(c.center)) for c in cams)
            if far > _FAR_CAMERA_M:
                log.warning('%s: a camera is %.0f m from the origin; if the translations are in '
                            'millimetres, add units = "mm" to [metadata]', path or "<calibration>", far)
        meta["units"] = "m"
        return cls(cams, meta)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "CameraRig":
        """Read and validate calibration.toml; CalibrationError names the file and the key."""
        p = Path(path)
        try:
            raw = p.read_bytes()
        except FileNotFoundError:
            raise CalibrationError(p, None, "file not found") from None
        except OSError as exc:
            raise CalibrationError(p, None, f"cannot read ({exc.strerror})") from None
        return cls.loads(raw, p)


# --------------------------------------------------------------------------- default rigs

#: (azimuth deg, horizontal distance m, height m, k1) of the default cameras
_DEFAULT_4 = ((45.0, 4.7, 2.1, -0.05), (135.0, 4.9, 2.3, -0.04), (225.0, 4.8, 2.0, -0.06), (315.0, 5.0, 2.2, -0.05))
_DEFAULT_2 = _DEFAULT_4[:2]


def default_rig(n_cameras: int = 4) -> CameraRig:
    """The simulated standard rig: 2 or 4 cameras named ``cam0``.. at 160x120, fx = fy = 140 px.

    Cameras stand 4.7-5.0 m from the origin horizontally (5.1-5.5 m in 3D) at 2.0-2.3 m
    height, at azimuths 45, 135, 225, 315 deg, all looking at (0, 0, 0.9); with 2 cameras both are on the +Y side (in front of a subject
    facing +Y). Mild barrel distortion (k1 -0.04..-0.06) like cheap lenses. A subject
    standing within ~1.5 m of the origin is fully in view of every camera.
    """
    if n_cameras not in (2, 4):
        raise ValueError(f"default_rig: n_cameras must be 2 or 4, got {n_cameras}")
    spec = _DEFAULT_4 if n_cameras == 4 else _DEFAULT_2
    cams = []
    for i, (az, dist, height, k1) in enumerate(spec):
        a = math.radians(az)
        c = np.array([dist * math.cos(a), dist * math.sin(a), height])
        R = look_at(c, (0.0, 0.0, 0.9))
        K = np.array([[140.0, 0.0, 79.5], [0.0, 140.0, 59.5], [0.0, 0.0, 1.0]])
        cams.append(
            Camera(
                name=f"cam{i}",
                size=(160, 120),
                matrix=K,
                dist=np.array([k1, 0.0, 0.0, 0.0, 0.0]),
                rvec=rotation_to_rvec(R),
                tvec=-R @ c,
            )
        )
    return CameraRig(cams, {"source": f"default_rig({n_cameras})"})
