"""The subject: bone lengths and marker offsets of one person, and its ``subject.toml`` file.

``subject.toml`` (docs/formats.md)::

    [subject]
    placement = "skin"              # or "joint_centres" (all offsets zero)
    units = "m"

    [subject.bone_lengths]          # metres, samba_common.skeleton.BONE_TYPES
    shoulder_width = 0.36
    ...

    [subject.offsets]               # metres in each marker's segment frame (e1, e2, e3), see
    left_shoulder = [0.0, 0.045, 0.0]   # samba_common.markerset
    ...

    [subject.offsets_sigma]         # optional: 1-sigma uncertainty of each component (m)
    left_shoulder = [0.004, 0.009, 0.008]
    ...
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .markerset import PLACEMENTS
from .skeleton import BONE_TYPES, MARKER_NAMES, N_MARKERS

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]


class SubjectError(ValueError):
    """A subject file is unreadable or wrong; the message names the file and the key."""


@dataclass
class Subject:
    """lengths: (8,) metres, BONE_TYPES order; offsets: (8, 3) metres in segment frames,
    MARKER_NAMES order; offsets_sigma: (8, 3) metres or None; placement: "skin" or "joint_centres"."""

    lengths: np.ndarray
    offsets: np.ndarray = field(default_factory=lambda: np.zeros((N_MARKERS, 3)))
    offsets_sigma: np.ndarray | None = None
    placement: str = "skin"

    def __post_init__(self) -> None:
        self.lengths = np.asarray(self.lengths, dtype=float).reshape(len(BONE_TYPES))
        self.offsets = np.asarray(self.offsets, dtype=float).reshape(N_MARKERS, 3)
        if self.offsets_sigma is not None:
            self.offsets_sigma = np.asarray(self.offsets_sigma, dtype=float).reshape(N_MARKERS, 3)
        if self.placement not in PLACEMENTS:
            raise ValueError(f"placement must be one of {PLACEMENTS}, got {self.placement!r}")

    def metadata(self) -> dict[str, np.ndarray]:
        """Arrays to carry into joints.npz / exports: subject_lengths (8,), subject_offsets (8, 3),
        subject_placement (str), and subject_offsets_sigma (8, 3) when known (metres)."""
        out = {"subject_lengths": self.lengths, "subject_offsets": self.offsets,
               "subject_placement": np.array(self.placement)}
        if self.offsets_sigma is not None:
            out["subject_offsets_sigma"] = self.offsets_sigma
        return out

    def to_toml(self) -> str:
        """The subject as ``subject.toml`` text."""
        def vec(v: np.ndarray) -> str:
            return "[" + ", ".join(f"{x:.5f}" for x in v) + "]"

        lines = ["# Samba subject: bone lengths and marker offsets (docs/formats.md)", "[subject]",
                 f'placement = "{self.placement}"', 'units = "m"', "", "[subject.bone_lengths]"]
        lines += [f"{n} = {v:.5f}" for n, v in zip(BONE_TYPES, self.lengths)]
        lines += ["", "[subject.offsets]  # (e1, e2, e3) in the marker's segment frame"]
        lines += [f"{n} = {vec(v)}" for n, v in zip(MARKER_NAMES, self.offsets)]
        if self.offsets_sigma is not None:
            lines += ["", "[subject.offsets_sigma]"]
            lines += [f"{n} = {vec(v)}" for n, v in zip(MARKER_NAMES, self.offsets_sigma)]
        return "\n".join(lines) + "\n"

    def save(self, path: str | os.PathLike) -> None:
        """Write ``subject.toml`` (atomically)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(self.to_toml())
        os.replace(tmp, path)


def _table(path, table: dict, key: str, names: tuple[str, ...], width: int | None, required: bool = True):
    sub = table.get(key)
    if sub is None:
        if required:
            raise SubjectError(f"{path}: missing table [subject.{key}]")
        return None
    if not isinstance(sub, dict):
        raise SubjectError(f"{path}: subject.{key} must be a table")
    unknown = set(sub) - set(names)
    if unknown:
        raise SubjectError(f"{path}: subject.{key}: unknown name(s) {sorted(unknown)}; expected {list(names)}")
    out = []
    for n in names:
        if n not in sub:
            raise SubjectError(f"{path}: subject.{key}.{n} is missing")
        try:
            v = np.asarray(sub[n], dtype=float)
        except (TypeError, ValueError):
            raise SubjectError(f"{path}: subject.{key}.{n} must be numeric, got {sub[n]!r}") from None
        if v.shape != (() if width is None else (width,)) or not np.all(np.isfinite(v)):
            want = "a number" if width is None else f"a list of {width} numbers"
            raise SubjectError(f"{path}: subject.{key}.{n} must be {want}, got {sub[n]!r}")
        out.append(v)
    return np.array(out)


def load_subject(path: str | os.PathLike) -> Subject:
    """Read and validate ``subject.toml``. Raises SubjectError naming the file and key."""
    try:
        with open(path, "rb") as fh:
            text = fh.read().decode("utf-8")
    except OSError as exc:
        raise SubjectError(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise SubjectError(f"{path}: not UTF-8 text") from None
    return load_subject_text(text, path)


def load_subject_text(text: str, path: str | os.PathLike = "<subject>") -> Subject:
    """Validate ``subject.toml`` text (e.g. recorded in a take); ``path`` names it in errors."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SubjectError(f"{path}: not valid TOML: {exc}") from None
    table = data.get("subject")
    if not isinstance(table, dict):
        raise SubjectError(f"{path}: missing table [subject]")
    placement = table.get("placement", "skin")
    if placement not in PLACEMENTS:
        raise SubjectError(f"{path}: subject.placement must be one of {list(PLACEMENTS)}, got {placement!r}")
    units = table.get("units", "m")
    if units != "m":
        raise SubjectError(f"{path}: subject.units must be \"m\", got {units!r}")
    lengths = _table(path, table, "bone_lengths", BONE_TYPES, None)
    if np.any(lengths <= 0) or np.any(lengths > 2.0):
        raise SubjectError(f"{path}: subject.bone_lengths must be positive metres (< 2 m), got {lengths}")
    offsets = _table(path, table, "offsets", MARKER_NAMES, 3, required=placement == "skin")
    if offsets is None:
        offsets = np.zeros((N_MARKERS, 3))
    if np.any(np.abs(offsets) > 0.25):
        raise SubjectError(f"{path}: subject.offsets must be metres within 0.25 m of the joint, got {offsets.max():.3g}")
    sigma = _table(path, table, "offsets_sigma", MARKER_NAMES, 3, required=False)
    return Subject(lengths, offsets, sigma, placement)


def subject_from_metadata(extra: dict) -> Subject | None:
    """The subject carried in a joints.npz's extra keys (``subject_lengths``, ``subject_offsets``,
    ``subject_placement``), or None when absent or malformed."""
    if "subject_lengths" not in extra:
        return None
    try:
        placement = str(np.asarray(extra.get("subject_placement", "skin")))
        offsets = extra.get("subject_offsets")
        sigma = extra.get("subject_offsets_sigma")
        return Subject(np.asarray(extra["subject_lengths"], float),
                       np.zeros((N_MARKERS, 3)) if offsets is None else np.asarray(offsets, float),
                       None if sigma is None else np.asarray(sigma, float), placement)
    except (ValueError, TypeError):
        return None
