"""Fault harness: a lossy, jittery, lying network between (simulated) motes and the server.

:class:`ChaosLink` is the fault model, independent of any transport. Every marker packet a
mote sends goes through :meth:`ChaosLink.process`, which returns the deliveries it turns into
(arrival time, key mote id, bytes) and counts exactly what it did:

- **loss** with bursts (Gilbert model: ``loss`` mean fraction, ``burst`` mean burst length in
  packets; 1 = independent losses);
- **jitter**: each delivery ``base_latency_ms + U(-jitter_ms, +jitter_ms)`` after capture, so
  packets of one mote overtake each other (**reordering**, counted on delivery);
- **duplicates**: a delivered packet sent again right after itself;
- **late**: a packet held back ``late_ms`` (past its frame's deadline);
- **malformed**: an extra damaged copy (truncated, bad magic or trailing bytes) under the mote's key;
- **unknown mote**: an extra copy re-encoded under a mote id that is not in the calibration;
- **clock offset and drift** per mote: the capture time written in the packet becomes
  ``t + offset + drift_ppm * 1e-6 * (t - t_first)``.

Mote kills and restarts (silence, then seq from 0, with liveliness leave/join) are scheduled by
the drivers: :func:`simulate` runs the whole chain on a virtual clock (deterministic, seconds of
CPU for minutes of take) and :class:`ChaosRelay` sits on Zenoh between the motes' session and the
server's session (``samba-chaos relay``), so real motes and a real server can be attacked too.
Server and router restarts are exercised in ``tests/server/test_chaos.py``. The counters of both
sides are compared by :func:`compare` (docs/reliability.md).
"""

from __future__ import annotations

import heapq
import itertools
import logging
import struct
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from samba_common.wire import HEADER, decode_packet, encode_packet, PacketError

log = logging.getLogger(__name__)

_T_OFFSET = 12  #: byte offset of the capture time (int64 ns) in a marker packet header
UNKNOWN_MOTE = "chaos-stranger"


@dataclass(frozen=True)
class FaultConfig:
    """What the harness does to the packets (probabilities per packet; times in ms)."""

    loss: float = 0.0  #: mean fraction of packets lost, 0..0.3
    burst: float = 1.0  #: mean length of a loss burst (packets)
    jitter_ms: float = 0.0  #: delivery delay spread: U(-jitter_ms, +jitter_ms)
    base_latency_ms: float = 25.0  #: mean delivery delay; must be >= jitter_ms
    duplicate: float = 0.0  #: probability a delivered packet is delivered twice
    late: float = 0.0  #: probability a packet is held back by late_ms
    late_ms: float = 300.0
    malformed: float = 0.0  #: probability of an extra damaged packet after a packet
    unknown: float = 0.0  #: probability of an extra packet from an unknown mote
    offsets_ms: tuple[float, ...] = (0.0,)  #: clock offset per mote (cycled)
    drift_ppm: tuple[float, ...] = (0.0,)  #: clock drift per mote (cycled), + = fast
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0 <= self.loss < 1 or self.burst < 1 or self.jitter_ms < 0 or self.base_latency_ms < self.jitter_ms:
            raise ValueError(f"invalid fault config {self}")
        for p in (self.duplicate, self.late, self.malformed, self.unknown):
            if not 0 <= p <= 1:
                raise ValueError(f"probabilities must be in 0..1: {self}")


@dataclass
class Injected:
    """Counters of one mote's faults (or the totals)."""

    sent: int = 0  #: packets the mote sent into the harness
    lost: int = 0
    delivered: int = 0  #: original packets delivered (on time or late)
    late: int = 0  #: of the delivered, held back by late_ms
    duplicate: int = 0
    malformed: int = 0
    unknown: int = 0
    reordered: int = 0  #: delivered after a packet of the same mote with a higher seq

    def add(self, other: "Injected") -> None:
        for k in self.__dataclass_fields__:
            setattr(self, k, getattr(self, k) + getattr(other, k))


@dataclass
class _MoteState:
    index: int
    bad: bool = False  # Gilbert state: in a loss burst
    counts: Injected = field(default_factory=Injected)
    last_delivered_seq: int = -1


class ChaosLink:
    """The fault model (see the module docstring). Not thread-safe: one caller at a time."""

    def __init__(self, config: FaultConfig, motes: list[str] | tuple[str, ...]):
        self.config = config
        self.rng = np.random.default_rng(config.seed)
        self.motes = {m: _MoteState(i) for i, m in enumerate(motes)}
        self.t_first: int | None = None
        # Gilbert model: P(good -> bad) and P(bad -> good) giving the mean loss and burst length
        c = config
        self._p_exit = 1.0 / c.burst
        self._p_enter = c.loss * self._p_exit / (1.0 - c.loss) if c.loss > 0 else 0.0

    # ------------------------------------------------------------------ per packet
    def _state(self, mote: str) -> _MoteState:
        st = self.motes.get(mote)
        if st is None:
            st = self.motes[mote] = _MoteState(len(self.motes))
        return st

    def clock(self, mote: str, t_ns: int) -> int:
        """The capture time ``t_ns`` (true clock) as the mote's faulty clock reads it."""
        c, i = self.config, self._state(mote).index
        if self.t_first is None:
            self.t_first = t_ns
        off = c.offsets_ms[i % len(c.offsets_ms)] * 1e6
        drift = c.drift_ppm[i % len(c.drift_ppm)] * 1e-6
        return int(t_ns + off + drift * (t_ns - self.t_first))

    def process(self, mote: str, payload: bytes, now_ns: int) -> list[tuple[int, str, bytes]]:
        """One packet ``mote`` sent at ``now_ns`` (true clock): its deliveries, any order."""
        c, rng = self.config, self.rng
        st = self._state(mote)
        st.counts.sent += 1
        payload = self._retime(mote, payload)
        st.bad = rng.random() < (1.0 - self._p_exit if st.bad else self._p_enter)
        out: list[tuple[int, str, bytes]] = []
        if st.bad:
            st.counts.lost += 1
        else:
            delay = c.base_latency_ms + rng.uniform(-c.jitter_ms, c.jitter_ms)
            if rng.random() < c.late:
                delay += c.late_ms
                st.counts.late += 1
            t = now_ns + int(delay * 1e6)
            st.counts.delivered += 1
            out.append((t, mote, payload))
            if rng.random() < c.duplicate:
                st.counts.duplicate += 1
                out.append((t + 1, mote, payload))
        t_extra = now_ns + int(c.base_latency_ms * 1e6)
        if rng.random() < c.malformed:
            st.counts.malformed += 1
            out.append((t_extra, mote, self._damage(payload)))
        if rng.random() < c.unknown:
            forged = self._stranger(payload)
            if forged is not None:
                st.counts.unknown += 1
                out.append((t_extra, UNKNOWN_MOTE, forged))
        return out

    def delivered(self, mote: str, payload: bytes) -> None:
        """Tell the link a packet reached the wire (counts reordering)."""
        if len(payload) < HEADER.size or payload[:4] != b"SMBM":
            return
        st = self.motes.get(mote)
        if st is None:
            return
        seq = struct.unpack_from("<I", payload, 8)[0]
        if seq < st.last_delivered_seq and st.last_delivered_seq - seq < 30:
            st.counts.reordered += 1
        st.last_delivered_seq = max(st.last_delivered_seq, seq) if st.last_delivered_seq - seq < 30 else seq

    def restarted(self, mote: str) -> None:
        """The mote restarted (its seq starts again from 0)."""
        self._state(mote).last_delivered_seq = -1

    # ------------------------------------------------------------------ helpers
    def _retime(self, mote: str, payload: bytes) -> bytes:
        if len(payload) < HEADER.size or payload[:4] != b"SMBM":
            return payload
        (t,) = struct.unpack_from("<q", payload, _T_OFFSET)
        buf = bytearray(payload)
        struct.pack_into("<q", buf, _T_OFFSET, self.clock(mote, t))
        return bytes(buf)

    def _damage(self, payload: bytes) -> bytes:
        """A copy the decoder must reject: truncated, bad magic or trailing bytes."""
        kind = int(self.rng.integers(3))
        if kind == 0 and len(payload) > 1:
            return payload[: int(self.rng.integers(0, len(payload)))]
        if kind == 1:
            return b"XXXX" + payload[4:]
        return payload + bytes(self.rng.integers(0, 256, int(self.rng.integers(1, 13)), dtype=np.uint8))

    def _stranger(self, payload: bytes) -> bytes | None:
        try:
            pkt = decode_packet(payload)
        except PacketError:
            return None
        pkt.mote_id = UNKNOWN_MOTE
        return encode_packet(pkt)

    def totals(self) -> Injected:
        out = Injected()
        for st in self.motes.values():
            out.add(st.counts)
        return out

    def report(self) -> dict:
        """What was injected: totals and per mote (dicts of :class:`Injected` fields)."""
        return {"total": self.totals().__dict__.copy(),
                "motes": {m: st.counts.__dict__.copy() for m, st in sorted(self.motes.items())}}


# ---------------------------------------------------------------------- virtual-clock driver


@dataclass
class SimResult:
    """Outcome of :func:`simulate`: both sides' counters and the expected frame figures."""

    injected: dict
    server: dict
    expected_frames: int  #: capture instants with at least one packet on time
    expected_missing: dict[str, int]  #: per mote: instants it was alive but its packet did not make it
    latency_ms: np.ndarray


def simulate(server, joints: np.ndarray, fps: float, seconds: float, faults: FaultConfig,
             kill: dict[int, tuple[float, float]] | None = None, clock: list[int] | None = None,
             noise_px: float = 0.05, t0_ns: int = 1_700_000_000_000_000_000) -> SimResult:
    """Run ``seconds`` of simulated motes (one per camera of ``server.rig``, showing ``joints``
    (F, 13, 3) m, looped, at ``fps``) through a :class:`ChaosLink` into ``server`` on a
    virtual clock. ``server`` must have been built with ``clock=lambda: clock[0]``;
    ``kill``: {mote index: (stop s, restart s)} (liveliness leave/join are sent too)."""
    from .simmotes import make_packet, project_take

    rig = server.rig
    names = list(rig.names)
    link = ChaosLink(faults, names)
    clock = clock if clock is not None else [t0_ns]
    uv, vis = project_take(rig, joints)
    rng = np.random.default_rng(faults.seed + 1)
    period = 1e9 / fps
    n = int(seconds * fps)
    kill = kill or {}
    heap: list = []
    tie = itertools.count()
    seqs = [0] * len(names)
    on_time: dict[int, set[str]] = {}  # capture index -> motes whose packet is delivered in time
    alive_at: dict[int, set[str]] = {}
    ever: set[str] = set()
    for m, name in enumerate(names):
        heapq.heappush(heap, (t0_ns - 1, next(tie), "join", name, b"", -1))
    for k in range(n):
        t_cap = int(t0_ns + k * period)
        alive = set()
        for m, name in enumerate(names):
            stop, restart = kill.get(m, (np.inf, np.inf))
            t_rel = k / fps
            if stop <= t_rel < restart:
                if stop <= t_rel < stop + 1 / fps:
                    heapq.heappush(heap, (t_cap, next(tie), "leave", name, b"", -1))
                continue
            if restart <= t_rel < restart + 1 / fps:
                seqs[m] = 0
                heapq.heappush(heap, (t_cap - 1, next(tie), "join", name, b"", -1))
            alive.add(name)
            fk = k % len(joints)
            pkt = make_packet(name, seqs[m], t_cap, uv[m, fk], vis[m, fk], rig.cameras[m].size, rng, noise_px)
            seqs[m] += 1
            before = link.motes[name].counts.late, link.motes[name].counts.delivered
            for t, key, data in link.process(name, encode_packet(pkt), t_cap):
                heapq.heappush(heap, (t, next(tie), "packet", key, data, k))
            st = link.motes[name].counts
            if st.delivered > before[1] and st.late == before[0]:
                on_time.setdefault(k, set()).add(name)
        alive_at[k] = alive
    # feed the server in arrival order
    restarted: set[str] = set()
    while heap:
        t, _, kind, key, data, k = heapq.heappop(heap)
        clock[0] = max(clock[0], t)
        if kind == "packet":
            link.delivered(key, data)
            server.ingest(key, data, arrival_ns=t)
        else:
            if kind == "join" and key in ever:
                link.restarted(key)
                restarted.add(key)
            ever.add(key)
            server.mote_event(key, kind == "join", t)
        server.process_pending()
    server.finish()
    expected_missing = {m: 0 for m in names}
    frames = 0
    for k in range(n):
        got = on_time.get(k, set())
        if got:
            frames += 1
            for m in alive_at[k] - got:
                expected_missing[m] += 1
    return SimResult(link.report(), server.report(), frames, expected_missing,
                     np.asarray(server.stats.latency_ms, float))


def compare(injected: dict, reported: dict) -> list[tuple[str, int, int]]:
    """(what, injected, reported) rows for the drop causes the harness injects."""
    tot, drops = injected["total"], reported["drops"]
    return [("lost (never arrives)", tot["lost"], 0), ("late", tot["late"], drops["late"]),
            ("duplicate", tot["duplicate"], drops["duplicate"]), ("malformed", tot["malformed"], drops["malformed"]),
            ("unknown mote", tot["unknown"], drops["unknown_mote"])]


# ---------------------------------------------------------------------- Zenoh relay


class ChaosRelay:
    """Relay ``samba/{src}/mote/*/markers`` (and the motes' liveliness tokens) into session
    ``dst`` through a :class:`ChaosLink`: motes publish on ``src``, the server listens on
    ``dst``. Deliveries are scheduled on the wall clock by a background thread."""

    def __init__(self, link: ChaosLink, src: str, dst: str, connect: list[str] | tuple[str, ...] = (),
                 listen: list[str] | tuple[str, ...] = (), mode: str = "peer"):
        from samba_common import zenoh_util as zk

        self.link, self.src, self.dst = link, src, dst
        self.cfg = zk.make_config(mode=mode, connect=connect, listen=listen)
        self._heap: list = []
        self._tie = itertools.count()
        self._cv = threading.Condition()
        self._stop = threading.Event()
        self._z = None
        self._pubs: dict[str, object] = {}
        self._tokens: dict[str, object] = {}
        self._decls: list = []
        self._thread: threading.Thread | None = None
        self.forwarded = 0

    def start(self) -> "ChaosRelay":
        import zenoh

        from samba_common import zenoh_util as zk

        self._z = zenoh.open(self.cfg)
        self._decls = [
            self._z.declare_subscriber(zk.markers_key(self.src, "*"), self._on_markers),
            self._z.liveliness().declare_subscriber(zk.liveliness_key(self.src, "*"), self._on_liveliness,
                                                    history=True),
        ]
        self._thread = threading.Thread(target=self._run, name="chaos-relay", daemon=True)
        self._thread.start()
        return self

    def _on_markers(self, sample) -> None:
        from samba_common import zenoh_util as zk

        try:
            mote = zk.mote_id_from_key(str(sample.key_expr)) or "?"
            now = time.time_ns()
            with self._cv:
                for item in self.link.process(mote, sample.payload.to_bytes(), now):
                    heapq.heappush(self._heap, (item[0], next(self._tie), item[1], item[2]))
                self._cv.notify()
        except Exception:  # pragma: no cover - a callback must not die
            log.exception("chaos relay: packet handling failed")

    def _on_liveliness(self, sample) -> None:
        import zenoh

        from samba_common import zenoh_util as zk

        mote = zk.mote_id_from_key(str(sample.key_expr))
        if mote is None or self._z is None:
            return
        try:
            if sample.kind == zenoh.SampleKind.PUT:
                with self._cv:
                    if mote in self._tokens:
                        return
                    self.link.restarted(mote)
                self._tokens[mote] = self._z.liveliness().declare_token(zk.liveliness_key(self.dst, mote))
            else:
                tok = self._tokens.pop(mote, None)
                if tok is not None:
                    tok.undeclare()
        except Exception:  # pragma: no cover
            log.exception("chaos relay: liveliness mirroring failed")

    def _run(self) -> None:
        from samba_common import zenoh_util as zk

        while not self._stop.is_set():
            with self._cv:
                if not self._heap:
                    self._cv.wait(0.05)
                    continue
                t, _, key, data = self._heap[0]
                wait = (t - time.time_ns()) / 1e9
                if wait > 0:
                    self._cv.wait(min(wait, 0.05))
                    continue
                heapq.heappop(self._heap)
                self.link.delivered(key, data)
            try:
                pub = self._pubs.get(key)
                if pub is None:
                    pub = self._pubs[key] = self._z.declare_publisher(zk.markers_key(self.dst, key), express=True)
                pub.put(data)
                self.forwarded += 1
            except Exception:  # pragma: no cover - closing
                log.debug("chaos relay: put failed", exc_info=True)

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for d in self._decls:
            try:
                d.undeclare()
            except Exception:  # pragma: no cover
                pass
        self._decls = []
        if self._z is not None:
            self._z.close()
            self._z = None

    def __enter__(self) -> "ChaosRelay":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
