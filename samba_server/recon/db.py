"""The motion database: poses from BVH captures in the joint-angle representation.

A :class:`MotionDB` stores, per pose, the 11 bone directions in the torso frame
(:mod:`samba_common.body`), plus the aligned 8-marker features and aligned 13-joint vectors of
the thesis (body frame of :mod:`samba_common.align`, shin = 1) for inspection and for search
with the database's own proportions. Bone lengths are kept per source clip. Neighbour search
uses the directions re-posed with the *subject's* bone lengths (see
:class:`samba_server.recon.reconstruct.Reconstructor`), so the database body never leaks into the
output proportions.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from samba_common.align import align_batch
from samba_common.body import bone_lengths, decompose, fk_body
from samba_common.bvh import BvhMapping, load_bvh, resample
from samba_common.formats import FormatError
from samba_common.skeleton import BONE_TYPES, JOINT_NAMES, MARKER_JOINT

log = logging.getLogger(__name__)

DB_VERSION = 2
DEFAULT_DB_NAME = "default_db.npz"
_KEYS = ("version", "dirs", "up", "clip", "clip_names", "clip_lengths", "fps")

#: left/right joint permutation used to mirror poses
_MIRROR = [JOINT_NAMES.index(n.replace("left", "@").replace("right", "left").replace("@", "right"))
           for n in JOINT_NAMES]


@dataclass
class MotionDB:
    """Poses of the motion database.

    dirs: (N, 11, 3) float32 unit bone directions in the torso frame;
    up: (N, 3) float32 world up (+Z) in the torso frame (how the pose stands to gravity);
    clip: (N,) int32 index into ``clip_names``; clip_names: (C,) str;
    clip_lengths: (C, 8) float32 bone lengths of each clip's body in metres (BONE_TYPES order);
    fps: rate the clips were resampled to.
    """

    dirs: np.ndarray
    up: np.ndarray
    clip: np.ndarray
    clip_names: np.ndarray
    clip_lengths: np.ndarray
    fps: float

    def __len__(self) -> int:
        return len(self.dirs)

    @property
    def mean_lengths(self) -> np.ndarray:
        """(8,) pose-weighted mean bone lengths of the database bodies, metres."""
        counts = np.bincount(self.clip, minlength=len(self.clip_names)).astype(float)
        return (counts @ self.clip_lengths.astype(float)) / counts.sum()

    def aligned_joints(self) -> np.ndarray:
        """(N, 13, 3) joints posed with each clip's own lengths, in the body frame (shin = 1)."""
        body = fk_body(self.dirs.astype(float), self.clip_lengths[self.clip].astype(float))
        shin = self.clip_lengths[self.clip, BONE_TYPES.index("shin")].astype(float)
        return align_batch(body[:, list(MARKER_JOINT)], body, shin)

    def subset(self, keep: np.ndarray) -> "MotionDB":
        """A database with the poses where boolean ``keep`` (N,) is true (clips kept as they are)."""
        return MotionDB(self.dirs[keep], self.up[keep], self.clip[keep], self.clip_names, self.clip_lengths, self.fps)

    def without(self, pattern: Callable[[str], bool]) -> "MotionDB":
        """Drop the poses of clips whose name satisfies ``pattern`` (e.g. leave-one-subject-out)."""
        bad = np.array([pattern(str(n)) for n in self.clip_names])
        return self.subset(~bad[self.clip])

    def save(self, path: str | os.PathLike) -> None:
        """Write the database as a compressed .npz (with the thesis' aligned features)."""
        aligned = self.aligned_joints().astype(np.float32)
        p = Path(path)
        tmp = p.with_name(p.name + ".part")
        with open(tmp, "wb") as fh:
            np.savez_compressed(
                fh, version=np.int32(DB_VERSION), dirs=self.dirs.astype(np.float32), up=self.up.astype(np.float32),
                clip=self.clip.astype(np.int32),
                clip_names=np.asarray(self.clip_names, dtype=str), clip_lengths=self.clip_lengths.astype(np.float32),
                fps=np.float64(self.fps), bone_types=np.array(BONE_TYPES), joint_names=np.array(JOINT_NAMES),
                joints_aligned=aligned, markers_aligned=aligned[:, list(MARKER_JOINT)])
        os.replace(tmp, p)

    @staticmethod
    def load(path: str | os.PathLike) -> "MotionDB":
        """Read a database .npz; FormatError names the file and the key when it is not one."""
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                data = {k: z[k] for k in _KEYS if k in z.files}
        except FileNotFoundError:
            raise FormatError(p, None, "file not found") from None
        except (OSError, ValueError, EOFError) as exc:
            raise FormatError(p, None, f"not a readable .npz file ({exc})") from None
        if "version" in data and int(data["version"]) != DB_VERSION:
            raise FormatError(p, "version", f"database version {int(data['version'])}, this Samba reads {DB_VERSION} "
                              "(rebuild it with samba-db build)")
        for key in _KEYS:
            if key not in data:
                raise FormatError(p, key, "missing key: not a Samba motion database (build one with samba-db build)")
        dirs, clip, lens = data["dirs"], data["clip"], data["clip_lengths"]
        if dirs.ndim != 3 or dirs.shape[1:] != (11, 3) or len(dirs) == 0:
            raise FormatError(p, "dirs", f"shape {dirs.shape}, expected (N>0, 11, 3)")
        if clip.shape != (len(dirs),) or clip.min() < 0 or clip.max() >= len(data["clip_names"]):
            raise FormatError(p, "clip", "does not index clip_names for every pose")
        if lens.shape != (len(data["clip_names"]), len(BONE_TYPES)) or not np.all(lens > 0):
            raise FormatError(p, "clip_lengths", f"shape {lens.shape}, expected (C, 8) positive lengths")
        if not np.all(np.isfinite(dirs)):
            raise FormatError(p, "dirs", "contains NaN or infinite values")
        if data["up"].shape != (len(dirs), 3) or not np.all(np.isfinite(data["up"])):
            raise FormatError(p, "up", f"shape {data['up'].shape}, expected ({len(dirs)}, 3) finite")
        return MotionDB(dirs.astype(np.float32), data["up"].astype(np.float32), clip.astype(np.int32), data["clip_names"].astype(str),
                        lens.astype(np.float32), float(data["fps"]))


def default_db_path() -> Path:
    """Path of the database shipped inside the package."""
    return Path(str(files("samba_common").joinpath("data", DEFAULT_DB_NAME)))


def sample_path() -> Path:
    """Path of the sample markers.npz shipped inside the package (scripts/make_sample.py)."""
    return Path(str(files("samba_common").joinpath("data", "sample_markers.npz")))


def load_default_db() -> MotionDB:
    """The shipped default database (built from the CMU clips, see samba_common/data/README.md)."""
    return MotionDB.load(default_db_path())


def _mirror(joints: np.ndarray) -> np.ndarray:
    out = joints[:, _MIRROR].copy()
    out[..., 0] *= -1.0
    return out


def _prune(dirs: np.ndarray, min_change: float) -> np.ndarray:
    """Indices of poses kept when each must differ from the last kept one by ``min_change``.

    The change is the largest angle (radians, chord approximation) between corresponding bones.
    """
    keep = [0]
    last = dirs[0]
    for i in range(1, len(dirs)):
        if np.max(np.linalg.norm(dirs[i] - last, axis=-1)) >= min_change:
            keep.append(i)
            last = dirs[i]
    return np.asarray(keep)


def build_db(sources: Iterable[str | os.PathLike], mapping: BvhMapping | str | None = None, fps: float = 30.0,
             min_change_deg: float = 4.0, mirror: bool = True, progress: Callable[[str], None] | None = None,
             base: MotionDB | None = None) -> MotionDB:
    """Build a database from BVH files.

    fps: resampling rate; min_change_deg: a pose is dropped when no bone moved by this angle
    since the last kept pose of its clip; mirror: also add left-right mirrored poses;
    base: an existing database to extend (its poses are kept).
    """
    dirs_all, up_all, clip_all, names, lengths = [], [], [], [], []
    if base is not None:
        dirs_all.append(base.dirs)
        up_all.append(base.up)
        clip_all.append(base.clip)
        names.extend(str(n) for n in base.clip_names)
        lengths.extend(base.clip_lengths)
    thr = 2.0 * np.sin(np.radians(min_change_deg) / 2.0)
    for src in sources:
        take = load_bvh(src, mapping)
        joints, _t = resample(take.joints, take.t, fps)
        lens = np.median(bone_lengths(joints), axis=0)
        variants = [(Path(src).stem, joints)] + ([(Path(src).stem + "~mirror", _mirror(joints))] if mirror else [])
        for name, jts in variants:
            _o, R, dirs = decompose(jts)
            keep = _prune(dirs, thr)
            dirs_all.append(dirs[keep].astype(np.float32))
            up_all.append(R[keep, 2, :].astype(np.float32))  # world Z in torso coordinates: row 2 of R
            clip_all.append(np.full(len(keep), len(names), np.int32))
            names.append(name)
            lengths.append(lens.astype(np.float32))
        if progress:
            progress(str(src))
    if not dirs_all:
        raise ValueError("no BVH files given")
    return MotionDB(np.concatenate(dirs_all), np.concatenate(up_all), np.concatenate(clip_all), np.array(names),
                    np.array(lengths, dtype=np.float32), float(fps))
