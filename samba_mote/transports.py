"""Where a mote's packets go: Zenoh, a serial line, an in-process bus; plus an MCAP copy.

Every transport has ``send_markers(payload)``, ``send_status(payload)`` and ``close()`` and
works as a context manager. :class:`Resilient` wraps one: a failing send is counted, the
transport is closed and reopened with exponential backoff (messages in between are dropped
and counted), and nothing ever raises into the capture loop.

Specs for :func:`open_transport`:

* ``zenoh`` (endpoints, mode and scouting from the arguments),
* ``serial:/dev/ttyUSB0?baud=921600`` or ``serial:loop://`` (pyserial URL),
* ``inproc`` with an :class:`InprocBus` object passed in (tests, offline runs).
"""

from __future__ import annotations

import logging
import threading
import time
import urllib.parse
from collections.abc import Callable
from pathlib import Path
from typing import Any, Protocol

from samba_common import zenoh_util as zk
from samba_common.framing import frame

log = logging.getLogger(__name__)


class TransportError(OSError):
    """A transport cannot be opened or a message cannot be sent."""


class Transport(Protocol):
    def send_markers(self, payload: bytes) -> None: ...

    def send_status(self, payload: bytes) -> None: ...

    def close(self) -> None: ...


class _Ctx:
    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()  # type: ignore[attr-defined]


class ZenohTransport(_Ctx):
    """Publishes on ``samba/{session}/mote/{id}/markers`` and ``.../status`` and holds the
    liveliness token ``samba/{session}/mote/{id}`` while open."""

    def __init__(self, mote_id: str, session_name: str = zk.DEFAULT_SESSION, mode: str = "peer",
                 listen: tuple[str, ...] = (), connect: tuple[str, ...] = (), scouting: bool = False,
                 tls: str | None = None) -> None:
        """tls: keys folder (``samba-keys``) for mutual TLS as this mote; endpoints must be ``tls/...``.
        Without endpoints or scouting it connects to a server on this machine (``tcp/127.0.0.1:7447``,
        ``tls/...`` with tls), the server's default."""
        import zenoh

        self.mote_id, self.session_name = mote_id, session_name
        if not listen and not connect and not scouting:
            connect = (("tls" if tls else "tcp") + "/127.0.0.1:7447",)
        extra = None
        if tls:
            from samba_common import keys

            keys.check_endpoints(list(listen) + list(connect), "endpoint")
            try:
                extra = keys.mote_settings(tls, mote_id)
            except keys.KeysError as exc:
                raise TransportError(str(exc)) from None
        try:
            self.session = zenoh.open(zk.make_config(mode, listen, connect, scouting, extra=extra))
        except Exception as exc:  # zenoh.ZError and friends
            raise TransportError(f"cannot open zenoh session ({exc})") from None
        self._markers = self.session.declare_publisher(zk.markers_key(session_name, mote_id))
        self._status = self.session.declare_publisher(zk.status_key(session_name, mote_id))
        self._token = self.session.liveliness().declare_token(zk.liveliness_key(session_name, mote_id))

    @property
    def matched(self) -> bool:
        """True when a subscriber for the marker packets is connected."""
        return bool(self._markers.matching_status.matching)

    def wait_matched(self, timeout: float) -> bool:
        """Wait (sleeping) up to ``timeout`` s for a marker subscriber; returns whether one came."""
        deadline = time.monotonic() + timeout
        while not self.matched and time.monotonic() < deadline:
            time.sleep(0.02)
        return self.matched

    def send_markers(self, payload: bytes) -> None:
        self._markers.put(payload)

    def send_status(self, payload: bytes) -> None:
        self._status.put(payload)

    def fetch_calibration(self, timeout: float = 2.0) -> bytes | None:
        """calibration.toml bytes from the server's queryable, or None (no reply in time)."""
        payload, reason = zk.first_reply(self.session, zk.calibration_key(self.session_name), timeout)
        if payload is None and reason is not None:
            log.warning("calibration query failed: %s", reason)
        return payload

    def close(self) -> None:
        try:
            self._token.undeclare()
        except Exception:  # already closed
            pass
        self.session.close()


class SerialTransport(_Ctx):
    """COBS + CRC32 frames (samba_common.framing) on a pyserial port. Marker packets and status
    JSON share the line; a reader tells them apart by the first byte (``S`` or ``{``)."""

    def __init__(self, url: str, baud: int = 921600, write_timeout: float = 0.5) -> None:
        import serial

        try:
            self.port = serial.serial_for_url(url, baudrate=baud, timeout=0.1, write_timeout=write_timeout)
        except (serial.SerialException, ValueError) as exc:
            raise TransportError(f"cannot open serial port {url}: {exc}") from None
        self.url = url

    def _write(self, payload: bytes) -> None:
        import serial

        try:
            self.port.write(frame(payload))
        except (serial.SerialException, OSError) as exc:
            raise TransportError(f"serial write failed on {self.url}: {type(exc).__name__} {exc}") from None

    send_markers = _write
    send_status = _write

    def close(self) -> None:
        self.port.close()


class InprocBus:
    """An in-process message bus (tests, offline runs): subscribers get ``(kind, payload)``."""

    def __init__(self) -> None:
        self._subs: list[Callable[[str, bytes], None]] = []
        self._lock = threading.Lock()

    def subscribe(self, callback: Callable[[str, bytes], None]) -> None:
        with self._lock:
            self._subs.append(callback)

    def publish(self, kind: str, payload: bytes) -> None:
        with self._lock:
            subs = list(self._subs)
        for cb in subs:
            cb(kind, payload)


class InprocTransport(_Ctx):
    def __init__(self, bus: InprocBus) -> None:
        self.bus = bus

    def send_markers(self, payload: bytes) -> None:
        self.bus.publish("markers", payload)

    def send_status(self, payload: bytes) -> None:
        self.bus.publish("status", payload)

    def close(self) -> None:
        pass


class McapRecorder(_Ctx):
    """Local MCAP copy of everything a mote publishes (server take layout: topic
    ``/mote/{id}/markers`` encoding ``samba-marker-v1``; ``/mote/{id}/status`` encoding ``json``)."""

    def __init__(self, path: str | Path, mote_id: str) -> None:
        from mcap.writer import Writer

        self.path = Path(path)
        self._fh = self.path.open("wb")
        self._writer = Writer(self._fh)
        self._writer.start(profile="samba", library="samba-mote")
        meta = {"mote_id": mote_id}
        self._ch = {
            "markers": self._writer.register_channel(f"/mote/{mote_id}/markers", "samba-marker-v1", 0, meta),
            "status": self._writer.register_channel(f"/mote/{mote_id}/status", "json", 0, meta),
        }
        self._seq = 0
        self.count = 0

    def record(self, kind: str, payload: bytes, t_ns: int | None = None) -> None:
        now = time.time_ns()
        self._writer.add_message(self._ch[kind], log_time=now, data=payload, publish_time=t_ns or now,
                                 sequence=self._seq & 0xFFFFFFFF)
        self._seq += 1
        self.count += 1

    def close(self) -> None:
        if self._fh.closed:
            return
        self._writer.finish()
        self._fh.close()


class Resilient(_Ctx):
    """Wraps a transport factory: sends never raise; failures are counted and the transport is
    reopened with exponential backoff (``backoff`` s doubling up to ``max_backoff``)."""

    def __init__(self, factory: Callable[[], Any], backoff: float = 0.5, max_backoff: float = 10.0,
                 what: str = "transport") -> None:
        self.factory, self.what = factory, what
        self.backoff0, self.max_backoff = backoff, max_backoff
        self.backoff = backoff
        self.inner: Any = None
        self.errors = 0
        self.dropped = 0
        self.sent = 0
        self._retry_at = 0.0
        self._connect()

    def _connect(self) -> bool:
        try:
            self.inner = self.factory()
            self.backoff = self.backoff0
            return True
        except Exception as exc:
            self.errors += 1
            self.inner = None
            self._retry_at = time.monotonic() + self.backoff
            log.warning("%s unavailable (%s); retrying in %.1f s", self.what, exc, self.backoff)
            self.backoff = min(self.backoff * 2, self.max_backoff)
            return False

    def _send(self, kind: str, payload: bytes) -> bool:
        if self.inner is None:
            if time.monotonic() < self._retry_at or not self._connect():
                self.dropped += 1
                return False
        try:
            getattr(self.inner, f"send_{kind}")(payload)
            self.sent += 1
            return True
        except Exception as exc:
            self.errors += 1
            self.dropped += 1
            log.warning("%s send failed (%s: %s); reopening", self.what, type(exc).__name__, exc)
            try:
                self.inner.close()
            except Exception:
                pass
            self.inner = None
            self._retry_at = time.monotonic() + self.backoff
            return False

    def send_markers(self, payload: bytes) -> bool:
        return self._send("markers", payload)

    def send_status(self, payload: bytes) -> bool:
        return self._send("status", payload)

    def close(self) -> None:
        if self.inner is not None:
            try:
                self.inner.close()
            finally:
                self.inner = None


def parse_serial_url(spec: str) -> tuple[str, int]:
    """``serial:/dev/ttyUSB0?baud=921600`` or ``serial:loop://`` -> (pyserial URL, baud)."""
    if not spec.startswith("serial:"):
        raise ValueError(f"not a serial spec: {spec!r}")
    rest = spec[len("serial:"):]
    if "?" in rest and not rest.startswith(("loop://", "socket://", "rfc2217://")):
        path, _, q = rest.partition("?")
    elif rest.startswith(("loop://", "socket://", "rfc2217://")) and "?baud=" in rest:
        path, _, q = rest.partition("?")
    else:
        path, q = rest, ""
    baud = int(urllib.parse.parse_qs(q).get("baud", ["921600"])[-1])
    if not path:
        raise ValueError("serial transport needs a device, e.g. serial:/dev/ttyUSB0?baud=921600")
    return path, baud
