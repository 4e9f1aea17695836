"""Exports of a Samba take to the formats other tools read: BVH, C3D, TRC (OpenSim), CSV.

``export_take(take, fmt, out)`` picks the writer from :data:`WRITERS`; ``samba-export`` is the
command line (:mod:`samba_server.cli.export`). Axis and unit conventions are in each module
and in docs/exports.md.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Callable

from .bvh import write_bvh
from .c3d import write_c3d
from .csvfile import write_csv
from .take import ExportTake, TakeError, load_take
from .trc import write_trc

log = logging.getLogger(__name__)

WRITERS: dict[str, Callable[[str | os.PathLike, ExportTake], object]] = {
    "bvh": write_bvh,
    "c3d": write_c3d,
    "trc": write_trc,
    "csv": write_csv,
}


def subject_sidecar(out: str | os.PathLike) -> Path:
    """Where the subject of a BVH/TRC/CSV export goes: ``take.bvh`` -> ``take.subject.toml``."""
    return Path(out).with_suffix(".subject.toml")


def export_take(take: ExportTake, fmt: str, out: str | os.PathLike) -> object:
    """Write ``take`` as ``fmt`` (a key of WRITERS) to ``out``; returns the writer's report.

    The subject the take was solved with (if known) goes into the C3D file itself (SAMBA
    parameters); BVH, TRC and CSV have no place for it that their readers accept, so it is
    written next to them as ``subject.toml`` (:func:`subject_sidecar`)."""
    try:
        writer = WRITERS[fmt]
    except KeyError:
        raise ValueError(f"unknown format {fmt!r}; known: {sorted(WRITERS)}") from None
    report = writer(out, take)
    if take.subject is not None and fmt != "c3d":
        side = subject_sidecar(out)
        take.subject.save(side)
        log.info("%s: subject (%s) written to %s", out, take.subject.placement, side)
    return report


__all__ = ["ExportTake", "TakeError", "WRITERS", "export_take", "load_take", "subject_sidecar"]
