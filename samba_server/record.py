"""MCAP take recorder and a reader that tolerates a truncated tail.

Layout of a Samba take (``*.mcap``, profile ``samba``): chunked (uncompressed chunks), with
message indexes, a summary (schemas, channels, statistics, chunk indexes) and summary offsets,
so indexed readers (``mcap`` Python ``make_reader``, ``@mcap/core`` ``McapIndexedReader``,
Foxglove) open a closed take directly. Every channel has a schema record:

- ``/mote/{id}/markers``: message encoding ``samba-marker-v1``, schema ``samba.MarkerPacket``
  (``text/plain``): raw marker packet bytes as received (``samba_common.wire``)
- ``/calibration``: ``toml``, schema ``samba.CalibrationToml`` (``text/plain``): calibration.toml
- ``/pose``: ``samba-pose-v1``, schema ``samba.Pose`` (``text/plain``): binary pose
  (``samba_common.pose_wire``)
- ``/events``: ``json``, schema ``samba.Event`` (``jsonschema``): mote joins/leaves

The ``text/plain`` schemas of the binary channels hold the byte layout (the wire modules'
documentation) for a third party to write a decoder; ``/events`` is decoded by any JSON-aware
tool. One channel per mote, ``metadata["mote_id"]``. ``log_time`` is the server's arrival time
(ns since the Unix epoch) and ``publish_time`` the capture time when known. Messages appear in
the file in arrival order, which is the order the server processed them: replay feeds them
back in the same order.

Crash safety: a chunk is closed and written at least every :data:`FLUSH_INTERVAL_S` (0.5 s,
a timer thread covers pauses in the message flow), each chunk with its message indexes in one
``os.write``, so a killed process (even ``kill -9``) leaves on disk every message recorded more
than about 0.6 s before it died; only the summary is missing, and :func:`iter_messages` reads
such a file by a linear scan up to its last complete chunk. A failing write (full disk, I/O
error) is rolled back to the last complete chunk and logged; the unwritten bytes are kept in
memory (up to ``max_pending_bytes``) and written as soon as the disk accepts them, messages
arriving while that backlog is full are dropped and counted in ``stats.dropped``. When the
disk takes writes again after such a gap, the backlog completes the current file (with its
summary) and the recording goes on in a new file ``take-2.mcap``, ``take-3.mcap``... (listed
in ``stats.files``), so that every file is a gap-free take. A disk that refuses writes for
longer than ``hold_s`` (5 s) ends the file there (readable, without its summary; the held
messages are counted as dropped), and the recording resumes in a new file as soon as the disk
takes one (tried every flush interval), e.g. after the user freed space.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import struct
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

log = logging.getLogger(__name__)

PROFILE = "samba"
MARKERS_ENCODING = "samba-marker-v1"
POSE_ENCODING = "samba-pose-v1"
CALIBRATION_TOPIC = "/calibration"
POSE_TOPIC = "/pose"
EVENTS_TOPIC = "/events"

#: a chunk is closed and written at least this often (seconds) while messages come in
FLUSH_INTERVAL_S = 0.5
#: upper bound of one chunk (bytes); at Samba's data rates the time limit comes first
CHUNK_BYTES = 1 << 20
#: unwritten bytes kept while the disk refuses writes; beyond, new messages are dropped
MAX_PENDING_BYTES = 64 << 20
#: a disk refusing writes longer than this (seconds) ends the file; a new one starts when it can
HOLD_S = 5.0
#: a continuation file is started only with at least this much free space
MIN_FREE_BYTES = 64 << 10


def markers_topic(mote_id: str) -> str:
    """MCAP topic of one mote's raw marker packets."""
    return f"/mote/{mote_id}/markers"


# ---------------------------------------------------------------------- schemas


def _layout_doc(module: str, fallback: str) -> bytes:
    import importlib

    doc = importlib.import_module(module).__doc__  # None under python -OO
    return (doc or fallback).strip().encode("utf-8") + b"\n"


EVENT_JSONSCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "title": "samba.Event",
    "description": "A mote joined or left the session (Zenoh liveliness), as seen by the server; or the "
                   "subject (bone lengths + skin-marker offsets) the solver uses from pose seq on changed.",
    "type": "object",
    "properties": {
        "mote_id": {"type": "string", "description": "the mote (camera) id (join, leave)"},
        "event": {"type": "string", "enum": ["join", "leave", "subject"]},
        "t_ns": {"type": "integer", "description": "server time, ns since the Unix epoch"},
        "seq": {"type": "integer", "description": "subject: first pose seq solved with it"},
        "subject_toml": {"type": "string", "description": "subject: the subject.toml text (docs/formats.md)"},
    },
    "required": ["event", "t_ns"],
    "allOf": [
        {"if": {"properties": {"event": {"enum": ["join", "leave"]}}}, "then": {"required": ["mote_id"]}},
        {"if": {"properties": {"event": {"const": "subject"}}}, "then": {"required": ["seq", "subject_toml"]}},
    ],
}


def _constants(module: str) -> bytes:
    """Numeric values a decoder needs, listed from the code (flags, names in index order)."""
    from samba_common import pose_wire, wire
    from samba_common.skeleton import JOINT_NAMES, MARKER_NAMES

    lines = ["", "Values:"]
    if module == "pose_wire":
        lines.append("  flags: " + ", ".join(f"{n}=0x{b:02x}" for b, n in pose_wire.FLAG_NAMES.items()))
        lines.append("  label_mode: " + ", ".join(f"{i}={n}" for i, n in enumerate(pose_wire.LABEL_MODES)))
        lines.append("  joints (index order): " + ", ".join(JOINT_NAMES))
    else:
        lines.append("  flags: " + ", ".join(f"{n}=0x{b:02x}" for b, n in wire.FLAG_NAMES.items()))
        lines.append(f"  label: index into the markers below, {wire.UNLABELLED} = unlabelled")
    lines.append("  markers (index order): " + ", ".join(MARKER_NAMES))
    return ("\n".join(lines) + "\n").encode()


def schema_for(topic: str) -> tuple[str, str, bytes]:
    """(name, encoding, data) of the schema record of ``topic``'s channel."""
    if topic == POSE_TOPIC:
        return ("samba.Pose", "text/plain",
                b"Message encoding samba-pose-v1: one binary pose per message, as below.\n\n"
                + _layout_doc("samba_common.pose_wire", "Binary pose: see samba_common/pose_wire.py.")
                + _constants("pose_wire"))
    if topic == EVENTS_TOPIC:
        return "samba.Event", "jsonschema", json.dumps(EVENT_JSONSCHEMA, indent=1).encode()
    if topic == CALIBRATION_TOPIC:
        return ("samba.CalibrationToml", "text/plain",
                b"Message encoding toml: the calibration.toml in use, UTF-8 TOML, anipose layout: "
                b"one [cam_N] table per camera with name, size [w, h] px, matrix (3x3 K), "
                b"distortions [k1, k2, p1, p2, k3], rotation (Rodrigues, world -> camera), "
                b"translation (x_cam = R x_world + t, in [metadata] units: \"m\" (default), \"cm\" or \"mm\").\n")
    return ("samba.MarkerPacket", "text/plain",
            b"Message encoding samba-marker-v1: one binary marker packet of one mote per message, "
            b"as the mote sent it; layout below.\n\n"
            + _layout_doc("samba_common.wire", "Binary marker packet: see samba_common/wire.py.")
            + _constants("wire"))


class RecorderError(OSError):
    """The take file cannot be created."""


class _SafeSink:
    """Write-through file sink.

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


class _Spool:
    """The stream the MCAP writer writes to: bytes wait here until :meth:`commit` hands them
    to the sink in one write. ``tell()`` is the file offset they will have, so the writer's
    indexes stay right even while a full disk holds them back."""

    def __init__(self, sink: _SafeSink):
        self.sink = sink
        self.buf = bytearray()

    def write(self, data: bytes) -> int:
        self.buf += data
        return len(data)

    def tell(self) -> int:
        return self.sink.tell() + len(self.buf)

    def flush(self) -> None:
        pass

    def commit(self) -> None:
        """Write everything pending; on OSError the file is unchanged and the bytes stay."""
        if self.buf:
            self.sink.write(bytes(self.buf))
            self.buf.clear()


@dataclass
class RecorderStats:
    """Counters of a recorder: messages accepted (``written``; on disk once flushed) and
    dropped, bytes on disk, messages not yet on disk (``pending``), last write error."""

    written: int = 0
    dropped: int = 0
    bytes: int = 0
    pending: int = 0
    last_error: str = ""
    files: list = field(default_factory=list)  #: every file written, the current one last


class Recorder:
    """Record raw mote packets, the calibration, poses and events into one MCAP file.

    Thread-safe: the ingest thread records packets while the processing loop records poses.
    A daemon thread writes the open chunk every :data:`FLUSH_INTERVAL_S`; :meth:`flush` does
    it on demand, :meth:`close` writes the summary.
    """

    def __init__(self, path: str | os.PathLike, calibration_toml: bytes | None = None,
                 metadata: dict[str, str] | None = None, _sink: _SafeSink | None = None,
                 flush_interval_s: float = FLUSH_INTERVAL_S, max_pending_bytes: int = MAX_PENDING_BYTES,
                 hold_s: float = HOLD_S):
        self.path = Path(path)
        self.hold_s = float(hold_s)
        self._error_since: float | None = None  # monotonic time the disk started refusing writes
        self._gap = False  # the file was ended by a long write failure; waiting to start the next
        self._last_try = 0.0
        self.first_path = self.path
        self.stats = RecorderStats(files=[self.path])
        self._calibration: tuple[bytes, int] | None = None
        self._metadata = metadata
        self._dropped_at_error = 0
        self.flush_interval_s = float(flush_interval_s)
        self.max_pending_bytes = int(max_pending_bytes)
        self._lock = threading.Lock()
        self._channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self._closed = False
        self._bytes_before = 0  # bytes of the files finished before the current one
        self._open = 0  # messages in the open chunk
        self._spooled = 0  # messages in closed chunks not yet on disk
        self._last_flush = time.monotonic()
        self._start_file(self.path, _sink)
        self._stop = threading.Event()
        self._flusher = threading.Thread(target=self._flush_loop, name=f"recorder-flush {self.path.name}",
                                         daemon=True)
        self._flusher.start()
        if calibration_toml is not None:
            self.write_calibration(calibration_toml)

    def _start_file(self, path: Path, sink: _SafeSink | None = None) -> None:
        """Create ``path`` and write the MCAP header (raises RecorderError)."""
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        except OSError as exc:
            raise RecorderError(exc.errno, f"cannot create take file {path}: {exc.strerror}") from None
        self._fd = fd
        self._sink = sink or _SafeSink(fd)
        self._spool = _Spool(self._sink)
        self._channels = {}
        self._schemas = {}
        self._writer = Writer(self._spool, chunk_size=CHUNK_BYTES,  # type: ignore[arg-type]
                              compression=CompressionType.NONE, use_chunking=True, enable_crcs=True)
        try:
            self._writer.start(profile=PROFILE, library="samba")
            if self._metadata:
                self._writer.add_metadata("samba", {str(k): str(v) for k, v in self._metadata.items()})
            self._spool.commit()
        except OSError as exc:
            os.close(fd)
            raise RecorderError(exc.errno, f"cannot write take file {path}: {exc.strerror}") from None

    def _rollover(self) -> None:
        """(lock held, backlog written) Finish the current file and go on in the next one."""
        old = self.path
        try:
            self._writer.finish()
            self._spool.commit()
        except OSError as exc:
            log.error("could not finish %s (%s): readable without its summary", old, exc.strerror or exc)
        os.close(self._fd)
        lost = self.stats.dropped - self._dropped_at_error
        if not self._open_next():
            self._gap = True  # no room for the next file yet: tried again every flush interval
            return
        log.warning("recording continues in %s (%d message(s) could not be written to %s)", self.path, lost, old)

    def _end_file(self) -> None:
        """(lock held) The disk has refused writes for ``hold_s``: end the file where it is
        (every complete chunk is on disk), drop the held messages, wait for room for the next."""
        lost = self._spooled + self._open
        self.stats.dropped += lost
        self.stats.written -= lost
        self._spool.buf.clear()
        self._spooled = self._open = self.stats.pending = 0
        os.close(self._fd)
        self._gap = True
        self._last_try = time.monotonic()
        log.warning("recording to %s ended after %.0f s of write failures (%s; %d held message(s) dropped; the "
                    "file is readable without its summary); a new file starts as soon as the disk takes one",
                    self.path, self.hold_s, self.stats.last_error, lost)

    def _try_resume(self) -> None:
        """(lock held, after _end_file) Start the next file if the disk takes it now."""
        self._last_try = time.monotonic()
        if self._open_next():
            self._gap = False
            self._error_since = None
            self.stats.last_error = ""
            log.warning("recording continues in %s (%d message(s) could not be recorded meanwhile)", self.path,
                        self.stats.dropped - self._dropped_at_error)

    def _open_next(self) -> bool:
        """(lock held) Create the next continuation file with the calibration; False if impossible."""
        part = len(self.stats.files) + 1
        new = self.first_path.with_name(f"{self.first_path.stem}-{part}{self.first_path.suffix}")
        try:
            st = os.statvfs(new.parent)
            if st.f_bavail * st.f_frsize < MIN_FREE_BYTES:  # not worth a file that fills at once
                return False
        except OSError:
            pass
        try:
            self._start_file(new)
        except RecorderError as exc:
            log.debug("next take file not possible yet: %s", exc)
            try:
                new.unlink()
            except OSError:
                pass
            return False
        self.path = new
        self.stats.files.append(new)
        self._bytes_before = self.stats.bytes
        if self._calibration is not None:
            toml_bytes, t_ns = self._calibration
            ch = self._channel(CALIBRATION_TOPIC, "toml", {})
            self._writer.add_message(channel_id=ch, log_time=t_ns, data=toml_bytes, publish_time=t_ns, sequence=0)
            self._open += 1
        return True

    # ------------------------------------------------------------------ writing
    def _channel(self, topic: str, encoding: str, metadata: dict[str, str]) -> int:
        ch = self._channels.get(topic)
        if ch is None:
            name, schema_encoding, data = schema_for(topic)
            sid = self._schemas.get(name)
            if sid is None:
                sid = self._schemas[name] = self._writer.register_schema(name, schema_encoding, data)
            ch = self._writer.register_channel(topic=topic, message_encoding=encoding, schema_id=sid,
                                               metadata=metadata)
            self._channels[topic] = ch
        return ch

    def _write_out(self) -> bool:
        """(lock held) Close the open chunk and write all pending bytes; False if the disk refused."""
        self._last_flush = time.monotonic()
        flush = getattr(self._writer, "flush", None)
        if flush is not None:
            flush()
        else:  # pragma: no cover - mcap < 1.6 has no public Writer.flush
            self._writer._Writer__finalize_chunk()  # type: ignore[attr-defined]
        self._spooled += self._open
        self._open = 0
        try:
            self._spool.commit()
        except OSError as exc:
            msg = "disk full" if exc.errno == errno.ENOSPC else f"{exc.strerror or exc}"
            if not self.stats.last_error:
                self._dropped_at_error = self.stats.dropped
            now = time.monotonic()
            if self._error_since is None:
                self._error_since = now
            if msg != self.stats.last_error:
                log.error("recording to %s failed (%s): %d message(s) held in memory, retrying every %.1f s",
                          self.path, msg, self._spooled, self.flush_interval_s)
            self.stats.last_error = msg
            self.stats.pending = self._spooled
            if now - self._error_since >= self.hold_s and not self._closed:
                self._end_file()
            return False
        self._error_since = None
        self._spooled = self.stats.pending = 0
        self.stats.bytes = self._bytes_before + self._sink.tell()
        if self.stats.last_error:
            self.stats.last_error = ""
            if self.stats.dropped > self._dropped_at_error and not self._closed:
                self._rollover()  # a gap: the next messages go to a new file
            else:
                log.warning("recording to %s resumed (nothing lost)", self.path)
        return True

    def _add(self, topic: str, encoding: str, metadata: dict[str, str], data: bytes, log_time: int,
             publish_time: int, sequence: int) -> bool:
        with self._lock:
            if self._closed:
                self.stats.dropped += 1
                return False
            if self._gap:
                if time.monotonic() - self._last_try >= self.flush_interval_s:
                    self._try_resume()
                if self._gap:
                    self.stats.dropped += 1
                    return False
            if len(self._spool.buf) > self.max_pending_bytes:  # the disk refuses writes, backlog full
                if time.monotonic() - self._last_flush >= self.flush_interval_s:
                    self._write_out()  # retry (at most once per interval)
                if len(self._spool.buf) > self.max_pending_bytes:
                    self.stats.dropped += 1
                    return False
            ch = self._channel(topic, encoding, metadata)
            self._writer.add_message(channel_id=ch, log_time=int(log_time), data=bytes(data),
                                     publish_time=int(publish_time), sequence=int(sequence) & 0xFFFFFFFF)
            self.stats.written += 1
            self._open += 1
            self.stats.pending = self._open + self._spooled
            if time.monotonic() - self._last_flush >= self.flush_interval_s or (
                    self._spool.buf and not self.stats.last_error):  # due, or the writer closed a full chunk
                self._write_out()  # while the disk refuses writes: one attempt per interval
            return True

    def _flush_loop(self) -> None:
        period = max(self.flush_interval_s / 5, 0.01)
        while not self._stop.wait(period):
            with self._lock:
                if self._closed:
                    return
                if self._gap:
                    if time.monotonic() - self._last_try >= self.flush_interval_s:
                        self._try_resume()
                    continue
                if (self._open or self._spool.buf) and time.monotonic() - self._last_flush >= self.flush_interval_s:
                    self._write_out()

    def flush(self) -> bool:
        """Write the open chunk now; False if the disk refused (the data stays pending)."""
        with self._lock:
            if self._closed or self._gap:
                return not self._gap
            return self._write_out()

    def write_packet(self, mote_id: str, payload: bytes, arrival_ns: int, capture_ns: int = 0,
                     seq: int = 0) -> bool:
        """Record one raw marker packet of ``mote_id``; False (and a counted drop) if it cannot be."""
        return self._add(markers_topic(mote_id), MARKERS_ENCODING, {"mote_id": mote_id}, payload,
                         arrival_ns, capture_ns or arrival_ns, seq)

    def write_calibration(self, toml_bytes: bytes, t_ns: int = 0) -> bool:
        """Record the calibration.toml in use (again at the start of every continuation file)."""
        self._calibration = (bytes(toml_bytes), int(t_ns))
        return self._add(CALIBRATION_TOPIC, "toml", {}, toml_bytes, t_ns, t_ns, 0)

    def write_pose(self, payload: bytes, publish_ns: int, frame_ns: int, seq: int = 0) -> bool:
        """Record one binary pose message."""
        return self._add(POSE_TOPIC, POSE_ENCODING, {}, payload, publish_ns, frame_ns, seq)

    def write_event(self, payload: bytes, t_ns: int) -> bool:
        """Record one JSON event (mote join/leave)."""
        return self._add(EVENTS_TOPIC, "json", {}, payload, t_ns, t_ns, 0)

    def write_metadata(self, name: str, data: dict[str, str]) -> bool:
        """Add an MCAP metadata record ``name`` now (e.g. the subject measured live); continuation
        files start with it too. False if the file is closed or in a write gap."""
        with self._lock:
            self._metadata = {**(self._metadata or {}), **{f"{name}.{k}": v for k, v in data.items()}}
            if self._closed or self._gap:
                return False
            try:
                self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})
            except OSError:
                return False
            return self._write_out()

    def close(self) -> None:
        """Write the last chunk and the MCAP summary, close the file (idempotent)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._stop.set()
            if not self._gap:  # (in a gap the last file was already ended by the full disk)
                self._finish_current()
        if self._flusher is not threading.current_thread():
            self._flusher.join(timeout=5)
        names = ", ".join(str(f) for f in self.stats.files)  # more than one after a full disk
        print(f"wrote {names}: {self.stats.written} messages, {self.stats.bytes / 1e6:.1f} MB"
              + (f", {self.stats.dropped} dropped ({self.stats.last_error})" if self.stats.dropped else ""),
              file=sys.stderr)

    def _finish_current(self) -> None:
        """(lock held, closing) Write the last chunk and the summary, close the file."""
        data_ok = self._write_out()  # the last chunk first: it matters more than the summary
        try:
            self._writer.finish()
            self._spool.commit()
        except OSError as exc:
            lost = self._spooled
            self.stats.dropped += lost
            self.stats.written -= lost
            self.stats.last_error = exc.strerror or str(exc)
            log.error("could not finish %s (%s): %s; the file stays readable without its summary",
                      self.path, exc.strerror or exc,
                      "summary not written" if data_ok else f"{lost} message(s) lost")
        finally:
            self._spooled = self.stats.pending = 0
            self.stats.bytes = self._bytes_before + self._sink.tell()
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
        #: MCAP metadata records read so far, by name (a later record of a name replaces it)
        self.metadata: dict[str, dict[str, str]] = {}

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
                        MemoryError, OverflowError) as exc:
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
                elif isinstance(rec, Metadata):
                    self.metadata[rec.name] = dict(rec.metadata)
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


def recorded_subjects(path: str | Path) -> list[tuple[int, str]]:
    """Every subject event of a take: (first pose seq, subject.toml text), in order."""
    out = []
    for m in TakeReader(path, topics=[EVENTS_TOPIC]):
        try:
            ev = json.loads(m.data)
        except ValueError:
            continue
        if isinstance(ev, dict) and ev.get("event") == "subject" and isinstance(ev.get("subject_toml"), str):
            out.append((int(ev.get("seq", 0)), ev["subject_toml"]))
    return out


def _subject_or_none(toml: str, where: str):
    """subject.toml text as a samba_common.subject.Subject, or None (logged) when invalid."""
    from samba_common.subject import SubjectError, load_subject_text

    try:
        return load_subject_text(toml, where)
    except SubjectError as exc:
        log.warning("%s", exc)
        return None


def _server_metadata(path: str | Path) -> dict:
    """The ``samba`` metadata record the recording server wrote (empty when there is none)."""
    reader = TakeReader(path, topics=[CALIBRATION_TOPIC])
    for _m in reader:
        break  # the metadata record is written before the first message
    return reader.metadata.get("samba", {})


def take_subject(path: str | Path):
    """The subject a take was recorded with when the server was given one (``--subject``:
    ``subject_toml`` in the ``samba`` metadata record), as a samba_common.subject.Subject, or
    None (then a replayed solver measures it live again, as the server did)."""
    toml = _server_metadata(path).get("subject_toml")
    return _subject_or_none(toml, f"{path} (its recorded subject)") if toml else None


def take_placement(path: str | Path) -> str | None:
    """The marker placement the server that recorded a take was asked for (``--placement`` or
    ``[reconstruct] placement``: "auto", "skin" or "joint_centres"; ``placement`` in the
    ``samba`` metadata record), or None for takes recorded before it was kept."""
    placement = _server_metadata(path).get("placement")
    return placement if placement in ("auto", "skin", "joint_centres") else None


def last_subject(path: str | Path):
    """The last subject a take's poses were solved with (the last subject event when it was
    measured live, else :func:`take_subject`), or None."""
    events = recorded_subjects(path)
    if not events:
        return take_subject(path)
    return _subject_or_none(events[-1][1], f"{path} (recorded subject)")
