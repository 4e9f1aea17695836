"""Readers and writers for ``markers.npz`` and ``joints.npz`` (FORMATS.md).

Every reader validates keys, shapes, dtypes and names and raises :class:`FormatError`
naming the file and the key, so a user sees *which* file is wrong and *why*.
"""

from __future__ import annotations

import os
import zipfile
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
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise FormatError(p, None, f"not a readable .npz file ({exc})") from None


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


def load_markers(path: str | os.PathLike) -> MarkerTake:
    """Read and validate a ``markers.npz``. Raises FormatError naming file and key."""
    data = _open_npz(path)
    markers = _points(path, data, "markers", len(MARKER_NAMES))
    t = _times(path, data, markers.shape[0])
    _names(path, data, "marker_names", MARKER_NAMES)
    extra = {k: v for k, v in data.items() if k not in ("markers", "t", "marker_names")}
    return MarkerTake(markers, t, extra)


def save_markers(path: str | os.PathLike, markers: np.ndarray, t: np.ndarray, **extra: np.ndarray) -> None:
    """Write a ``markers.npz``. markers: (F, 8, 3) metres; t: (F,) seconds."""
    markers = np.asarray(markers, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if markers.ndim != 3 or markers.shape[1:] != (len(MARKER_NAMES), 3) or t.shape != (markers.shape[0],):
        raise ValueError(f"markers {markers.shape} / t {t.shape} do not match (F, 8, 3) / (F,)")
    _atomic_savez(path, markers=markers, t=t, marker_names=np.array(MARKER_NAMES), **extra)


def load_joints(path: str | os.PathLike) -> JointTake:
    """Read and validate a ``joints.npz``. Raises FormatError naming file and key."""
    data = _open_npz(path)
    joints = _points(path, data, "joints", len(JOINT_NAMES))
    t = _times(path, data, joints.shape[0])
    _names(path, data, "joint_names", JOINT_NAMES)
    extra = {k: v for k, v in data.items() if k not in ("joints", "t", "joint_names")}
    return JointTake(joints, t, extra)


def save_joints(path: str | os.PathLike, joints: np.ndarray, t: np.ndarray, **extra: np.ndarray) -> None:
    """Write a ``joints.npz``. joints: (F, 13, 3) metres; t: (F,) seconds; extra keys allowed."""
    joints = np.asarray(joints, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if joints.ndim != 3 or joints.shape[1:] != (len(JOINT_NAMES), 3) or t.shape != (joints.shape[0],):
        raise ValueError(f"joints {joints.shape} / t {t.shape} do not match (F, 13, 3) / (F,)")
    _atomic_savez(path, joints=joints, t=t, joint_names=np.array(JOINT_NAMES), **extra)


def _atomic_savez(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """Write an .npz next to its destination, then rename: a crash never leaves half a file."""
    p = Path(path)
    tmp = p.with_name(p.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, p)
