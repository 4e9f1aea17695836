"""The mote's capture loop: source -> MotePipeline -> transport (+ MCAP copy, status, preview).

Used by the ``samba-mote`` CLI and by tests. The loop never busy-waits (a live source blocks
in ``read()``, file/sim sources pace themselves or run flat out), survives a source that
fails (closed and reopened with backoff: camera unplugged and back; a missing file raises
:class:`~samba_mote.sources.SourceGone` at once instead) and a transport that
fails (see :class:`samba_mote.transports.Resilient`), and stops at the end of a finite
source, after ``max_frames``, or when ``stop`` is set (SIGINT/SIGTERM in the CLI).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from samba_common.wire import MoteStatus, encode_packet, encode_status

from .pipeline import MotePipeline
from .sources import Source, SourceError, SourceGone

log = logging.getLogger(__name__)


@dataclass
class RunStats:
    """What a run did (the CLI prints it on exit)."""

    frames: int = 0
    packets_sent: int = 0
    dropped_frames: int = 0  #: capture gaps longer than 1.5 frame periods
    send_failures: int = 0
    source_errors: int = 0
    reopen_count: int = 0
    detect_us: list[float] = field(default_factory=list)
    seconds: float = 0.0
    end_reason: str = ""

    def summary(self) -> str:
        d = np.asarray(self.detect_us[-10000:]) if self.detect_us else np.zeros(1)
        fps = self.frames / self.seconds if self.seconds > 0 else 0.0
        return (f"{self.frames} frames in {self.seconds:.1f} s ({fps:.1f} fps), {self.packets_sent} packets sent, "
                f"{self.send_failures} send failures, {self.dropped_frames} dropped frames, "
                f"{self.source_errors} source errors ({self.reopen_count} reopens), detection+tracking "
                f"median {np.median(d):.0f} us p95 {np.percentile(d, 95):.0f} us; ended: {self.end_reason}")


class MoteRunner:
    """Runs one mote. ``open_source``: a callable returning a Source (called again to reopen);
    ``transport``: anything with send_markers/send_status (ideally ``Resilient``)."""

    def __init__(self, open_source: Callable[[], Source], pipeline: MotePipeline, transport,
                 recorder=None, status_period: float = 1.0, preview_dir: str | os.PathLike | None = None,
                 preview_every: int = 30, max_frames: int | None = None, reopen_backoff: float = 0.5,
                 max_reopen_backoff: float = 10.0, source_label: str = "") -> None:
        self.open_source = open_source
        self.pipeline = pipeline
        self.transport = transport
        self.recorder = recorder
        self.status_period = status_period
        self.preview_dir = Path(preview_dir) if preview_dir else None
        self.preview_every = preview_every
        self.max_frames = max_frames
        self.reopen_backoff, self.max_reopen_backoff = reopen_backoff, max_reopen_backoff
        self.source_label = source_label
        self.stats = RunStats()

    def _status(self, t0_wall: float, cpu0: float, frames0: int, now: float) -> MoteStatus:
        cpu = sum(os.times()[:2])
        dt = max(now - t0_wall, 1e-6)
        recent = self.stats.detect_us[-max(self.stats.frames - frames0, 1):] or [0.0]
        return MoteStatus(self.pipeline.mote_id, time.time_ns(), fps=(self.stats.frames - frames0) / dt,
                          frames=self.stats.frames, dropped=self.stats.dropped_frames,
                          detect_us=float(np.mean(recent)), cpu_load=(cpu - cpu0) / dt,
                          n_blobs=float(self.pipeline.last_blobs), source=self.source_label,
                          send_errors=self.stats.send_failures)

    def _send(self, kind: str, payload: bytes, t_ns: int) -> None:
        ok = self.transport.send_markers(payload) if kind == "markers" else self.transport.send_status(payload)
        if ok is False:
            self.stats.send_failures += 1
        elif kind == "markers":
            self.stats.packets_sent += 1
        if self.recorder is not None:
            try:
                self.recorder.record(kind, payload, t_ns)
            except Exception as exc:
                log.warning("recording failed: %s", exc)

    def run(self, stop: threading.Event | None = None) -> RunStats:
        stop = stop or threading.Event()
        st = self.stats
        start = time.monotonic()
        source: Source | None = None
        backoff = self.reopen_backoff
        last_t: int | None = None
        period_ns: float | None = None
        st_t0, st_cpu0, st_f0 = time.monotonic(), sum(os.times()[:2]), 0
        if self.preview_dir:
            self.preview_dir.mkdir(parents=True, exist_ok=True)
        try:
            while not stop.is_set():
                if self.max_frames is not None and st.frames >= self.max_frames:
                    st.end_reason = "max frames"
                    break
                if source is None:
                    try:
                        source = self.open_source()
                        period_ns = 1e9 / source.fps if getattr(source, "fps", 0) else None
                        backoff = self.reopen_backoff
                    except SourceGone:  # a missing file will not appear: no retry
                        st.source_errors += 1
                        raise
                    except (SourceError, OSError) as exc:
                        st.source_errors += 1
                        log.warning("source unavailable (%s); retrying in %.1f s", exc, backoff)
                        stop.wait(backoff)
                        backoff = min(backoff * 2, self.max_reopen_backoff)
                        continue
                try:
                    item = source.read()
                except (SourceError, OSError) as exc:
                    st.source_errors += 1
                    st.reopen_count += 1
                    log.warning("source failed (%s); reopening", exc)
                    source.close()
                    source = None
                    stop.wait(backoff)
                    continue
                if item is None:
                    st.end_reason = "source ended"
                    break
                t_ns, frame = item
                if last_t is not None and period_ns and t_ns - last_t > 1.5 * period_ns:
                    st.dropped_frames += int(round((t_ns - last_t) / period_ns)) - 1
                last_t = t_ns
                try:
                    pkt = self.pipeline.process(t_ns, frame)
                except ValueError as exc:  # malformed frame: count and skip
                    st.source_errors += 1
                    log.warning("bad frame skipped: %s", exc)
                    continue
                st.frames += 1
                st.detect_us.append(self.pipeline.last_detect_us)
                if len(st.detect_us) > 20000:
                    del st.detect_us[:10000]
                self._send("markers", encode_packet(pkt), t_ns)
                if self.preview_dir and st.frames % self.preview_every == 1:
                    self._preview(frame, pkt)
                now = time.monotonic()
                if now - st_t0 >= self.status_period:
                    s = self._status(st_t0, st_cpu0, st_f0, now)
                    self._send("status", encode_status(s), s.t_ns)
                    st_t0, st_cpu0, st_f0 = now, sum(os.times()[:2]), st.frames
            else:
                st.end_reason = "stopped"
            if st.frames > st_f0:  # a last status, so even a run shorter than status_period reports
                now = time.monotonic()
                s = self._status(st_t0, st_cpu0, st_f0, now)
                self._send("status", encode_status(s), s.t_ns)
        finally:
            if source is not None:
                source.close()
            st.seconds = time.monotonic() - start
        return st

    def _preview(self, frame: np.ndarray, pkt) -> None:
        import cv2

        img = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
        for lab, (u, v), fl in zip(pkt.labels, pkt.uv, pkt.flags):
            if not np.isfinite(u):
                continue
            colour = (0, 255, 0) if lab < 8 else (0, 0, 255)
            cv2.circle(img, (int(round(u)), int(round(v))), 4, colour, 1)
            if lab < 8:
                cv2.putText(img, str(int(lab)), (int(u) + 4, int(v) - 4), cv2.FONT_HERSHEY_PLAIN, 0.7, colour, 1)
        path = self.preview_dir / f"{self.pipeline.mote_id}_{pkt.seq:08d}.png"
        cv2.imwrite(str(path), img)
