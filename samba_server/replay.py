"""Replay a recorded take: in-process through the server pipeline (exact), or republished on
Zenoh with the original timing (or as fast as possible) for a running ``samba-server``.

In-process replay feeds :meth:`Server.ingest` with the recorded arrival stamps and the
recorded mote joins/leaves, in file order, which is the order the live server processed
them; the server's decisions depend only on those, so the poses equal the live ones.

Republished packets carry their recorded arrival stamp in a Zenoh attachment
(:data:`ATTACHMENT`); a live server (:class:`ReplayClock`) uses it, shifted to its own clock,
as the arrival time. Frame grouping then sees the recorded timing even when the player runs
faster than real time (``--speed max``): without it, packets arriving in a burst all look
simultaneous and most frames fall apart.
"""

from __future__ import annotations

import json
import logging
import os
import struct
import threading
import time
from collections.abc import Callable
from pathlib import Path

from samba_common import zenoh_util as zk

from samba_common.pose_wire import FLAG_SOLVE_SKIPPED, PoseError, decode_pose

from .record import CALIBRATION_TOPIC, EVENTS_TOPIC, POSE_TOPIC, TakeReader, recorded_subjects, take_subject  # noqa: F401
from .server import Server

log = logging.getLogger(__name__)


def take_calibration(path: str | Path) -> bytes | None:
    """The calibration.toml bytes recorded in a take (first one), or None."""
    for m in TakeReader(path, topics=[CALIBRATION_TOPIC]):
        return m.data
    return None


def skipped_solves(path: str | Path) -> set[int] | None:
    """Seqs of the recorded poses whose solve the live server skipped (``FLAG_SOLVE_SKIPPED``),
    counted from the first recorded pose, or None when the take holds no poses (then nothing
    is skipped)."""
    seqs: set[int] = set()
    first: int | None = None  # a recording started mid-run: seqs counted from its first pose
    for m in TakeReader(path, topics=[POSE_TOPIC]):
        try:
            pose = decode_pose(m.data)
        except PoseError:
            continue
        if first is None:
            first = pose.seq
        if pose.flags & FLAG_SOLVE_SKIPPED:
            seqs.add(pose.seq - first)
    return seqs if first is not None else None


def replay_into(server: Server, path: str | Path, progress: Callable[[int], None] | None = None,
                solve_all: bool = False) -> TakeReader:
    """Feed every recorded packet and event of ``path`` into ``server`` and flush it.

    The frames whose solve the live server skipped (it was behind, ``max_lag_ms``) are skipped
    again, so the poses equal the live ones; ``solve_all`` solves them too. Returns the reader
    (``.truncated`` tells whether the take ended early).
    """
    server.skip_seqs = set() if solve_all else (skipped_solves(path) or set())
    reader = TakeReader(path)
    for m in reader:
        mote = m.mote_id
        if mote is not None:
            server.ingest(mote, m.data, arrival_ns=m.log_time)
        elif m.topic == EVENTS_TOPIC:
            try:
                ev = json.loads(m.data)
                if ev.get("event") not in ("join", "leave"):
                    continue  # e.g. "subject": the replayed solver measures it again at the same frame
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


#: attachment of a republished packet: magic, replay run id (u64), recorded arrival (i64 ns)
ATTACHMENT = struct.Struct("<4sQq")
ATTACHMENT_MAGIC = b"SMBR"


class ReplayClock:
    """Maps the recorded arrival stamps of republished packets onto the live server's clock.

    Each replay run (its id in the attachment) gets one constant shift, chosen at its first
    packet so that its stamps start now and after every stamp already given out: recorded
    inter-arrival times are kept exactly, whatever the playback speed. Thread-safe.
    """

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._run: int | None = None
        self._shift = 0
        self._received = 0  # packets of the current run

    def progress(self) -> dict:
        """``{"run": id or None, "received": packets of that run taken in}`` (see :meth:`Player.play`)."""
        with self._lock:
            return {"run": self._run, "received": self._received}

    def arrival_ns(self, attachment: bytes | None, now_ns: int, last_arrival_ns: int) -> int | None:
        """The arrival stamp for a packet with ``attachment`` received at ``now_ns``, or None
        when it carries no (valid) replay attachment (a live mote: stamp it on arrival)."""
        if not attachment or len(attachment) != ATTACHMENT.size:
            return None
        magic, run, recorded = ATTACHMENT.unpack(attachment)
        if magic != ATTACHMENT_MAGIC:
            return None
        with self._lock:
            if run != self._run:
                self._run, self._received = run, 0
                self._shift = max(now_ns, last_arrival_ns + 1) - recorded
            return recorded + self._shift

    def taken_in(self) -> None:
        """Count one packet of the current run as taken in by the server (queued, not dropped)."""
        with self._lock:
            self._received += 1


class Player:
    """Republish a take's mote packets on Zenoh, one liveliness token per recorded mote.

    speed: 1.0 = original timing, 2.0 = twice as fast, None/0 = as fast as possible. Every
    packet carries its recorded arrival stamp (:data:`ATTACHMENT`), so a live server groups
    frames as the recording did, at any speed.
    """

    def __init__(self, path: str | Path, session: str = zk.DEFAULT_SESSION, connect=(), listen=(),
                 speed: float | None = 1.0):
        self.path = Path(path)
        self.session_name = session
        self.cfg = zk.make_config(connect=connect, listen=listen)
        self.speed = speed
        self.sent = 0
        #: packets the server says it took in of this run (its replay status), None = unknown
        self.taken_in: int | None = None

    def play(self, stop=None, wait_match: float = 5.0, max_join_gap: float = 0.6, quiet_s: float = 0.5,
             drain_s: float = 60.0) -> int:
        """Publish every packet; returns the number sent. ``stop``: optional threading.Event.

        Every recorded mote's publisher is declared first (its subscriber waited for, up to
        ``wait_match`` s); the recorded joins and leaves become liveliness tokens declared and
        undeclared at their place in the take. After a join, the first packet waits for the
        recorded join-to-packet gap (at most ``max_join_gap`` s, longer than the server's
        250 ms ``dead_after``, even at ``--speed max``), so the server judges the new mote alive
        or not as it did live. Leaves wait for the server to take in the last packets (see the
        end); at ``--speed max`` a leave in the middle of the take is kept until the end."""
        import zenoh

        run_id = int.from_bytes(os.urandom(8), "little")
        motes = sorted({m.mote_id for m in TakeReader(self.path) if m.mote_id is not None})
        with zenoh.open(self.cfg) as z:
            # BLOCK: a replay loses no packet when it outruns the server (DROP, the default, is
            # for live motes, whose stale packets are worth nothing)
            pubs = {mote: z.declare_publisher(zk.markers_key(self.session_name, mote),
                                              congestion_control=zenoh.CongestionControl.BLOCK) for mote in motes}
            deadline = time.monotonic() + wait_match
            while not all(p.matching_status.matching for p in pubs.values()) and time.monotonic() < deadline:
                time.sleep(0.01)
            if not all(p.matching_status.matching for p in pubs.values()):
                log.warning("no subscriber for the markers of %s after %.1f s: is samba-server running on this "
                            "session (%r) and endpoint?", ", ".join(motes), wait_match, self.session_name)
            last_pose = [0.0]  # wall time of the server's last pose: the end waits for it to go quiet
            pose_sub = z.declare_subscriber(zk.pose_key(self.session_name),
                                            lambda _s: last_pose.__setitem__(0, time.monotonic()))
            tokens: dict[str, object] = {}
            join: tuple[int, float] | None = None  # (recorded, wall) time of the last join
            t_first = None
            wall0 = t_last = time.monotonic()
            for m in TakeReader(self.path):
                if stop is not None and stop.is_set():
                    break
                mote = m.mote_id
                if mote is None:
                    if m.topic == EVENTS_TOPIC:
                        join = self._event(z, m, tokens) or join
                    continue
                if mote not in tokens:  # a take recorded without events: the mote joins now
                    tokens[mote] = z.liveliness().declare_token(zk.liveliness_key(self.session_name, mote))
                    join = (m.log_time, time.monotonic())
                if join is not None:
                    gap = min(max(m.log_time - join[0], 0) / 1e9 / (self.speed or 1.0), max_join_gap)
                    time.sleep(max(join[1] + gap - time.monotonic(), 0.0))
                    join = None
                    if t_first is not None:  # the wait does not shift the rest of the timing
                        wall0 = time.monotonic() - (m.log_time - t_first) / 1e9 / (self.speed or 1.0)
                if t_first is None:
                    t_first, wall0 = m.log_time, time.monotonic()
                if self.speed:
                    due = wall0 + (m.log_time - t_first) / 1e9 / self.speed
                    delay = due - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                pubs[mote].put(m.data, attachment=ATTACHMENT.pack(ATTACHMENT_MAGIC, run_id, m.log_time))
                self.sent += 1
            t_last = time.monotonic()
            # Zenoh delivers data and liveliness on separate paths: leaving at once could reach the
            # server before the last packets (at --speed max they queue up), so wait until it has
            # taken in and processed them all (at most drain_s)
            self._drain(z, run_id, lambda: max(last_pose[0], t_last), quiet_s, drain_s)
            pose_sub.undeclare()
            for tok in tokens.values():
                tok.undeclare()
        return self.sent

    def _drain(self, z, run_id: int, last_activity: Callable[[], float], quiet_s: float, drain_s: float) -> None:
        """Wait until the server says (its replay status queryable) that it took in all
        ``self.sent`` packets of this run and processed them; a server without the queryable
        (an older one) is waited for until it published no pose for ``quiet_s``. At most
        ``drain_s`` s; a server still short of packets then is reported."""
        end = time.monotonic() + drain_s
        key = zk.replay_status_key(self.session_name)
        status, seen, changed = None, None, time.monotonic()
        while time.monotonic() < end:
            status = _query_json(z, key, timeout=min(2.0, max(end - time.monotonic(), 0.1)))
            if status is None:
                break
            got = status.get("received", -1) if status.get("run") == run_id else -1
            if got >= 0:
                self.taken_in = got
            if got >= self.sent and status.get("backlog") == 0:
                return
            if got != seen or status.get("backlog") != 0:
                seen, changed = got, time.monotonic()
            elif time.monotonic() - changed > max(4 * quiet_s, 2.0):
                break  # idle, and nothing more comes in: packets were lost on the way
            time.sleep(0.02)
        if status is not None:
            log.warning("the server took in %s of the %d packets sent: the rest was lost on the way",
                        self.taken_in or 0, self.sent)
            return
        while time.monotonic() < end and time.monotonic() - last_activity() < quiet_s:
            time.sleep(0.05)

    def _event(self, z, m, tokens: dict) -> tuple[int, float] | None:
        """Declare/undeclare the token of a recorded join/leave; returns (recorded, wall) of a join."""
        try:
            ev = json.loads(m.data)
            if ev.get("event") not in ("join", "leave"):
                return None  # e.g. "subject": the server being fed measures it itself
            mote, joined = str(ev["mote_id"]), ev["event"] == "join"
        except (ValueError, KeyError, TypeError, AttributeError):
            log.warning("bad event record skipped: %r", m.data[:80])
            return None
        if joined and mote not in tokens:
            tokens[mote] = z.liveliness().declare_token(zk.liveliness_key(self.session_name, mote))
            return (m.log_time, time.monotonic())
        if not joined and mote in tokens and self.speed:
            tokens.pop(mote).undeclare()
        return None


def _query_json(z, key: str, timeout: float) -> dict | None:
    """The first JSON reply of a Zenoh query on ``key``; ``{}`` when the query timed out or
    failed (a busy server: ask again); None when nobody serves ``key`` (the query ends at once)."""
    payload, reason = zk.first_reply(z, key, timeout)
    if payload is None:
        if reason is not None:
            log.debug("query %s failed: %s", key, reason)
            return {}
        return None
    try:
        return json.loads(payload)
    except ValueError as exc:
        log.debug("query %s: not JSON: %s", key, exc)
        return {}
