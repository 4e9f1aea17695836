"""Running a :class:`~samba_server.server.Server` as an application: configs/server.toml loading,
logging, building a Server with its reconstructor and recorder, running it live on Zenoh with
the status line and the browser viewer, exporting its poses. Used by the command lines of
:mod:`samba_server.cli` (server, process, replay, demo) and by the benchmarks."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from importlib.resources import files
from pathlib import Path
from typing import Callable

import numpy as np

from samba_common import zenoh_util as zk
from samba_common.calib import CameraRig
from samba_common.config import from_dict, read_toml

from .recon.reconstruct import ReconstructConfig
from .labelling.labeller import LabelConfig
from .labelling.points import PointsConfig
from .record import Recorder, RecorderError
from .server import Server, ServerConfig
from .sync import SyncConfig
from .triangulate import TriangulateConfig

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ServerConfigs:
    """All tables of configs/server.toml."""

    server: ServerConfig
    sync: SyncConfig
    triangulate: TriangulateConfig
    labelling: LabelConfig
    reconstruct: ReconstructConfig


def default_config_path() -> Path:
    """The packaged configs/server.toml."""
    return Path(str(files("samba_configs").joinpath("server.toml")))


def load_server_configs(path: str | os.PathLike | None = None, placement: str | None = None,
                        **sync_overrides) -> ServerConfigs:
    """Load configs/server.toml (default: the packaged one); raise ConfigError on bad keys.
    placement: "auto", "skin" or "joint-centres" (``--placement``) overrides ``[reconstruct]
    placement``; sync_overrides (e.g. fps) override ``[sync]`` keys."""
    p = Path(path) if path is not None else default_config_path()
    data = read_toml(p) if p.exists() else {}
    sync = dict(data.get("sync", {}))
    sync.update({k: v for k, v in sync_overrides.items() if v is not None})
    return ServerConfigs(
        server=from_dict(ServerConfig, data.get("server", {}), f"{p} [server]"),
        sync=from_dict(SyncConfig, sync, f"{p} [sync]"),
        triangulate=from_dict(TriangulateConfig, data.get("triangulate", {}), f"{p} [triangulate]"),
        labelling=_label_config(data.get("labelling", {}), p),
        reconstruct=from_dict(ReconstructConfig, {**data.get("reconstruct", {}),
                                                  **({"placement": placement.replace("-", "_")} if placement else {})},
                              f"{p} [reconstruct]"),
    )


def add_placement_arg(ap: argparse.ArgumentParser) -> None:
    """``--placement``: where the markers sit, for a subject measured live."""
    ap.add_argument("--placement", choices=("auto", "skin", "joint-centres"),
                    help="where the markers sit: skin (taped on the acromion, the lateral knee and ankle, the "
                         "back of the wrist: every real take), joint-centres (simulated takes) or auto (decided "
                         "from the knee and ankle spacing in the standard pose; a near call when the feet "
                         "are at hip width and the landmarks sit close to the joints). Default: [reconstruct] "
                         "placement (auto). samba-process prints the placement used and why; samba-server logs it (-v)")


def _label_config(table: dict, p: Path) -> LabelConfig:
    """``[labelling]`` with its sub-table ``[labelling.points]``."""
    table = dict(table)
    points = from_dict(PointsConfig, table.pop("points", {}), f"{p} [labelling.points]")
    return from_dict(LabelConfig, {**table, "points": points}, f"{p} [labelling]")


def setup_logging(verbose: int) -> None:
    """WARNING by default, INFO with -v, DEBUG with -vv."""
    level = logging.WARNING if verbose <= 0 else logging.INFO if verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        import zenoh

        zenoh.init_log_from_env_or("error")
    except Exception:  # pragma: no cover
        pass


def make_reconstructor(db_path: str | None, config: ReconstructConfig | None = None, subject=None):
    """A Reconstructor with the motion DB at ``db_path`` (or the shipped one), compiled and ready.
    subject: a samba_common.subject.Subject (bone lengths + marker offsets) or None (body measured
    live from the standard pose, markers on the joint centres)."""
    from .recon.reconstruct import Reconstructor

    db = None
    if db_path:
        from .recon.db import MotionDB

        db = MotionDB.load(db_path)
    if subject is not None:
        offsets = subject.offsets if subject.placement == "skin" else None
        rec = Reconstructor(db=db, config=config, lengths=subject.lengths, offsets=offsets)
    else:
        rec = Reconstructor(db=db, config=config)
    rec.warm_up()  # compile before the first live frame
    return rec


def warn_few_cameras(rig: CameraRig) -> bool:
    """Log a warning when the rig has fewer than 3 cameras, saying what its marker names are
    worth there; True when it did."""
    if len(rig) >= 3:
        return False
    log.warning("%d camera(s) in the calibration: with fewer than 3, every pair of blobs on an epipolar line "
                "makes a 3D point and most fit some body, so marker names are often wrong (about 1 frame in 5 on "
                "the labelling benchmark with 2 cameras, docs/BENCHMARKS.md): every left/right joint's bound "
                "covers the other side (joint_bound, most joints flagged as guesses) and a confidently wrong "
                "joint is still left in about 1 %% of confident frames there; use 3 or more cameras",
                len(rig))
    return True


def build_server(calibration: str | os.PathLike, configs: ServerConfigs, db: str | None = None,
                 record: str | None = None, live: bool = True, subject: str | None = None) -> Server:
    """Load the calibration and build a Server (raises CalibrationError / RecorderError, and
    SubjectError for a bad ``subject`` toml)."""
    toml = Path(calibration).read_bytes()
    rig = CameraRig.load(calibration)
    warn_few_cameras(rig)
    server_cfg = configs.server
    if not live and server_cfg.max_lag_ms:
        server_cfg = ServerConfig(**{**server_cfg.__dict__, "max_lag_ms": 0.0})
    subj = None
    # the placement asked for (--placement / [reconstruct] placement): a replay decides as live did
    meta = {"tool": "samba-server", "placement": configs.reconstruct.placement}
    if subject:
        from samba_common.subject import load_subject

        subj = load_subject(subject)
        meta["subject_toml"] = subj.to_toml()
    recorder = Recorder(record, metadata=meta) if record else None
    return Server(rig, calibration_toml=toml, reconstructor=make_reconstructor(db, configs.reconstruct, subj),
                  config=server_cfg,
                  sync_config=configs.sync, tri_config=configs.triangulate, label_config=configs.labelling,
                  recorder=recorder)


def export_joints(server: Server, path: str | os.PathLike) -> int:
    """Write the server's pose history as joints.npz (extra keys: t_ns, residual, n_markers,
    markers, joint_bound, and the subject in use at the end: subject_lengths, subject_offsets,
    subject_placement). Returns the number of frames."""
    from samba_common.formats import save_joints
    from samba_common.pose_wire import stack_bounds

    joints, t = server.joints_array()
    poses = server.poses
    subject = server.subject
    extra = subject.metadata() if subject is not None else {}
    save_joints(path, joints, t, t_ns=np.array([p.t_ns for p in poses], dtype=np.int64),
                residual=np.array([p.residual_m for p in poses]), n_markers=np.array([p.n_markers for p in poses]),
                markers=np.stack([p.markers for p in poses]) if poses else np.zeros((0, 8, 3)),
                joint_bound=stack_bounds(poses), **extra)
    return len(poses)


class Status:
    """Rolling figures for the status line / viewer panel: fps, latency, motes alive, drops."""

    def __init__(self, server: Server, alive: set[str] | None = None):
        self.server = server
        self.alive = alive
        self._last = (time.monotonic(), 0)
        self._last_packets: dict[str, int] = {}
        self._blobs: dict[str, int] = {}  # blobs in each mote's latest packet
        server.packet_listeners.append(self._on_packet)

    def _on_packet(self, pkt) -> None:
        self._blobs[pkt.mote_id] = int(len(pkt.uv))

    def _mote_rows(self, alive: list[str], dt: float) -> dict:
        """Per mote: alive, fps (packets/s since the last snapshot), blobs (latest packet),
        drops (packets dropped late or duplicate + frames missed while alive), packets, late."""
        s = self.server
        rows = {}
        for m in sorted(set(s.rig.names) | set(alive)):
            n = s.stats.mote_packets.get(m, 0)
            st = s.sync.motes.get(m)
            rows[m] = {"alive": m in alive, "packets": n, "late": st.late if st else 0,
                       "fps": round((n - self._last_packets.get(m, n)) / dt, 1) if m in self._last_packets else None,
                       "blobs": self._blobs.get(m), "drops": (st.late + st.duplicate + st.missing) if st else 0}
            self._last_packets[m] = n
        return rows

    def snapshot(self) -> dict:
        s = self.server
        now = time.monotonic()
        t0, f0 = self._last
        frames = s.stats.frames
        fps = (frames - f0) / max(now - t0, 1e-6)
        self._last = (now, frames)
        lat = s.stats.latency_ms[-120:]
        late = sum(m.late + m.duplicate for m in s.sync.motes.values())
        alive = sorted(self.alive) if self.alive is not None else s.sync.alive()
        return {"fps": round(fps, 1), "latency_ms": round(float(np.median(lat)), 2) if lat else None,
                "motes_alive": len(alive), "motes": self._mote_rows(alive, max(now - t0, 1e-6)),
                "frames": frames, "solved": s.stats.solved,
                "drops": s.stats.bad_packets + s.stats.unknown_motes + s.stats.queue_overflow + late,
                "recording": s.recorder is not None, "degraded": s.sync.frames_incomplete,
                "drops_by_cause": s.report()["drops"],  # also refreshes the drift estimates
                "clocks": {m: {"offset_ms": round(st.clock_offset_ms, 2),
                               "drift_ppm": None if st.drift_ppm != st.drift_ppm else round(st.drift_ppm)}
                           for m, st in sorted(s.sync.motes.items())}}

    @staticmethod
    def line(snap: dict) -> str:
        lat = "-" if snap["latency_ms"] is None else f"{snap['latency_ms']:.1f} ms"
        return (f"fps {snap['fps']:5.1f} | latency {lat:>8} | motes {snap['motes_alive']} alive | "
                f"frames {snap['frames']} solved {snap['solved']} | drops {snap['drops']}"
                + (" | REC" if snap["recording"] else ""))


def record_toggle(server: Server, folder: str | os.PathLike = ".") -> Callable[[bool], None]:
    """The viewer's start/stop recording: start writes ``take-YYYYmmdd-HHMMSS.mcap`` in ``folder``
    (unless a recording runs already), stop closes the current recording."""

    def on_record(start: bool) -> None:
        if start and server.recorder is None:
            path = Path(folder) / time.strftime("take-%Y%m%d-%H%M%S.mcap")
            try:
                server.set_recorder(Recorder(path, metadata={"tool": "samba-server viewer"}))
                log.info("recording to %s", path)
            except RecorderError as exc:
                log.error("cannot start recording: %s", exc)
        elif not start:
            old = server.set_recorder(None)
            if old is not None:
                old.close()
                log.info("recording stopped")

    return on_record


def attach_viewer(server: Server, http: str, status: Status, record_dir: str | os.PathLike = "."):
    """Start the browser viewer on ``http`` ("PORT" or "HOST:PORT") and feed it; its record
    buttons start and stop recordings in ``record_dir``."""
    from .viewer.server import Viewer

    host, _, port = http.rpartition(":")
    viewer = Viewer(host or "127.0.0.1", int(port), on_record=record_toggle(server, record_dir))

    from .viewer.bridge import pose_quality

    def on_pose(msg) -> None:
        viewer.publish_pose(msg.t_ns / 1e9, msg.joints, msg.markers, pose_quality(msg))

    def on_packet(pkt) -> None:
        viewer.publish_blobs(pkt.mote_id, pkt.uv, pkt.labels, (pkt.width, pkt.height))

    server.pose_listeners.append(on_pose)
    server.packet_listeners.append(on_packet)
    viewer.start()
    return viewer


def add_network_args(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--session", default=zk.DEFAULT_SESSION, help="session name (default: %(default)s)")
    ap.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                    help="Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 (repeatable)")
    ap.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                    help="Zenoh endpoint to connect to (repeatable)")
    ap.add_argument("--scouting", action="store_true", help="enable Zenoh multicast scouting")
    ap.add_argument("--tls", metavar="KEYS_DIR",
                    help="mutual TLS + access control with the keys of 'samba-keys init KEYS_DIR' "
                         "(endpoints then tls/HOST:PORT; see docs/security.md)")


def zenoh_endpoints(args) -> tuple[list[str], list[str], dict | None]:
    """(listen, connect, extra Zenoh settings) of the server from its parsed arguments.

    Without any endpoint or scouting the server listens on loopback port 7447 (``tcp/`` or, with
    ``--tls``, ``tls/``): a LAN address is only used when the user gives one. With ``--tls`` every
    endpoint must be ``tls/...`` and the settings are :func:`samba_common.keys.server_settings`.
    Raises ValueError (bad endpoint) or :class:`samba_common.keys.KeysError` (keys folder).
    """
    tls = getattr(args, "tls", None)
    listen, connect = list(args.listen), list(args.connect)
    if not listen and not connect and not getattr(args, "scouting", False):
        listen = [("tls" if tls else "tcp") + "/127.0.0.1:7447"]
    if not tls:
        return listen, connect, None
    from samba_common import keys

    keys.check_endpoints(listen + connect, "endpoint")
    return listen, connect, keys.server_settings(tls, args.session)


def run_live(server: Server, args, extra_stop: threading.Event | None = None, on_tick=None,
             before_close=None, summary: bool = True) -> int:
    """Run ``server`` on Zenoh until Ctrl-C, SIGTERM or ``args.duration``; export/close at the end.
    ``summary``: print frames / solved / solves skipped at the end and exit 3 (with a warning saying
    why) when fewer than half the frames were solved (``samba-demo`` prints its own line)."""
    from .live import LiveServer

    stop = extra_stop or threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    from samba_common.keys import KeysError

    try:
        listen, connect, extra = zenoh_endpoints(args)
    except (KeysError, ValueError) as exc:
        print(f"{Path(sys.argv[0]).name}: {exc}", file=sys.stderr)
        if server.recorder is not None:
            server.recorder.close()
        return 1
    live = LiveServer(server, session=args.session, listen=listen, connect=connect,
                      scouting=args.scouting, extra=extra)
    status = Status(server, live.alive)
    viewer = None
    code = 0
    try:
        live.start()
        if listen and not getattr(args, "quiet", False):
            print(f"zenoh: session {args.session!r}, listening on {', '.join(listen)}"
                  + (" (mutual TLS)" if extra else ""), file=sys.stderr)
        if args.http:
            record_dir = Path(args.record).parent if getattr(args, "record", None) else Path(".")
            viewer = attach_viewer(server, args.http, status, record_dir)
            print(f"viewer: {viewer.url}", file=sys.stderr)
        t_end = time.monotonic() + args.duration if args.duration else None
        while not stop.is_set() and (t_end is None or time.monotonic() < t_end):
            stop.wait(0.5)
            snap = status.snapshot()
            if viewer is not None:
                viewer.publish_status(snap)
            if on_tick is not None:
                on_tick(snap)
            elif getattr(args, "status", False) and sys.stderr.isatty():
                sys.stderr.write("\r" + Status.line(snap) + "  ")
                sys.stderr.flush()
    except KeyboardInterrupt:
        pass
    except Exception as exc:  # zenoh errors (port taken, bad endpoint)
        print(f"\n{Path(sys.argv[0]).name}: {exc}", file=sys.stderr)
        code = 1
    finally:
        if before_close is not None:
            before_close()
        live.close()
        if viewer is not None:
            viewer.stop()
        if server.recorder is not None:
            server.recorder.close()
            if server.recorder.stats.dropped:
                print(f"recording: {server.recorder.stats.dropped} message(s) could not be written "
                      f"({server.recorder.stats.last_error})", file=sys.stderr)
        if getattr(args, "export", None):
            n = export_joints(server, args.export)
            print(f"\nwrote {n} frames to {args.export}", file=sys.stderr)
        if summary:
            code = code or _take_summary(server)
    return code


def _take_summary(server: Server) -> int:
    """At the end of a live session: frames, solved, solves skipped (stderr), and a warning with the
    reason when fewer than half the frames were solved. Returns 3 then (as samba-process), else 0."""
    st = server.stats
    if not st.frames:
        return 0
    skipped = f", {st.solve_skipped} solves skipped (the server was behind)" if st.solve_skipped else ""
    print(f"{st.frames} frames, {st.solved} solved{skipped}", file=sys.stderr)
    if server.reconstructor is None or st.solved >= 0.5 * st.frames:
        return 0
    print(f"samba-server: WARNING: only {st.solved} of {st.frames} frames solved: {server.failure_reason()}",
          file=sys.stderr)
    return 3

