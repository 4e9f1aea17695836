"""TRC export for OpenSim: tab-separated, millimetres, OpenSim's axes.

OpenSim's ground frame is Y up, X forward, Z to the subject's right. The Samba subject faces +Y
(Z up, right hand toward +X), so::

    opensim = 1000 * (y, z, x)        (a proper rotation, no mirroring)

Layout (what OpenSim's TRCFileAdapter reads): line 1 ``PathFileType 4 (X/Y/Z) <file>``;
line 2 the header names; line 3 their values (rates, frame and marker counts, Units ``mm``);
line 4 ``Frame# Time`` then each marker name followed by two empty tabs; line 5 ``X1 Y1 Z1 ...``;
an empty line; then one row per frame. A missing coordinate is an empty field.
"""

from __future__ import annotations

import logging
import os
import sys

import numpy as np

from .c3d import point_array, point_labels
from .take import ExportTake

log = logging.getLogger(__name__)

#: Samba world metres -> OpenSim millimetres, row-vector convention: p_osim = p @ TO_OPENSIM.T
TO_OPENSIM = 1000.0 * np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def _fmt(v: float) -> str:
    return "" if not np.isfinite(v) else f"{v:.4f}"


def write_trc(path: str | os.PathLike, take: ExportTake) -> int:
    """Write a TRC file of the joints (and markers, suffixed ``_marker``); returns the point count."""
    labels = point_labels(take)
    pts = point_array(take) @ TO_OPENSIM.T  # (F, P, 3) mm
    F, P, _ = pts.shape
    rate = take.rate()
    name = os.path.basename(os.fspath(path))
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.6g}\t{rate:.6g}\t{F}\t{P}\tmm\t{rate:.6g}\t1\t{F}",
        "Frame#\tTime\t" + "\t".join(f"{lab}\t\t" for lab in labels).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, P + 1)),
        "",
    ]
    flat = pts.reshape(F, -1)
    for f in range(F):
        lines.append(f"{f + 1}\t{take.t[f]:.6f}\t" + "\t".join(_fmt(v) for v in flat[f]))
    tmp = f"{os.fspath(path)}.part"
    with open(tmp, "w", encoding="ascii", newline="\n") as fh:
        fh.write("\n".join(lines) + "\n")
    os.replace(tmp, path)
    log.info("%s: %d frames, %d points", path, F, P)
    print(f"wrote {os.fspath(path)}: {F} frames x {P} points", file=sys.stderr)
    return P
