"""CSV export: one row per frame, ``t`` then ``<joint>_x, <joint>_y, <joint>_z`` for the 13
joints in FORMATS.md order; Samba world frame (Z up), metres; an unsolved joint is an empty
field (pandas and numpy read it as NaN)."""

from __future__ import annotations

import csv
import logging
import os

import numpy as np

from samba_common.skeleton import JOINT_NAMES

from .take import ExportTake

log = logging.getLogger(__name__)


def csv_header() -> list[str]:
    """Column names: t, head_x, head_y, head_z, left_shoulder_x, ..."""
    return ["t"] + [f"{j}_{a}" for j in JOINT_NAMES for a in "xyz"]


def write_csv(path: str | os.PathLike, take: ExportTake) -> int:
    """Write the joints as CSV; returns the number of rows written (frames)."""
    flat = take.joints.reshape(take.n_frames, -1)
    tmp = f"{os.fspath(path)}.part"
    with open(tmp, "w", encoding="ascii", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(csv_header())
        for t, row in zip(take.t, flat):
            w.writerow([f"{t:.6f}"] + ["" if not np.isfinite(v) else f"{v:.6f}" for v in row])
    os.replace(tmp, path)
    log.info("%s: %d rows", path, take.n_frames)
    return take.n_frames
