"""One warning line per mote that contributed nothing (samba_server/activity.py)."""

from __future__ import annotations

import numpy as np

from samba_common.wire import MarkerPacket
from samba_server.activity import MoteActivity


def _pkt(mote: str, labels: list[int]) -> MarkerPacket:
    n = len(labels)
    return MarkerPacket(mote_id=mote, seq=0, t_ns=0, width=160, height=120, threshold=100, labels=np.array(labels, np.uint8),
                        uv=np.zeros((n, 2), np.float32), flags=np.zeros(n, np.uint8))


def test_warns_about_silent_and_blind_motes_and_notes_unlabelling_ones() -> None:
    act = MoteActivity(["cam0", "cam1", "cam2", "cam3"])
    for _ in range(5):
        act(_pkt("cam0", [0, 1, 255]))
        act(_pkt("cam1", []))
        act(_pkt("cam2", [255, 255]))
    lines = act.warnings()
    assert len(lines) == 2
    assert any("cam3" in x and "no packets" in x for x in lines)
    assert any("cam1" in x and "no blob" in x for x in lines)
    # a mote whose 2D template never matched (feet at hip width): a note, not a warning
    notes = act.notes()
    assert len(notes) == 1 and "cam2" in notes[0] and "none labelled" in notes[0]
