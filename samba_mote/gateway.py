"""Serial-line mote -> Zenoh gateway (command line: ``samba-gateway``, :mod:`samba_mote.cli.gateway`).

Reads COBS/CRC frames from a serial port, validates each payload (marker packet or status
JSON), and publishes it on the mote's Zenoh keys with a liveliness token per mote id seen.
Corrupt frames and invalid payloads are dropped and counted; a vanished port is reopened
with backoff.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

from samba_common import zenoh_util as zk
from samba_common.framing import FrameReader
from samba_common.wire import MAGIC, PacketError, decode_packet, decode_status

log = logging.getLogger("samba_mote.gateway")


@dataclass
class GatewayStats:
    packets: int = 0
    status: int = 0
    bad_frames: int = 0
    bad_payloads: int = 0
    reopens: int = 0

    def summary(self) -> str:
        return (f"{self.packets} marker packets, {self.status} status messages forwarded; {self.bad_frames} corrupt "
                f"frames, {self.bad_payloads} invalid payloads dropped; {self.reopens} port reopens")


class Gateway:
    """Serial -> Zenoh bridge. ``session``: an open zenoh session; ``port_factory``: returns an
    open pyserial port (called again after a failure)."""

    def __init__(self, session, session_name: str, port_factory) -> None:
        self.session, self.session_name, self.port_factory = session, session_name, port_factory
        self.stats = GatewayStats()
        self._pubs: dict[str, tuple] = {}
        self._reader = FrameReader()

    def _publishers(self, mote_id: str):
        if mote_id not in self._pubs:
            s, n = self.session, self.session_name
            self._pubs[mote_id] = (s.declare_publisher(zk.markers_key(n, mote_id)),
                                   s.declare_publisher(zk.status_key(n, mote_id)),
                                   s.liveliness().declare_token(zk.liveliness_key(n, mote_id)))
            log.info("mote %s seen on the serial line", mote_id)
        return self._pubs[mote_id]

    def handle(self, payload: bytes) -> None:
        """Validate and publish one payload."""
        try:
            if payload[:4] == MAGIC:
                pkt = decode_packet(payload)
                self._publishers(pkt.mote_id)[0].put(payload)
                self.stats.packets += 1
            else:
                st = decode_status(payload)
                self._publishers(st.mote_id)[1].put(payload)
                self.stats.status += 1
        except (PacketError, ValueError) as exc:
            self.stats.bad_payloads += 1
            log.debug("dropped payload: %s", exc)

    def run(self, stop: threading.Event, max_backoff: float = 10.0) -> GatewayStats:
        port, backoff = None, 0.5
        while not stop.is_set():
            if port is None:
                try:
                    port = self.port_factory()
                    backoff = 0.5
                except Exception as exc:
                    log.warning("serial port unavailable (%s); retrying in %.1f s", exc, backoff)
                    stop.wait(backoff)
                    backoff = min(backoff * 2, max_backoff)
                    continue
            try:
                # everything waiting, or block (up to the port timeout) for one byte
                chunk = port.read(port.in_waiting or 1)
            except Exception as exc:
                log.warning("serial read failed (%s); reopening", exc)
                self.stats.reopens += 1
                try:
                    port.close()
                except Exception:
                    pass
                port = None
                continue
            errors_before = self._reader.errors
            for payload in self._reader.feed(chunk):
                self.handle(payload)
            self.stats.bad_frames += self._reader.errors - errors_before
        if port is not None:
            port.close()
        return self.stats

    def close(self) -> None:
        for _m, _s, token in self._pubs.values():
            try:
                token.undeclare()
            except Exception:
                pass
