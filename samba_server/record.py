"""MCAP take recorder and a reader that tolerates a truncated tail.

Layout of a Samba take (``*.mcap``, profile ``samba``):

================================  ======================  ===================================
topic                             message encoding        payload
================================  ======================  ===================================
``/mote/{id}/markers``            ``samba-marker-v1``     raw marker packet bytes as received
                                                          (``samba_common.wire``), one channel
                                                          per mote, ``metadata["mote_id"]``
``/calibration``                  ``toml``                calibration.toml bytes
``/pose``                         ``samba-pose-v1``       binary pose (``samba_common.pose_wire``)
``/events``                       ``json``                mote joins/leaves (liveliness)
================================  ======================  ===================================

``log_time`` is the server's arrival time (ns since the Unix epoch) and ``publish_time`` the
capture time when known. Messages appear in the file in arrival order, which is the order the
server processed them: replay feeds them back in the same order.

Crash safety: the file is written *unchunked* and every record goes to the operating system
with one ``os.write`` as soon as it is added, so a killed process (even ``kill -9``) leaves
every message it had recorded on disk; only the closing summary is missing, and
:func:`iter_messages` reads such a file up to its last complete record. A failing write
(full disk, I/O error) is rolled back to the last complete record, logged once, and counted
in :attr:`Recorder.dropped`; recording resumes by itself when writes succeed again.
"""

from __future__ import annotations

import errno
import logging
import os
import struct
import threading
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

log = logging.getLogger(__name__)

PROFILE = "samba"
MARKERS_ENCODING = "samba-marker-v1"
POSE_ENCODING = "samba-pose-v1"
CALIBRATION_TOPIC = "/calibration"
POSE_TOPIC = "/pose"
EVENTS_TOPIC = "/events"


def markers_topic(mote_id: str) -> str:
    """MCAP topic of one mote's raw marker packets."""
    return f"/mote/{mote_id}/markers"


class RecorderError(OSError):
    """The take file cannot be created."""


class _SafeSink:
    """Write-through file sink for the MCAP writer.

    Each ``write`` goes straight to the kernel. On failure the file is truncated back to
    the last complete write and the error is re-raised, so the file never holds a partial
    record.
    """

    def __init__(self, fd: int):
        self.fd = fd
        self.pos = 0

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        start = self.pos
        try:
            while view:
                n = os.write(self.fd, view)
                view = view[n:]
                self.pos += n
        except OSError:
            try:
                os.ftruncate(self.fd, start)
                os.lseek(self.fd, start, os.SEEK_SET)
            except OSError:  # pragma: no cover - nothing more we can do
                pass
            self.pos = start
            raise
        return len(data)

    def tell(self) -> int:
        return self.pos

    def flush(self) -> None:
        pass


@dataclass
class RecorderStats:
    """Counters of a recorder: messages written and dropped (write failures), bytes."""

    written: int = 0
    dropped: int = 0
    bytes: int = 0
    last_error: str = ""


class Recorder:
    """Record raw mote packets, the calibration, poses and events into one MCAP file.

    Thread-safe: the ingest thread records packets while the processing loop records poses.
    """

    def __init__(self, path: str | os.PathLike, calibration_toml: bytes | None = None,
                 metadata: dict[str, str] | None = None, _sink: _SafeSink | None = None):
        self.path = Path(path)
        self.stats = RecorderStats()
        self._lock = threading.Lock()
        self._channels: dict[str, int] = {}
        self._closed = False
        try:
            fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as exc:
            raise RecorderError(exc.errno, f"cannot create take file {self.path}: {exc.strerror}") from None
        self._fd = fd
        self._sink = _sink or _SafeSink(fd)
        self._writer = Writer(self._sink, use_chunking=False, enable_crcs=True)  # type: ignore[arg-type]
        try:
            self._writer.start(profile=PROFILE, library="samba")
            if metadata:
                self._writer.add_metadata("samba", {str(k): str(v) for k, v in metadata.items()})
        except OSError as exc:
            os.close(fd)
            raise RecorderError(exc.errno, f"cannot write take file {self.path}: {exc.strerror}") from None
        if calibration_toml is not None:
            self.write_calibration(calibration_toml)

    # ------------------------------------------------------------------ writing
    def _channel(self, topic: str, encoding: str, metadata: dict[str, str]) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            ch = self._writer.register_channel(topic=topic, message_encoding=encoding, schema_id=0,
                                               metadata=metadata)
            self._channels[topic] = ch
        return ch

    def _add(self, topic: str, encoding: str, metadata: dict[str, str], data: bytes, log_time: int,
             publish_time: int, sequence: int) -> bool:
        with self._lock:
            if self._closed:
                self.stats.dropped += 1
                return False
            new_channel = topic not in self._channels
            try:
                ch = self._channel(topic, encoding, metadata)
                self._writer.add_message(channel_id=ch, log_time=int(log_time), data=bytes(data),
                                         publish_time=int(publish_time), sequence=int(sequence) & 0xFFFFFFFF)
            except OSError as exc:
                if new_channel:  # its Channel record went down with the failed write
                    self._channels.pop(topic, None)
                self.stats.dropped += 1
                msg = f"{exc.strerror or exc}"
                if exc.errno == errno.ENOSPC:
                    msg = "disk full"
                if msg != self.stats.last_error:
                    log.error("recording to %s failed (%s): message dropped, will retry on the next one",
                              self.path, msg)
                self.stats.last_error = msg
                return False
            self.stats.written += 1
            self.stats.bytes = self._sink.tell()
            if self.stats.last_error:
                log.warning("recording to %s resumed after %d dropped message(s)", self.path,
                            self.stats.dropped)
                self.stats.last_error = ""
            return True

    def write_packet(self, mote_id: str, payload: bytes, arrival_ns: int, capture_ns: int = 0,
                     seq: int = 0) -> bool:
        """Record one raw marker packet of ``mote_id``; False (and a counted drop) on failure."""
        return self._add(markers_topic(mote_id), MARKERS_ENCODING, {"mote_id": mote_id}, payload,
                         arrival_ns, capture_ns or arrival_ns, seq)

    def write_calibration(self, toml_bytes: bytes, t_ns: int = 0) -> bool:
        """Record the calibration.toml in use."""
        return self._add(CALIBRATION_TOPIC, "toml", {}, toml_bytes, t_ns, t_ns, 0)

    def write_pose(self, payload: bytes, publish_ns: int, frame_ns: int, seq: int = 0) -> bool:
        """Record one binary pose message."""
        return self._add(POSE_TOPIC, POSE_ENCODING, {}, payload, publish_ns, frame_ns, seq)

    def write_event(self, payload: bytes, t_ns: int) -> bool:
        """Record one JSON event (mote join/leave)."""
        return self._add(EVENTS_TOPIC, "json", {}, payload, t_ns, t_ns, 0)

    def close(self) -> None:
        """Write the MCAP summary and close the file (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            try:
                self._writer.finish()
            except OSError as exc:
                log.error("could not finish %s (%s): the file stays readable without its summary",
                          self.path, exc.strerror or exc)
            finally:
                os.close(self._fd)

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ---------------------------------------------------------------------- reading


@dataclass
class RecordedMessage:
    """One message of a take: ``topic``, ``log_time``/``publish_time`` ns, ``data`` bytes."""

    topic: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def mote_id(self) -> str | None:
        """The mote of a ``/mote/{id}/markers`` message, else None."""
        if self.topic.startswith("/mote/") and self.topic.endswith("/markers"):
            return self.metadata.get("mote_id") or self.topic.split("/")[2]
        return None


class TakeReader:
    """Iterate over the messages of a take in file order, stopping quietly at a truncated tail.

    After iteration, ``truncated`` tells whether the file ended early (no footer, partial
    record) and ``error`` holds the reason. Raises ``FileNotFoundError``/``ValueError`` only
    when the file is missing or is not an MCAP file at all.
    """

    def __init__(self, path: str | os.PathLike, topics: Iterable[str] | None = None):
        self.path = Path(path)
        self.topics = set(topics) if topics is not None else None
        self.truncated = False
        self.error = ""
        self.channels: dict[int, Channel] = {}

    def __iter__(self) -> Iterator[RecordedMessage]:
        with self.path.open("rb") as fh:
            head = fh.read(8)
            if head[:5] != b"\x89MCAP":
                raise ValueError(f"{self.path}: not an MCAP file")
            fh.seek(0)
            records = StreamReader(fh, validate_crcs=False, record_size_limit=64 * 2**20).records
            seen_footer = False
            while True:
                try:
                    rec = next(records)
                except StopIteration:
                    break
                except (McapError, ValueError, EOFError, struct.error, OSError, IndexError, KeyError, UnicodeDecodeError,
                        MemoryError) as exc:
                    self.truncated = True
                    self.error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
                    log.info("%s: stopped at a truncated or damaged tail (%s)", self.path, self.error)
                    break
                if isinstance(rec, Channel):
                    self.channels[rec.id] = rec
                elif isinstance(rec, Message):
                    ch = self.channels.get(rec.channel_id)
                    if ch is None or (self.topics is not None and ch.topic not in self.topics):
                        continue
                    yield RecordedMessage(ch.topic, rec.log_time, rec.publish_time, rec.sequence,
                                          bytes(rec.data), dict(ch.metadata))
                elif isinstance(rec, Footer):
                    seen_footer = True
                elif isinstance(rec, Schema):
                    pass
            if not seen_footer and not self.truncated:
                self.truncated = True
                self.error = "no footer (recording was not closed)"


def iter_messages(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[RecordedMessage]:
    """Messages of the take at ``path`` in file order (see :class:`TakeReader`)."""
    return iter(TakeReader(path, topics))
