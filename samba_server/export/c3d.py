"""C3D export through ezc3d: the 13 joints and, when the take has them, the 8 markers.

Coordinates stay in the Samba world frame (Z up, the usual C3D lab frame), in millimetres.
Point labels: the joint names, then ``<marker>_marker`` for the markers (marker and joint
names coincide, labels must be unique). Missing points are written the C3D way: coordinates
0 with residual -1 ("invalid"); ezc3d reads them back as NaN.

Time: ``POINT:RATE`` is the take's median frame rate and ``SAMBA:T0`` the time of the first
frame (seconds), so frame ``i`` (0-based) is at ``T0 + i / RATE``; ``SAMBA:T_ERROR`` is the
largest difference (seconds) between that and the take's own time stamps (0 for a regular
take, about a frame or more when the take has gaps). No parameter grows with the number of
frames (a C3D parameter dimension is one byte and a parameter at most 32 KiB), so a take of
any length reads back. ``SAMBA:SOURCE`` is the source file name. Takes of more than 65535
frames also get ``TRIAL:ACTUAL_START_FIELD`` / ``ACTUAL_END_FIELD`` (the header's frame
count is 16-bit). The subject the take was solved with (placement, bone lengths, marker
offsets) is in ``SAMBA:SUBJECT_PLACEMENT``, ``BONE_LENGTHS``, ``MARKER_OFFSETS`` and friends
(:func:`add_subject_parameters`). docs/exports.md lists every parameter.
"""

from __future__ import annotations

import logging
import os
import sys

import numpy as np

from samba_common.skeleton import BONE_TYPES, JOINT_NAMES, MARKER_NAMES
from samba_common.subject import Subject

from .take import ExportTake

log = logging.getLogger(__name__)

#: frames the C3D header can count; longer takes need the TRIAL:ACTUAL_*_FIELD parameters
HEADER_MAX_FRAMES = 65535


def point_labels(take: ExportTake) -> list[str]:
    """Labels in file order: joints, then markers (if any) suffixed ``_marker``."""
    labels = list(JOINT_NAMES)
    if take.markers is not None:
        labels += [f"{m}_marker" for m in MARKER_NAMES]
    return labels


def point_array(take: ExportTake) -> np.ndarray:
    """(F, P, 3) metres in label order."""
    parts = [take.joints] + ([take.markers] if take.markers is not None else [])
    return np.concatenate(parts, axis=1)


def time_parameters(t: np.ndarray, rate: float) -> tuple[float, float, float]:
    """(T0, RATE, T_ERROR) as stored (T0 and RATE rounded to float32 like in the file);
    T_ERROR = max |t[i] - (T0 + i / RATE)| seconds."""
    t = np.asarray(t, dtype=np.float64)
    t0 = float(np.float32(t[0]))
    rate32 = float(np.float32(rate))
    err = float(np.max(np.abs(t - (t0 + np.arange(len(t)) / rate32))))
    return t0, rate32, err


def frame_times(t0: float, rate: float, n_frames: int) -> np.ndarray:
    """(F,) seconds of the frames of a Samba C3D: ``T0 + i / RATE``."""
    return t0 + np.arange(n_frames) / rate


def _int_parameter(c, group: str, name: str, words: list[int], description: str) -> None:
    """Add an INT (16-bit) parameter; ezc3d's add_parameter would store integers as floats."""
    c.add_parameter(group, name, [0.0] * len(words), description)
    c["parameters"][group][name]["type"] = 2  # ezc3d.INT
    c["parameters"][group][name]["value"] = np.array([w - 65536 if w > 32767 else w for w in words])


def add_subject_parameters(c, subject: Subject) -> None:
    """The subject the take was solved with, as SAMBA parameters (docs/exports.md): placement,
    bone types and lengths (mm), marker names and offsets (3, 8) mm in each marker's segment
    frame (e1, e2, e3; samba_common.markerset), and their 1-sigma when known."""
    c.add_parameter("SAMBA", "SUBJECT_PLACEMENT", [subject.placement], "markers on skin landmarks or joint centres")
    c.add_parameter("SAMBA", "BONE_TYPES", list(BONE_TYPES), "bone types of BONE_LENGTHS")
    c.add_parameter("SAMBA", "BONE_LENGTHS", [float(v) for v in 1000.0 * subject.lengths], "subject bone lengths (mm)")
    c.add_parameter("SAMBA", "OFFSET_MARKERS", list(MARKER_NAMES), "markers of MARKER_OFFSETS")
    c.add_parameter("SAMBA", "MARKER_OFFSETS", 1000.0 * subject.offsets.T,
                    "marker - joint centre (mm) in the segment frame (e1, e2, e3), one column per marker")
    if subject.offsets_sigma is not None:
        c.add_parameter("SAMBA", "OFFSET_SIGMA", 1000.0 * subject.offsets_sigma.T, "1-sigma of MARKER_OFFSETS (mm)")


def write_c3d(path: str | os.PathLike, take: ExportTake) -> int:
    """Write a C3D file; returns the number of points per frame."""
    import ezc3d  # heavy native import: only when exporting C3D

    pts = point_array(take) * 1000.0  # (F, P, 3) mm
    F, P, _ = pts.shape
    t0, rate, t_error = time_parameters(take.t, take.rate())
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(point_labels(take))
    c["parameters"]["POINT"]["DESCRIPTIONS"]["value"] = tuple(
        ["samba joint"] * len(JOINT_NAMES) + ["samba marker"] * (P - len(JOINT_NAMES)))
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, P, F))
    data[:3] = np.transpose(pts, (2, 1, 0))
    missing = ~np.all(np.isfinite(pts), axis=-1).T  # (P, F)
    data[:3, missing] = np.nan  # ezc3d writes these as 0, 0, 0 with residual -1
    residuals = np.where(missing, -1.0, 0.0)[None]
    c["data"]["points"] = data
    c["data"]["meta_points"] = {"residuals": residuals, "camera_masks": np.zeros((7, P, F), dtype=bool)}
    c.add_parameter("SAMBA", "T0", [t0], "time of the first frame (s); frame i is at T0 + i / POINT:RATE")
    c.add_parameter("SAMBA", "T_ERROR", [t_error], "max |samba time stamp - (T0 + i / POINT:RATE)| (s)")
    c.add_parameter("SAMBA", "SOURCE", [os.path.basename(take.source) or "samba"], "source take file")
    if take.subject is not None:
        add_subject_parameters(c, take.subject)
    if F > HEADER_MAX_FRAMES:
        # Vicon's convention for long trials: two 16-bit words (low, high) of the frame number
        _int_parameter(c, "TRIAL", "ACTUAL_START_FIELD", [1, 0], "first frame")
        _int_parameter(c, "TRIAL", "ACTUAL_END_FIELD", [F & 0xFFFF, F >> 16], "last frame")
        log.warning("%s: %d frames; readers that only use the 16-bit header frame count "
                    "(ezc3d 1.7, Mokka) read the first %d", path, F, HEADER_MAX_FRAMES)
    if F > 1 and t_error > 0.5 / rate:
        log.warning("%s: time steps are irregular (a frame is %.1f ms off T0 + i/RATE); C3D assumes a "
                    "constant rate: use the CSV or TRC export for the exact time stamps", path, 1e3 * t_error)
    tmp = f"{os.fspath(path)}.part.c3d"
    c.write(tmp)
    os.replace(tmp, path)
    n_missing = int(missing.sum())
    log.info("%s: %d frames, %d points, %d missing samples", path, F, P, n_missing)
    print(f"wrote {os.fspath(path)}: {F} frames x {P} points at {rate:g} Hz"
          + (f", {n_missing} missing point samples" if n_missing else ""), file=sys.stderr)
    return P
