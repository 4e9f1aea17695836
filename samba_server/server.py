"""The Samba server core: ingest -> sync -> label (3D points named as markers) -> solve -> publish.

:class:`Server` has no network code. Transports call :meth:`Server.ingest` (thread-safe; it
stamps the arrival time, records the raw packet and queues it) and
:meth:`Server.mote_event`; the processing loop (:meth:`Server.run` in a thread, or
:meth:`Server.process_pending` from the caller) handles the queue strictly in order. Every
decision depends only on the queued items and their arrival stamps, so feeding a recorded
take back through :meth:`ingest` with the recorded stamps reproduces the live poses exactly
(:mod:`samba_server.replay`). The Zenoh wiring lives in :mod:`samba_server.live`.
"""

from __future__ import annotations

import json
import logging
from array import array
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from samba_common.calib import CameraRig
from samba_common.pose_wire import (FLAG_INCOMPLETE, FLAG_LABEL_OVERRIDDEN, FLAG_LABEL_RENAMED, FLAG_SOLVE_SKIPPED,
                                    FLAG_SOLVED, PoseMessage, encode_pose)
from samba_common.skeleton import MARKER_JOINT, N_JOINTS, N_MARKERS
from samba_common.wire import PacketError, decode_packet

from .record import Recorder
from .labelling import LabelConfig, Labeller, LabelQuality, marker_bits
from .recon.bounds import mirrored_legs, mirrored_pairs, mirrored_wrists
from .sync import FrameSync, SyncConfig, SyncPacket
from .triangulate import TriangulateConfig, Triangulator

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ServerConfig:
    """``[server]`` settings."""

    queue_size: int = 8192  #: packets waiting for processing; beyond it packets are dropped (counted)
    idle_poll_ms: float = 2.0  #: processing loop wake-up when no packet arrives
    keep_history: bool = True  #: keep every pose (for --export and tests)
    drop_merged: bool = True  #: blobs flagged merged are treated as unseen
    max_lag_ms: float = 0.0  #: live only: skip the skeleton solve of frames older than this (0 = never)


@dataclass
class ServerStats:
    """Counters of one server run (all monotonically increasing)."""

    packets: int = 0
    bad_packets: int = 0
    unknown_motes: int = 0
    queue_overflow: int = 0
    frames: int = 0
    solved: int = 0
    labels_overridden: int = 0
    solve_skipped: int = 0
    label_errors: int = 0  #: frames whose labelling raised (logged; the frame is output unnamed)
    mote_packets: dict[str, int] = field(default_factory=dict)
    #: latency of the last poses (ms), the newest 50 000..100 000 kept; a compact array('d')
    #: (8 bytes a pose) so that a long session's memory stays flat
    latency_ms: array = field(default_factory=lambda: array("d"))


PublishFn = Callable[[PoseMessage], None]


class Server:
    """See the module docstring. ``reconstructor``: an object with ``solve(markers (8,3), t)``
    returning ``.joints`` (13,3), ``.residual``, ``.n_markers`` (or None: markers only)."""

    def _marker_view(self, joints: np.ndarray) -> np.ndarray:
        """Joints (13, 3) for the labeller's predictions: with skin-marker offsets the marker
        joints are replaced by the model markers (joint centre + offset), otherwise unchanged."""
        markers_of = getattr(self.reconstructor, "markers_of", None)
        offsets = getattr(self.reconstructor, "offsets", None)
        if markers_of is None or offsets is None or not np.any(offsets):
            return joints
        view = joints.copy()
        view[list(MARKER_JOINT)] = markers_of(joints)
        return view

    def __init__(self, rig: CameraRig, calibration_toml: bytes | None = None, reconstructor=None,
                 config: ServerConfig | None = None, sync_config: SyncConfig | None = None,
                 tri_config: TriangulateConfig | None = None, label_config: LabelConfig | None = None,
                 recorder: Recorder | None = None, publish: PublishFn | None = None,
                 clock: Callable[[], int] = time.time_ns):
        self.rig = rig
        self.calibration_toml = calibration_toml if calibration_toml is not None else rig.dumps().encode()
        self.config = config or ServerConfig()
        self.sync = FrameSync(sync_config)
        self.triangulator = Triangulator(rig, tri_config)
        db = getattr(reconstructor, "db", None)
        self.labeller = Labeller(rig, self.triangulator, label_config,
                                 prior_lengths=None if db is None else db.mean_lengths)
        self.labeller.pose_fit = getattr(reconstructor, "body_distance", None)
        self.reconstructor = reconstructor
        self.recorder = recorder
        self.publish = publish
        self.clock = clock
        self.stats = ServerStats()
        self.poses: list[PoseMessage] = []
        self._cam_index = {name: i for i, name in enumerate(rig.names)}
        self._queue: queue.Queue = queue.Queue(self.config.queue_size)
        self._lock = threading.Lock()
        self._seq = 0
        self._ingested = 0
        self.last_arrival_ns = 0
        self._t0_ns: int | None = None
        self._unknown_logged: set[str] = set()
        self._subject_version = getattr(reconstructor, "subject_version", 0)
        #: callables(MarkerPacket) called with every decoded packet (e.g. the viewer's blobs)
        self.packet_listeners: list[Callable] = []
        #: callables(PoseMessage) called with every pose after ``publish``
        self.pose_listeners: list[Callable] = []
        #: (8, 3) world m: the last frame's names before the output left unseparated wrists
        #: unnamed (:meth:`Labeller.unseparated`); what the solver and samba-process's two-way pass
        #: use. The markers named here and unnamed in the pose are those wrists.
        self.last_named = np.full((8, 3), np.nan)
        #: replay: pose seqs whose solve the live server skipped (recorded FLAG_SOLVE_SKIPPED).
        #: When set (a replay), the recording's decisions replace the wall-clock ones: the lag
        #: test, and the idle release of frames (see :meth:`process_pending`)
        self.skip_seqs: set[int] | None = None
        self._queued = self._handled = 0  # items (packets, joins, leaves) queued and handled
        if recorder is not None:
            recorder.write_calibration(self.calibration_toml, clock())

    # ------------------------------------------------------------------ subject
    @property
    def subject(self):
        """The subject (samba_common.subject.Subject) the solver uses now, or None (not known yet)."""
        return getattr(self.reconstructor, "subject", None)

    def _record_subject(self, recorder: Recorder, t_ns: int) -> None:
        """Write the current subject into ``recorder``: an event on /events (with the first pose
        seq solved with it) and the MCAP metadata record ``samba.subject``."""
        subject = self.subject
        if subject is None:
            return
        toml = subject.to_toml()
        ev = {"event": "subject", "t_ns": int(t_ns), "seq": self._seq, "subject_toml": toml}
        recorder.write_event(json.dumps(ev).encode(), int(t_ns))
        recorder.write_metadata("samba.subject", {"subject_toml": toml, "seq": str(self._seq),
                                                  "placement": subject.placement})

    def _check_subject(self, t_ns: int) -> None:
        """After a solve: a subject measured live (or refined) is logged and recorded."""
        version = getattr(self.reconstructor, "subject_version", 0)
        if version == self._subject_version:
            return
        self._subject_version = version
        log.info("subject in use from pose %d: %s", self._seq, self.subject.placement if self.subject else None)
        recorder = self.recorder
        if recorder is not None:
            self._record_subject(recorder, t_ns)

    # ------------------------------------------------------------------ thread-safe inputs
    def ingest(self, mote_id: str, payload: bytes, arrival_ns: int | None = None) -> bool:
        """Queue one raw marker packet from ``mote_id`` (any thread). False if dropped."""
        with self._lock:
            t = self.clock() if arrival_ns is None else int(arrival_ns)
            self.last_arrival_ns = t
            if self.recorder is not None:
                self.recorder.write_packet(mote_id, payload, t, seq=self._ingested)
            self._ingested += 1
            try:
                self._queue.put_nowait(("packet", mote_id, payload, t))
            except queue.Full:
                self.stats.queue_overflow += 1
                return False
            self._queued += 1
            return True

    def mote_event(self, mote_id: str, joined: bool, t_ns: int | None = None) -> None:
        """A mote's liveliness token appeared (joined) or vanished (any thread)."""
        with self._lock:
            t = self.clock() if t_ns is None else int(t_ns)
            if self.recorder is not None:
                ev = {"mote_id": mote_id, "event": "join" if joined else "leave", "t_ns": t}
                self.recorder.write_event(json.dumps(ev).encode(), t)
            self._queue.put(("join" if joined else "leave", mote_id, b"", t))
            self._queued += 1

    @property
    def backlog(self) -> int:
        """Items (packets, joins, leaves) taken in and not yet fully handled (any thread)."""
        with self._lock:
            return self._queued - self._handled

    # ------------------------------------------------------------------ processing
    def process_pending(self, timeout: float | None = None, stop: threading.Event | None = None) -> list[PoseMessage]:
        """Handle every queued item in order (waiting up to ``timeout`` s for the first).

        When the queue is empty, advance the sync clock to now so that frames waiting for a
        dead mote are released (only packets stamped later than now can still arrive). Not in
        a replay (``skip_seqs`` set): its frames are released by their recorded stamps, leaves
        and ``finish``, as in an in-process replay, never by a wall clock that a server running
        behind the replay lets overtake them.
        """
        out: list[PoseMessage] = []
        try:
            item = self._queue.get(timeout=timeout) if timeout else self._queue.get_nowait()
        except queue.Empty:
            item = None
        while item is not None:
            try:
                out += self._handle(item)
            finally:
                self._handled += 1
            if stop is not None and stop.is_set():
                return out
            try:
                item = self._queue.get_nowait()
            except queue.Empty:
                item = None
        if timeout and self.skip_seqs is None:
            with self._lock:
                if self._queue.empty():
                    now = self.clock()
                else:
                    now = None
            if now is not None:
                out += [self._frame(f) for f in self.sync.poll(now)]
        return out

    def run(self, stop: threading.Event) -> None:
        """Processing loop until ``stop`` is set; never raises on bad data."""
        wait = self.config.idle_poll_ms / 1000.0
        while not stop.is_set():
            try:
                self.process_pending(timeout=wait, stop=stop)
            except Exception:  # a bug must not kill the live stream: log it and go on
                log.exception("processing error (frame skipped)")

    def finish(self) -> list[PoseMessage]:
        """Process what is queued, then emit every pending frame (end of stream)."""
        out = self.process_pending()
        out += [self._frame(f) for f in self.sync.flush()]
        return out

    def _handle(self, item) -> list[PoseMessage]:
        kind, mote_id, payload, t = item
        if kind == "join":
            log.info("mote %s joined", mote_id)
            self.sync.mote_joined(mote_id, t)
            return []
        if kind == "leave":
            log.info("mote %s left", mote_id)
            return [self._frame(f) for f in self.sync.mote_left(mote_id, t)]
        self.stats.packets += 1
        try:
            pkt = decode_packet(payload)
        except PacketError as exc:
            self.stats.bad_packets += 1
            log.debug("bad packet from %s dropped: %s", mote_id, exc)
            return [self._frame(f) for f in self.sync.poll(t)]
        if pkt.mote_id not in self._cam_index:
            self.stats.unknown_motes += 1
            if pkt.mote_id not in self._unknown_logged:
                self._unknown_logged.add(pkt.mote_id)
                log.warning("packets from mote %r, which is not in the calibration (%s): dropped",
                            pkt.mote_id, ", ".join(self.rig.names))
            return [self._frame(f) for f in self.sync.poll(t)]
        self.stats.mote_packets[pkt.mote_id] = self.stats.mote_packets.get(pkt.mote_id, 0) + 1
        for fn in self.packet_listeners:
            try:
                fn(pkt)
            except Exception:
                log.exception("packet listener failed")
        frames = self.sync.push(SyncPacket(pkt.mote_id, pkt.seq, pkt.t_ns, t, pkt))
        return [self._frame(f) for f in frames]

    def markers_for(self, frame, t: float) -> tuple[np.ndarray, int, LabelQuality]:
        """The named markers of a frame at t seconds: ((8, 3) world m, NaN = not named, marker
        mask, label quality). Every mote's blobs, labelled or not, become 3D points that the
        labelling stage names against the predicted body (:mod:`samba_server.labelling`)."""
        packets = [None] * len(self.rig.names)
        for mote_id, sp in frame.packets.items():
            packets[self._cam_index[mote_id]] = sp.payload
        return self.label_packets(packets, t)

    def label_packets(self, packets: list, t: float) -> tuple[np.ndarray, int, LabelQuality]:
        """:meth:`markers_for` on packets: per camera (rig order) a MarkerPacket or None."""
        if self.reconstructor is not None:
            self.labeller.set_lengths(getattr(self.reconstructor, "lengths", None),
                                      getattr(self.reconstructor, "offsets", None))
        try:
            pts, quality = self.labeller.label(packets, t)
        except Exception:  # a labelling bug costs this frame's names, not the take (offline) or the stream
            self.stats.label_errors += 1
            if self.stats.label_errors <= 3 or self.stats.label_errors % 100 == 0:
                log.exception("labelling failed on the frame at t=%.3f s (%d frames so far): frame left unnamed",
                              t, self.stats.label_errors)
            return np.full((N_MARKERS, 3), np.nan), 0, LabelQuality(mode="lost")
        mask = marker_bits(np.isfinite(pts).all(axis=1))
        return pts, mask, quality

    def solve_markers(self, markers: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
        """Solve the named markers (8, 3) of the frame at t s: ((8, 3) markers, (13, 3) joints,
        NaN if unsolved; residual m; (13,) joint bounds m, inf if unsolved). Names the solver
        cannot fit go back to the labelling (:meth:`Labeller.refit`), which may swap them: the
        frame is then solved again with the new names, which are returned. Legs the labelling
        is unsure of (:attr:`Labeller.legs_unsure`: they may be each other's) widen the
        knees' and ankles' bounds (:func:`~samba_server.recon.bounds.mirrored_legs`); with fewer than 3
        cameras every left/right pair's are (:func:`~samba_server.recon.bounds.mirrored_pairs`). A solved pose feeds
        the labelling's predictions; a solver error is logged and leaves the frame unsolved."""
        joints, residual = np.full((N_JOINTS, 3), np.nan), float("nan")
        bounds = np.full(N_JOINTS, np.inf)
        rec = self.reconstructor
        try:
            before = rec.checkpoint() if hasattr(rec, "checkpoint") else None
            r = rec.solve(markers, t)
            if before is not None and r.residual > self.labeller.config.refit_residual_m:
                renamed = self.labeller.refit(markers, rec.markers_of(r.joints), r.residual, t,
                                              lambda m: rec.trial(m, t, before))
                if renamed is not None:
                    markers = renamed
                    rec.restore(before)
                    r = rec.solve(markers, t)
            joints = np.asarray(r.joints, float)
            residual = float(r.residual)
            bounds = mirrored_legs(r.bounds, joints, self.labeller.legs_unsure)
            if len(self.rig) < 3:  # left and right are a guess there
                bounds = mirrored_pairs(bounds, joints)
        except Exception:
            log.exception("solver failed on frame t=%.3f s (frame left unsolved)", t)
        if np.isfinite(joints).all():
            self.labeller.observe(t, self._marker_view(joints), residual)
        return markers, joints, residual, bounds

    def _frame(self, frame) -> PoseMessage:
        self.stats.frames += 1
        if self._t0_ns is None:
            self._t0_ns = frame.t_ns
        t = (frame.t_ns - self._t0_ns) / 1e9
        markers, mask, quality = self.markers_for(frame, t)
        joints = np.full((N_JOINTS, 3), np.nan)
        bounds = None
        residual, flags = float("nan"), 0
        if self.skip_seqs is not None:
            skip = self._seq in self.skip_seqs
        else:
            lag_ms = (self.clock() - frame.t_ns) / 1e6
            skip = self.config.max_lag_ms > 0 and lag_ms > self.config.max_lag_ms
        if skip:
            self.stats.solve_skipped += 1
            flags |= FLAG_SOLVE_SKIPPED
        if self.reconstructor is not None and not skip:
            markers, joints, residual, bounds = self.solve_markers(markers, t)  # a refit swaps names, keeps the mask
            self._check_subject(frame.t_ns)
            if np.isfinite(joints).all():
                flags |= FLAG_SOLVED
                self.stats.solved += 1
        self.last_named = markers
        gap = self.labeller.unseparated(markers)  # hands together no view separates: a gap, not a coin flip
        if gap.any():
            markers = np.where(gap[:, None], np.nan, markers)
            mask = marker_bits(np.isfinite(markers).all(axis=1))
            if bounds is not None:
                bounds = mirrored_wrists(bounds, joints, True)
        if not frame.complete:
            flags |= FLAG_INCOMPLETE
        if quality.renamed:
            flags |= FLAG_LABEL_RENAMED
        if quality.overridden:
            flags |= FLAG_LABEL_OVERRIDDEN
            self.stats.labels_overridden += quality.overridden
        msg = PoseMessage(seq=self._seq, t_ns=frame.t_ns, joints=joints, residual_m=residual,
                          n_markers=bin(mask).count("1"), n_views=len(frame.packets), flags=flags,
                          markers=markers, marker_mask=mask, label_margin_m=quality.margin_m,
                          label_mode=quality.mode, joint_bound=bounds)
        self._seq += 1
        msg.latency_ms = (self.clock() - frame.t_ns) / 1e6
        self.stats.latency_ms.append(msg.latency_ms)
        if len(self.stats.latency_ms) > 100_000:
            del self.stats.latency_ms[:50_000]
        if self.config.keep_history:
            self.poses.append(msg)
        if self.publish is not None:
            try:
                self.publish(msg)
            except Exception:
                log.exception("publishing pose %d failed", msg.seq)
        for fn in self.pose_listeners:
            try:
                fn(msg)
            except Exception:
                log.exception("pose listener failed")
        recorder = self.recorder
        if recorder is not None:
            recorder.write_pose(encode_pose(msg), self.clock(), frame.t_ns, msg.seq)
        return msg

    def set_recorder(self, recorder: Recorder | None) -> Recorder | None:
        """Start (or stop, with None) recording while running; returns the previous recorder."""
        with self._lock:
            old, self.recorder = self.recorder, recorder
            if recorder is not None:
                now = self.clock()
                recorder.write_calibration(self.calibration_toml, now)
                self._record_subject(recorder, now)
        return old

    def failure_reason(self) -> str:
        """Why most frames of a take have no pose (one sentence), from the counters: solves skipped
        because the live server was behind, no frame, no 3D marker, never identified, or lost."""
        st = self.labeller.stats
        skipped = self.stats.solve_skipped
        if skipped and skipped >= 0.5 * max(self.stats.frames, 1):
            then = (f"the recording holds every packet: samba-replay {self.recorder.path} --out joints.npz "
                    "--solve-all solves them" if self.recorder is not None else
                    "record the take (--record) to solve them afterwards with samba-replay --out --solve-all")
            return (f"the server fell behind the motes and skipped the solve of {skipped} frames (older than "
                    f"max_lag_ms = {self.config.max_lag_ms:g} ms: a faster machine, fewer motes or a lower fps); "
                    + then)
        if st.frames == 0:
            return "no frame was assembled (are the videos empty or unreadable, did any mote send?)"
        seen = st.frames_with_points / st.frames
        if seen < 0.5:
            return (f"markers were seen by two cameras in only {100 * seen:.0f} % of frames (check the calibration, "
                    "that the cameras overlap, and the blobs with samba-mote --preview)")
        if st.first_identified_t is None:
            return ("the markers were never identified: no standard pose found and no frame showed enough of the body "
                    "(start the take with the standard pose, facing +Y, in view of every camera)")
        return (f"markers identified at {st.first_identified_t:.2f} s but lost for most of the take "
                f"({st.identifications} identifications; look at samba-inspect --plot)")

    def report(self) -> dict:
        """What the server saw, for operators and the fault-harness tests (docs/reliability.md).

        ``frames``: emitted; ``degraded``: emitted with an alive mote missing; ``drops`` by
        cause: ``late`` (its frame was already out), ``malformed`` (not a marker packet),
        ``duplicate`` (seq seen again), ``unknown_mote`` (not in the calibration),
        ``queue_overflow`` (server behind). ``motes``: per mote ``packets`` received,
        ``late``, ``duplicate``, ``missing`` (degraded frames lacking it), ``restarts``,
        ``clock_offset_ms`` (mote clock - server clock, up to the minimum latency) and
        ``drift_ppm`` (+ = mote clock fast; None until 5 s of data).
        """
        sync = self.sync
        sync.update_drift()
        motes = {}
        for m, st in sorted(sync.motes.items()):
            drift = st.drift_ppm
            motes[m] = {"packets": st.received, "late": st.late, "duplicate": st.duplicate, "missing": st.missing,
                        "restarts": st.restarts, "clock_offset_ms": round(st.clock_offset_ms, 3),
                        "drift_ppm": None if drift != drift else round(drift, 1)}
        return {"frames": sync.frames_emitted, "degraded": sync.frames_incomplete, "solved": self.stats.solved,
                "drops": {"late": sum(st.late for st in sync.motes.values()),
                          "malformed": self.stats.bad_packets,
                          "duplicate": sum(st.duplicate for st in sync.motes.values()),
                          "unknown_mote": self.stats.unknown_motes,
                          "queue_overflow": self.stats.queue_overflow},
                "motes": motes}

    def joints_array(self) -> tuple[np.ndarray, np.ndarray]:
        """History as ((F, 13, 3) joints, (F,) seconds since the first frame)."""
        if not self.poses:
            return np.zeros((0, N_JOINTS, 3)), np.zeros(0)
        t0 = self.poses[0].t_ns
        return (np.stack([p.joints for p in self.poses]), np.array([(p.t_ns - t0) / 1e9 for p in self.poses]))
