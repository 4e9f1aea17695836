"""Readers and writers for ``markers.npz`` and ``joints.npz`` (FORMATS.md).

Every reader validates keys, shapes, dtypes and names and raises :class:`FormatError`
naming the file and the key, so a user sees *which* file is wrong and *why*.
"""

from __future__ import annotations

import os
import struct
import zipfile
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .skeleton import JOINT_NAMES, MARKER_NAMES


class FormatError(ValueError):
    """A Samba file does not follow FORMATS.md. ``str(err)`` names the file and the key."""

    def __init__(self, path: str | os.PathLike, key: str | None, message: str):
        self.path = str(path)
        self.key = key
        where = f"{self.path}" + (f" [{key}]" if key else "")
        super().__init__(f"{where}: {message}")


@dataclass
class MarkerTake:
    """Labelled 3D markers of one take.

    markers: (F, 8, 3) float64 world metres, NaN where unseen; t: (F,) float64 seconds.
    """

    markers: np.ndarray
    t: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class JointTake:
    """Reconstructed 13-joint skeleton of one take.

    joints: (F, 13, 3) float64 world metres (a whole frame NaN when unsolved);
    t: (F,) float64 seconds; extra: additional arrays (residuals, bone lengths, ...).
    """

    joints: np.ndarray
    t: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)


def _open_npz(path: str | os.PathLike) -> dict[str, np.ndarray]:
    p = Path(path)
    if not p.exists():
        raise FormatError(p, None, "file not found")
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, KeyError, struct.error,
            UnicodeDecodeError, MemoryError, NotImplementedError) as exc:  # a damaged zip/npy fails in any layer
        raise FormatError(p, None, f"not a readable .npz file ({type(exc).__name__}: {exc})") from None


def _names(path, data, key, expected: tuple[str, ...]) -> None:
    if key not in data:
        raise FormatError(path, key, f"missing key (expected {list(expected)})")
    names = tuple(str(s) for s in np.asarray(data[key]).reshape(-1))
    if names != expected:
        raise FormatError(path, key, f"names {list(names)} differ from {list(expected)}")


def _points(path, data, key, n: int) -> np.ndarray:
    if key not in data:
        raise FormatError(path, key, "missing key")
    a = data[key]
    if a.dtype.kind not in "fiu":
        raise FormatError(path, key, f"dtype {a.dtype} is not numeric")
    if a.ndim != 3 or a.shape[1:] != (n, 3):
        raise FormatError(path, key, f"shape {a.shape}, expected (F, {n}, 3)")
    a = a.astype(np.float64)
    if np.isinf(a).any():
        raise FormatError(path, key, "contains infinite values (use NaN for missing)")
    return a


def _times(path, data, n_frames: int) -> np.ndarray:
    if "t" not in data:
        raise FormatError(path, "t", "missing key")
    t = np.asarray(data["t"])
    if t.dtype.kind not in "fiu" or t.shape != (n_frames,):
        raise FormatError(path, "t", f"shape {t.shape} dtype {t.dtype}, expected ({n_frames},) float seconds")
    t = t.astype(np.float64)
    if not np.all(np.isfinite(t)):
        raise FormatError(path, "t", "contains NaN or infinite times")
    if n_frames > 1 and np.any(np.diff(t) < 0):
        raise FormatError(path, "t", "times are not in increasing order")
    return t


def _load_take(path, key: str, names_key: str, names: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, dict]:
    data = _open_npz(path)
    points = _points(path, data, key, len(names))
    t = _times(path, data, points.shape[0])
    _names(path, data, names_key, names)
    return points, t, {k: v for k, v in data.items() if k not in (key, "t", names_key)}


def _save_take(path, key: str, points: np.ndarray, t: np.ndarray, names_key: str, names: tuple[str, ...],
               extra: dict[str, np.ndarray]) -> None:
    points = np.asarray(points, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if points.ndim != 3 or points.shape[1:] != (len(names), 3) or t.shape != (points.shape[0],):
        raise ValueError(f"{key} {points.shape} / t {t.shape} do not match (F, {len(names)}, 3) / (F,)")
    _atomic_savez(path, **{key: points, "t": t, names_key: np.array(names)}, **extra)


def load_markers(path: str | os.PathLike) -> MarkerTake:
    """Read and validate a ``markers.npz``. Raises FormatError naming file and key."""
    return MarkerTake(*_load_take(path, "markers", "marker_names", MARKER_NAMES))


def save_markers(path: str | os.PathLike, markers: np.ndarray, t: np.ndarray, **extra: np.ndarray) -> None:
    """Write a ``markers.npz`` (atomically). markers: (F, 8, 3) metres; t: (F,) seconds."""
    _save_take(path, "markers", markers, t, "marker_names", MARKER_NAMES, extra)


def load_joints(path: str | os.PathLike) -> JointTake:
    """Read and validate a ``joints.npz``. Raises FormatError naming file and key."""
    return JointTake(*_load_take(path, "joints", "joint_names", JOINT_NAMES))


def save_joints(path: str | os.PathLike, joints: np.ndarray, t: np.ndarray, **extra: np.ndarray) -> None:
    """Write a ``joints.npz`` (atomically). joints: (F, 13, 3) metres; t: (F,) seconds; extra keys allowed."""
    _save_take(path, "joints", joints, t, "joint_names", JOINT_NAMES, extra)


def _atomic_savez(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """Write an .npz next to its destination, then rename: a crash never leaves half a file."""
    p = Path(path)
    tmp = p.with_name(p.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, p)
