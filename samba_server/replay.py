"""Replay a recorded take: in-process through the server pipeline (exact), or republished on
Zenoh with the original timing (or as fast as possible) for a running ``samba-server``.

In-process replay feeds :meth:`Server.ingest` with the recorded arrival stamps and the
recorded mote joins/leaves, in file order, which is the order the live server processed
them; the server's decisions depend only on those, so the poses equal the live ones.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from pathlib import Path

from samba_common import zenoh_util as zk

from .record import CALIBRATION_TOPIC, EVENTS_TOPIC, TakeReader
from .server import Server

log = logging.getLogger(__name__)


def take_calibration(path: str | Path) -> bytes | None:
    """The calibration.toml bytes recorded in a take (first one), or None."""
    for m in TakeReader(path, topics=[CALIBRATION_TOPIC]):
        return m.data
    return None


def replay_into(server: Server, path: str | Path, progress: Callable[[int], None] | None = None) -> TakeReader:
    """Feed every recorded packet and event of ``path`` into ``server`` and flush it.

    Returns the reader (``.truncated`` tells whether the take ended early).
    """
    reader = TakeReader(path)
    for m in reader:
        mote = m.mote_id
        if mote is not None:
            server.ingest(mote, m.data, arrival_ns=m.log_time)
        elif m.topic == EVENTS_TOPIC:
            try:
                ev = json.loads(m.data)
                server.mote_event(str(ev["mote_id"]), ev["event"] == "join", int(ev["t_ns"]))
            except (ValueError, KeyError, TypeError):
                log.warning("bad event record skipped: %r", m.data[:80])
        else:
            continue
        server.process_pending()
        if progress is not None:
            progress(1)
    server.finish()
    return reader


class Player:
    """Republish a take's mote packets on Zenoh, one liveliness token per recorded mote.

    speed: 1.0 = original timing, 2.0 = twice as fast, None/0 = as fast as possible.
    """

    def __init__(self, path: str | Path, session: str = zk.DEFAULT_SESSION, connect=(), listen=(),
                 speed: float | None = 1.0):
        self.path = Path(path)
        self.session_name = session
        self.cfg = zk.make_config(connect=connect, listen=listen)
        self.speed = speed
        self.sent = 0

    def play(self, stop=None, wait_match: float = 5.0) -> int:
        """Publish every packet; returns the number sent. ``stop``: optional threading.Event."""
        import zenoh

        with zenoh.open(self.cfg) as z:
            pubs: dict[str, object] = {}
            tokens: list = []
            t_first = None
            wall0 = time.monotonic()
            for m in TakeReader(self.path):
                if stop is not None and stop.is_set():
                    break
                mote = m.mote_id
                if mote is None:
                    continue
                pub = pubs.get(mote)
                if pub is None:
                    tokens.append(z.liveliness().declare_token(zk.liveliness_key(self.session_name, mote)))
                    pub = pubs[mote] = z.declare_publisher(zk.markers_key(self.session_name, mote))
                    deadline = time.monotonic() + wait_match
                    while not pub.matching_status.matching and time.monotonic() < deadline:
                        time.sleep(0.01)
                    if t_first is not None:  # do not count the wait in the timing
                        wall0 = time.monotonic() - (m.log_time - t_first) / 1e9 / (self.speed or 1.0)
                if t_first is None:
                    t_first, wall0 = m.log_time, time.monotonic()
                if self.speed:
                    due = wall0 + (m.log_time - t_first) / 1e9 / self.speed
                    delay = due - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                pub.put(m.data)
                self.sent += 1
            time.sleep(0.1)
            for tok in tokens:
                tok.undeclare()
        return self.sent
