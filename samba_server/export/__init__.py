"""Exports of a Samba take to the formats other tools read: BVH, C3D, TRC (OpenSim), CSV.

``export_take(take, fmt, out)`` picks the writer from :data:`WRITERS`; ``samba-export`` is the
command line (:mod:`samba_server.cli.export`). Axis and unit conventions are in each module
and in docs/exports.md.
"""

from __future__ import annotations

import os
from typing import Callable

from .bvh import write_bvh
from .c3d import write_c3d
from .csvfile import write_csv
from .take import ExportTake, TakeError, load_take
from .trc import write_trc

WRITERS: dict[str, Callable[[str | os.PathLike, ExportTake], object]] = {
    "bvh": write_bvh,
    "c3d": write_c3d,
    "trc": write_trc,
    "csv": write_csv,
}


def export_take(take: ExportTake, fmt: str, out: str | os.PathLike) -> object:
    """Write ``take`` as ``fmt`` (a key of WRITERS) to ``out``; returns the writer's report."""
    try:
        writer = WRITERS[fmt]
    except KeyError:
        raise ValueError(f"unknown format {fmt!r}; known: {sorted(WRITERS)}") from None
    return writer(out, take)


__all__ = ["ExportTake", "TakeError", "WRITERS", "export_take", "load_take"]
