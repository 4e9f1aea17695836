"""CSV export: one row per frame, ``t`` then ``<joint>_x, <joint>_y, <joint>_z`` for the 13
joints in FORMATS.md order; Samba world frame (Z up), metres; an unsolved joint is an empty
field (pandas and numpy read it as NaN)."""

from __future__ import annotations

import csv
import logging
import os
import sys

import numpy as np

from samba_common.skeleton import JOINT_NAMES

from .take import ExportTake

log = logging.getLogger(__name__)


def csv_header() -> list[str]:
    """Column names: t, head_x, head_y, head_z, left_shoulder_x, ..."""
    return ["t"] + [f"{j}_{a}" for j in JOINT_NAMES for a in "xyz"]


def write_joints_csv(path: str | os.PathLike, joints: np.ndarray, t: np.ndarray) -> int:
    """Write joints (F, 13, 3) metres at times t (F,) s as CSV (atomically); returns the rows written."""
    flat = np.asarray(joints).reshape(len(t), 3 * len(JOINT_NAMES))
    tmp = f"{os.fspath(path)}.part"
    with open(tmp, "w", encoding="ascii", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(csv_header())
        for ti, row in zip(t, flat):
            w.writerow([f"{ti:.6f}"] + ["" if not np.isfinite(v) else f"{v:.6f}" for v in row])
    os.replace(tmp, path)
    log.info("%s: %d rows", path, len(t))
    return len(t)


def write_csv(path: str | os.PathLike, take: ExportTake) -> int:
    """Write a take's joints as CSV; returns the number of rows written (frames)."""
    n = write_joints_csv(path, take.joints, take.t)
    print(f"wrote {os.fspath(path)}: {n} frames", file=sys.stderr)
    return n
