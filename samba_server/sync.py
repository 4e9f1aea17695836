"""Group free-running motes' packets into frames by capture time (pure logic, no I/O).

Each mote stamps its packets with its own clock (``t_ns``); the server stamps them on
arrival (``arrival_ns``). The delay ``d = arrival_ns - t_ns`` is the mote's clock offset plus
the transport latency, which is never below some floor. A sliding-window **minimum** of ``d``
per mote (the one-way "minimum delay" filter of NTP) therefore estimates the offset up to a
constant common to all motes; jitter only ever adds to ``d``, so the minimum is immune to it.
Corrected capture times ``t_ns + min d`` of all motes are on the server's clock and directly
comparable.

Packets join the pending frame whose anchor (first packet's corrected time) is within
``group_tolerance`` frame periods and which has no packet from that mote yet. A frame is
emitted when every live mote has contributed, or at its deadline (arrival clock):
``anchor + tolerance + max_wait``. A mote silent for ``dead_after_ms`` or reported gone is
not waited for, so a dead mote never stalls the stream (a frame whose instant came before the
report still waits for it up to its deadline: the mote's last packets may be behind it).
Packets for frames already emitted are counted as late and dropped; a packet whose sequence
number was already seen recently (``dedup_window`` packets of that mote) is counted as a
duplicate and dropped.

Clock drift (a mote's crystal running fast or slow, up to a few hundred ppm) is estimated per
mote from the lower envelope of the delays over the last ``drift_window_s`` (see
:class:`_Drift`): ``drift_ppm = -slope * 1e6`` (positive = the mote's clock runs fast). The 4 s offset window already follows a 200 ppm drift to within
0.8 ms, so grouping does not need the drift; it is reported (with the offset) so an operator
sees a mote whose clock misbehaves. All decisions depend only on the sequence of
(packet, arrival time) inputs, so a replay of the same inputs gives the same frames.
"""

from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SyncConfig:
    """Frame grouping parameters (``[sync]`` in configs/server.toml)."""

    fps: float = 60.0  #: nominal mote frame rate, sets the grouping tolerance
    group_tolerance: float = 0.5  #: frame periods within which packets join one frame
    max_wait_ms: float = 12.0  #: extra wait for late/jittered packets after the frame's window
    offset_window_s: float = 4.0  #: sliding window of the per-mote minimum-delay filter
    dead_after_ms: float = 250.0  #: a mote silent this long is not waited for
    restart_seq_gap: int = 30  #: a backwards seq jump larger than this = mote restarted
    dedup_window: int = 256  #: recent seqs remembered per mote to recognise duplicates
    drift_block_s: float = 0.1  #: arrival-time block whose minimum delay is one drift sample
    drift_window_s: float = 60.0  #: drift fitted over this many seconds of blocks (>= 5 s needed)

    def __post_init__(self) -> None:
        if self.fps <= 0 or not 0 < self.group_tolerance <= 1 or self.max_wait_ms < 0:
            raise ValueError(f"invalid sync config {self}")

    @property
    def period_ns(self) -> int:
        return int(round(1e9 / self.fps))


@dataclass
class SyncPacket:
    """One packet entering the synchroniser; ``payload`` is passed through untouched."""

    mote_id: str
    seq: int
    t_ns: int
    arrival_ns: int
    payload: Any = None
    tc_ns: int = 0  #: corrected capture time (server clock), set by the synchroniser


@dataclass
class Frame:
    """Packets of one capture instant: ``packets`` by mote id; ``t_ns`` mean corrected time."""

    t_ns: int
    packets: dict[str, SyncPacket]
    complete: bool
    missing: tuple[str, ...] = ()


@dataclass
class MoteSyncStats:
    """Per-mote counters and clock estimates."""

    received: int = 0
    late: int = 0  #: dropped: its frame was already emitted
    duplicate: int = 0  #: dropped: seq already seen
    restarts: int = 0  #: came back after a silence or a seq reset (clock estimate reset)
    missing: int = 0  #: frames emitted without this mote while it was alive (degraded frames)
    offset_ns: int = 0  #: minimum delay arrival - capture (ns) = -(clock offset) + min latency
    drift_ppm: float = float("nan")  #: clock rate error, + = mote clock fast (NaN until known)
    last_arrival_ns: int = 0

    @property
    def clock_offset_ms(self) -> float:
        """Mote clock minus server clock (ms), up to the minimum transport latency."""
        return -self.offset_ns / 1e6


@dataclass
class _Pending:
    anchor: int
    packets: dict[str, SyncPacket] = field(default_factory=dict)


class _MinDelay:
    """Sliding-window minimum of (arrival - capture) over the last ``window_ns``."""

    def __init__(self, window_ns: int):
        self.window_ns = window_ns
        self.q: deque[tuple[int, int]] = deque()  # (arrival, delay), delays increasing

    def add(self, arrival: int, delay: int) -> int:
        while self.q and self.q[-1][1] >= delay:
            self.q.pop()
        self.q.append((arrival, delay))
        while self.q[0][0] < arrival - self.window_ns:
            self.q.popleft()
        return self.q[0][1]


class _Drift:
    """Clock drift from the lower envelope of the delays (Moon, Skelly & Towsley, "Estimation
    and removal of clock skew from network delay measurements", 1999): the minimum delay of
    each ``block_ns`` block of arrival time is kept for the window; the drift is the slope of
    the line under all of them closest to them in the mean (the edge of their lower convex
    hull that spans their mean time), which jitter cannot bias. Computed on demand."""

    def __init__(self, block_ns: int, n_blocks: int):
        self.block_ns = block_ns
        self.blocks: deque[tuple[int, int]] = deque(maxlen=max(n_blocks, 10))  # (block index, min delay)
        self._cur: int | None = None
        self._cur_min = 0

    def add(self, arrival: int, delay: int) -> None:
        b = arrival // self.block_ns
        if self._cur is None or b != self._cur:
            if self._cur is not None:
                self.blocks.append((self._cur, self._cur_min))
            self._cur, self._cur_min = b, delay
        else:
            self._cur_min = min(self._cur_min, delay)

    @property
    def ppm(self) -> float:
        """Drift in ppm (+ = the mote's clock runs fast); NaN before 5 s of blocks."""
        try:
            pts = list(self.blocks)
        except RuntimeError:  # pragma: no cover - mutated concurrently; next time
            return float("nan")
        if len(pts) < 2 or (pts[-1][0] - pts[0][0]) * self.block_ns < 5e9:
            return float("nan")
        b0, d0 = pts[0]
        xy = [(float((b - b0) * self.block_ns), float(d - d0)) for b, d in pts]
        hull: list[tuple[float, float]] = []
        for p in xy:  # lower hull, x increasing
            while len(hull) >= 2 and ((hull[-1][0] - hull[-2][0]) * (p[1] - hull[-2][1])
                                      - (hull[-1][1] - hull[-2][1]) * (p[0] - hull[-2][0])) <= 0:
                hull.pop()
            hull.append(p)
        xm = sum(x for x, _ in xy) / len(xy)
        for (x1, y1), (x2, y2) in zip(hull, hull[1:]):
            if x1 <= xm <= x2 and x2 > x1:
                return -(y2 - y1) / (x2 - x1) * 1e6
        return float("nan")


class FrameSync:
    """Turn a stream of packets from several motes into frames (see the module docstring)."""

    def __init__(self, config: SyncConfig | None = None):
        self.config = config or SyncConfig()
        c = self.config
        self._tol = int(c.group_tolerance * c.period_ns)
        self._wait = int(c.max_wait_ms * 1e6)
        self._dead = int(c.dead_after_ms * 1e6)
        self._pending: list[_Pending] = []
        self._delay: dict[str, _MinDelay] = {}
        self._last_seq: dict[str, int] = {}
        self._seen: dict[str, tuple[set[int], deque[int]]] = {}  # recent seqs per mote
        self._drift: dict[str, _Drift] = {}
        self._gone: dict[str, int] = {}  # mote -> time it left (arrival clock)
        self.motes: dict[str, MoteSyncStats] = {}
        self.now_ns = 0
        self.last_anchor: int | None = None
        self._last_t = -(2**62)
        self.frames_emitted = 0
        self.frames_incomplete = 0

    # ------------------------------------------------------------------ inputs
    def mote_joined(self, mote_id: str, now_ns: int | None = None) -> None:
        """A mote (re)appeared: wait for it from now on; forget its clock estimate."""
        if now_ns is not None:
            self.now_ns = max(self.now_ns, now_ns)
        st = self.motes.setdefault(mote_id, MoteSyncStats())
        if st.received:
            st.restarts += 1
        st.last_arrival_ns = max(st.last_arrival_ns, self.now_ns)
        self._gone.pop(mote_id, None)
        self._forget(mote_id)

    def _forget(self, mote_id: str) -> None:
        """Reset a mote's clock estimates and seq history (it restarted)."""
        self._delay.pop(mote_id, None)
        self._drift.pop(mote_id, None)
        self._last_seq.pop(mote_id, None)
        self._seen.pop(mote_id, None)

    def mote_left(self, mote_id: str, t_ns: int | None = None) -> list[Frame]:
        """A mote is gone (at ``t_ns``): stop waiting for it; returns frames now complete."""
        self._gone[mote_id] = self.now_ns if t_ns is None else t_ns
        return self._emit_ready()

    def push(self, p: SyncPacket) -> list[Frame]:
        """Add one packet; returns the frames that are ready, oldest first."""
        out = self.poll(p.arrival_ns)
        st = self.motes.setdefault(p.mote_id, MoteSyncStats())
        silent = st.received > 0 and p.arrival_ns - st.last_arrival_ns > self._dead
        st.received += 1
        st.last_arrival_ns = p.arrival_ns
        self._gone.pop(p.mote_id, None)
        last = self._last_seq.get(p.mote_id)
        # a seq going back = the mote restarted (new clock, perhaps); a silence with the seq
        # going on = packets lost on the way (a network outage): the clock estimates stay
        if last is not None and (p.seq < last - self.config.restart_seq_gap or (silent and p.seq <= last)):
            st.restarts += 1
            log.info("mote %s is back (seq %d after %d): clock estimate reset", p.mote_id, p.seq, last)
            self._forget(p.mote_id)
            last = None
        seen, order = self._seen.setdefault(p.mote_id, (set(), deque()))
        if p.seq in seen:
            st.duplicate += 1
            return out
        seen.add(p.seq)
        order.append(p.seq)
        if len(order) > self.config.dedup_window:
            seen.discard(order.popleft())
        self._last_seq[p.mote_id] = p.seq if last is None else max(last, p.seq)
        est = self._delay.get(p.mote_id)
        if est is None:
            est = self._delay[p.mote_id] = _MinDelay(int(self.config.offset_window_s * 1e9))
        delay = p.arrival_ns - p.t_ns
        st.offset_ns = est.add(p.arrival_ns, delay)
        drift = self._drift.get(p.mote_id)
        if drift is None:
            c = self.config
            drift = self._drift[p.mote_id] = _Drift(int(c.drift_block_s * 1e9),
                                                    int(round(c.drift_window_s / c.drift_block_s)))
        drift.add(p.arrival_ns, delay)
        p.tc_ns = p.t_ns + st.offset_ns
        if self.last_anchor is not None and p.tc_ns <= self.last_anchor + self._tol:
            st.late += 1
            return out
        best, best_d = None, None
        for fr in self._pending:
            d = abs(fr.anchor - p.tc_ns)
            if d <= self._tol and p.mote_id not in fr.packets and (best_d is None or d < best_d):
                best, best_d = fr, d
        if best is None:
            best = _Pending(p.tc_ns)
            i = len(self._pending)
            while i > 0 and self._pending[i - 1].anchor > best.anchor:
                i -= 1
            self._pending.insert(i, best)
        best.packets[p.mote_id] = p
        return out + self._emit_ready()

    def poll(self, now_ns: int) -> list[Frame]:
        """Advance the clock to ``now_ns`` (arrival clock); returns frames now due."""
        self.now_ns = max(self.now_ns, now_ns)
        return self._emit_ready()

    def flush(self) -> list[Frame]:
        """Emit every pending frame (end of stream)."""
        out = [self._emit(fr) for fr in self._pending]
        self._pending = []
        return out

    def update_drift(self) -> None:
        """Compute every mote's ``drift_ppm`` now (a few ms: call it for reports, not per packet)."""
        for m, st in list(self.motes.items()):
            d = self._drift.get(m)
            st.drift_ppm = d.ppm if d is not None else float("nan")

    # ------------------------------------------------------------------ internals
    def alive(self) -> list[str]:
        """Motes currently waited for: heard within ``dead_after_ms`` and not reported gone."""
        return sorted(self._heard() - self._gone.keys())

    def _heard(self) -> set[str]:
        """Motes heard within ``dead_after_ms``."""
        return {m for m, st in self.motes.items() if self.now_ns - st.last_arrival_ns <= self._dead}

    def _emit_ready(self) -> list[Frame]:
        if not self._pending:
            return []
        heard = self._heard()
        alive = heard - self._gone.keys()
        # a mote reported gone after a frame's instant is still waited for there, up to the
        # frame's deadline: its last packets may be on their way behind the report (Zenoh
        # delivers liveliness and data on separate paths; under load a mote's leave reached the
        # server before its last packet, which was then dropped as late, and a replay that
        # delivered them the other way round grouped that frame otherwise)
        left = {m: self._gone[m] for m in heard & self._gone.keys()}
        ready = 0
        # strictly in order: a complete frame never releases an older incomplete one early,
        # whose packets may still be on their way (network jitter larger than a frame period)
        for fr in self._pending:
            wait = alive | {m for m, g in left.items() if g > fr.anchor}
            if fr.anchor + self._tol + self._wait <= self.now_ns or wait <= fr.packets.keys():
                ready += 1
            else:
                break
        out = [self._emit(fr, alive) for fr in self._pending[:ready]]
        del self._pending[:ready]
        return out

    def _emit(self, fr: _Pending, alive: set[str] | None = None) -> Frame:
        # "missing" is judged at the frame's own time, so it does not depend on when the
        # frame happened to be emitted (live idle polls vs replay)
        alive = {m for m, st in self.motes.items()
                 if self._gone.get(m, fr.anchor + 1) > fr.anchor and fr.anchor - st.last_arrival_ns <= self._dead}
        missing = tuple(sorted(alive - fr.packets.keys()))
        t = sum(p.tc_ns for p in fr.packets.values()) // len(fr.packets)
        t = max(t, self._last_t + 1)
        self._last_t = t
        self.last_anchor = fr.anchor if self.last_anchor is None else max(self.last_anchor, fr.anchor)
        self.frames_emitted += 1
        if missing:
            self.frames_incomplete += 1
            for m in missing:
                self.motes[m].missing += 1
        return Frame(t, dict(sorted(fr.packets.items())), not missing, missing)
