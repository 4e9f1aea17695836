"""C3D export through ezc3d: the 13 joints and, when the take has them, the 8 markers.

Coordinates stay in the Samba world frame (Z up, the usual C3D lab frame), in millimetres.
Point labels: the joint names, then ``<marker>_marker`` for the markers (marker and joint
names coincide, labels must be unique). Missing points are NaN with residual -1 (the C3D
convention for "invalid"). POINT:RATE is the take's median frame rate; the Samba time stamps
of each frame are kept in the SAMBA:TIME parameter (seconds).
"""

from __future__ import annotations

import logging
import os

import numpy as np

from samba_common.skeleton import JOINT_NAMES, MARKER_NAMES

from .take import ExportTake

log = logging.getLogger(__name__)


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


def write_c3d(path: str | os.PathLike, take: ExportTake) -> int:
    """Write a C3D file; returns the number of points per frame."""
    import ezc3d  # heavy native import: only when exporting C3D

    pts = point_array(take) * 1000.0  # (F, P, 3) mm
    F, P, _ = pts.shape
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [take.rate()]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(point_labels(take))
    c["parameters"]["POINT"]["DESCRIPTIONS"]["value"] = tuple(
        ["samba joint"] * len(JOINT_NAMES) + ["samba marker"] * (P - len(JOINT_NAMES)))
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    data = np.ones((4, P, F))
    data[:3] = np.transpose(pts, (2, 1, 0))
    missing = ~np.all(np.isfinite(pts), axis=-1).T  # (P, F)
    data[:3, missing] = np.nan
    residuals = np.where(missing, -1.0, 0.0)[None]
    c["data"]["points"] = data
    c["data"]["meta_points"] = {"residuals": residuals, "camera_masks": np.zeros((7, P, F), dtype=bool)}
    c.add_parameter("SAMBA", "TIME", [float(v) for v in take.t])
    c.add_parameter("SAMBA", "SOURCE", [os.path.basename(take.source) or "samba"])
    tmp = f"{os.fspath(path)}.part.c3d"
    c.write(tmp)
    os.replace(tmp, path)
    log.info("%s: %d frames, %d points, %d missing samples", path, F, P, int(missing.sum()))
    return P
