"""What is in a take (motes, frames, drops, rates, duration) and its recorded poses as arrays;
the command line is ``samba-inspect`` (:mod:`samba_server.cli.inspect`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from samba_common.pose_wire import PoseError, decode_pose, stack_bounds
from samba_common.wire import PacketError, decode_packet

from .record import CALIBRATION_TOPIC, EVENTS_TOPIC, POSE_TOPIC, TakeReader


@dataclass
class MoteSummary:
    """Per mote: packets, undecodable packets, seq gaps (packets lost before recording), times."""

    packets: int = 0
    bad: int = 0
    lost: int = 0
    first_ns: int = 0
    last_ns: int = 0
    _last_seq: int | None = None

    @property
    def rate(self) -> float:
        span = (self.last_ns - self.first_ns) / 1e9
        return (self.packets - 1) / span if span > 0 else 0.0


@dataclass
class TakeSummary:
    """Everything samba-inspect reports; poses as arrays for export."""

    path: Path
    motes: dict[str, MoteSummary] = field(default_factory=dict)
    poses: list = field(default_factory=list)
    bad_poses: int = 0
    events: int = 0
    has_calibration: bool = False
    first_ns: int = 0
    last_ns: int = 0
    truncated: bool = False
    error: str = ""

    @property
    def duration(self) -> float:
        return max(self.last_ns - self.first_ns, 0) / 1e9


def summarize(path: str | Path) -> TakeSummary:
    """Read the whole take (tolerating a truncated tail)."""
    s = TakeSummary(Path(path))
    reader = TakeReader(path)
    for m in reader:
        mote = m.mote_id
        if m.log_time and (mote is not None or m.topic == POSE_TOPIC):
            # the take's span: packets and poses (the calibration and events may be stamped
            # when the server started, long before or on another clock than the capture)
            s.first_ns = m.log_time if not s.first_ns else min(s.first_ns, m.log_time)
            s.last_ns = max(s.last_ns, m.log_time)
        if mote is not None:
            ms = s.motes.setdefault(mote, MoteSummary(first_ns=m.log_time))
            ms.packets += 1
            ms.last_ns = m.log_time
            try:
                pkt = decode_packet(m.data)
            except PacketError:
                ms.bad += 1
                continue
            if ms._last_seq is not None and 0 < pkt.seq - ms._last_seq < 10_000:
                ms.lost += pkt.seq - ms._last_seq - 1
            ms._last_seq = pkt.seq
        elif m.topic == POSE_TOPIC:
            try:
                s.poses.append(decode_pose(m.data))
            except PoseError:
                s.bad_poses += 1
        elif m.topic == EVENTS_TOPIC:
            s.events += 1
        elif m.topic == CALIBRATION_TOPIC:
            s.has_calibration = True
    s.truncated, s.error = reader.truncated, reader.error
    return s


def report(s: TakeSummary) -> str:
    lines = [f"{s.path}: {s.duration:.2f} s" + (f" (truncated: {s.error})" if s.truncated else ""),
             f"calibration: {'yes' if s.has_calibration else 'no'}; mote events: {s.events}"]
    for mote, ms in sorted(s.motes.items()):
        lines.append(f"  mote {mote}: {ms.packets} packets, {ms.rate:.1f}/s, {ms.lost} lost before recording "
                     f"(seq gaps), {ms.bad} undecodable")
    solved = sum(p.solved for p in s.poses)
    lat = [p.latency_ms for p in s.poses if np.isfinite(p.latency_ms)]
    if lat and max(abs(np.percentile(lat, 1)), abs(np.percentile(lat, 99))) > 3.6e6:
        # over an hour: capture and arrival stamps on different clocks (e.g. an old samba-process take)
        lines.append("latency: not meaningful, capture and arrival times are on different clocks")
        lat = []
    rate = (len(s.poses) - 1) / ((s.poses[-1].t_ns - s.poses[0].t_ns) / 1e9) if len(s.poses) > 1 and \
        s.poses[-1].t_ns > s.poses[0].t_ns else 0.0
    lines.append(f"poses: {len(s.poses)} frames ({rate:.1f}/s), {solved} solved, {s.bad_poses} undecodable"
                 + (f", latency p50 {np.percentile(lat, 50):.1f} ms p99 {np.percentile(lat, 99):.1f} ms" if lat else ""))
    return "\n".join(lines)


def pose_arrays(s: TakeSummary) -> tuple[np.ndarray, np.ndarray, dict]:
    """(F, 13, 3) joints, (F,) seconds from the first pose, extras."""
    if not s.poses:
        return np.zeros((0, 13, 3)), np.zeros(0), {}
    t0 = s.poses[0].t_ns
    joints = np.stack([p.joints for p in s.poses])
    t = np.array([(p.t_ns - t0) / 1e9 for p in s.poses])
    markers = np.stack([p.markers if p.markers is not None else np.full((8, 3), np.nan) for p in s.poses])
    return joints, t, {"markers": markers, "residual": np.array([p.residual_m for p in s.poses]),
                       "latency_ms": np.array([p.latency_ms for p in s.poses]),
                       "joint_bound": stack_bounds(s.poses),
                       "t_ns": np.array([p.t_ns for p in s.poses], dtype=np.int64)}
