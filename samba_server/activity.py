"""Per-mote activity over a take, to warn about motes that silently contributed nothing.

A :class:`MoteActivity` sees every decoded :class:`~samba_common.wire.MarkerPacket` (as a
``Server.packet_listeners`` entry, or called directly by ``samba-process``) and, at the end
of a take, :meth:`MoteActivity.warnings` gives one line per problem: a camera of the
calibration that sent nothing, a mote that saw no blob in any frame. A mote that saw blobs
but never labelled a marker is a note (:meth:`MoteActivity.notes`), not a problem: its blobs
are still used, the server names them in 3D, and its 2D standard-pose template (feet apart)
does not match a subject standing with the feet at hip width, as most do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class MoteCounts:
    """Packets of one mote: total, with at least one blob, with at least one labelled marker."""

    packets: int = 0
    with_blobs: int = 0
    with_labels: int = 0


class MoteActivity:
    """Counts per mote (callable with a MarkerPacket). ``cameras``: the calibration's names."""

    def __init__(self, cameras: list[str] | tuple[str, ...] = (), n_markers: int = 8) -> None:
        self.cameras = list(cameras)
        self.n_markers = n_markers
        self.motes: dict[str, MoteCounts] = {}

    def __call__(self, pkt) -> None:
        c = self.motes.setdefault(pkt.mote_id, MoteCounts())
        c.packets += 1
        labels = np.asarray(pkt.labels)
        if len(labels):
            c.with_blobs += 1
            if (labels < self.n_markers).any():
                c.with_labels += 1

    def warnings(self) -> list[str]:
        """One line per camera of the calibration that sent nothing and per mote that saw no blob."""
        out = []
        for cam in self.cameras:
            if cam not in self.motes:
                out.append(f"camera {cam} of the calibration sent no packets in the whole take")
        for mote, c in sorted(self.motes.items()):
            if c.with_blobs == 0:
                out.append(f"mote {mote}: no blob in any of its {c.packets} frames (lens covered, exposure or "
                           "threshold? check with samba-mote --preview DIR)")
        return out

    def notes(self) -> list[str]:
        """One line per mote that saw blobs but never labelled a marker (its 2D standard-pose
        template never matched): the server named its blobs in 3D all the same."""
        return [f"mote {mote}: blobs in {c.with_blobs} of {c.packets} frames, none labelled by the mote (its 2D "
                "standard-pose template did not match); the server named its blobs in 3D"
                for mote, c in sorted(self.motes.items()) if c.with_blobs and c.with_labels == 0]
