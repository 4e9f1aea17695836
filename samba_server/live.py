"""Zenoh wiring of the :class:`~samba_server.server.Server`: subscribe, discover, publish, serve.

- subscriber ``samba/{session}/mote/*/markers`` -> :meth:`Server.ingest` (arrival stamped there;
  packets republished by ``samba-replay`` carry their recorded arrival, see :class:`ReplayClock`)
- liveliness subscriber ``samba/{session}/mote/*`` (history on) -> joins/leaves, logged
- queryable ``samba/{session}/calibration`` -> the calibration.toml bytes
- queryable ``samba/{session}/replay`` -> JSON progress of a ``samba-replay --connect`` run:
  ``{"run": id, "received": packets of that run, "backlog": items not yet processed}``
- publishers ``samba/{session}/pose`` (binary) and ``samba/{session}/pose/json``
- a processing thread running :meth:`Server.run`
"""

from __future__ import annotations

import json
import logging
import threading

from samba_common import zenoh_util as zk
from samba_common.pose_wire import PoseMessage, encode_pose, pose_to_json

from .replay import ReplayClock
from .server import Server

log = logging.getLogger(__name__)


class LiveServer:
    """Run ``server`` on a Zenoh session. Use as a context manager or call start()/close()."""

    def __init__(self, server: Server, session: str = zk.DEFAULT_SESSION, listen=(), connect=(),
                 mode: str = "peer", scouting: bool = False, publish_json: bool = True, extra: dict | None = None):
        """extra: more Zenoh settings, e.g. :func:`samba_common.keys.server_settings` (TLS + access control)."""
        self.server = server
        self.session_name = session
        self.cfg = zk.make_config(mode=mode, listen=listen, connect=connect, scouting=scouting, extra=extra)
        self.publish_json = publish_json
        self.alive: set[str] = set()
        self._replay_clock = ReplayClock()
        self._replaying = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._z = None
        self._decls: list = []

    def start(self) -> "LiveServer":
        import zenoh

        self._z = zenoh.open(self.cfg)
        z, s = self._z, self.session_name
        self._pub = z.declare_publisher(zk.pose_key(s), encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM)
        self._pub_json = (z.declare_publisher(zk.pose_json_key(s), encoding=zenoh.Encoding.APPLICATION_JSON)
                          if self.publish_json else None)
        self.server.publish = self._publish
        self._decls = [
            z.declare_subscriber(zk.markers_key(s, "*"), self._on_markers),
            z.liveliness().declare_subscriber(zk.liveliness_key(s, "*"), self._on_liveliness, history=True),
            z.declare_queryable(zk.calibration_key(s), self._on_query),
            z.declare_queryable(zk.replay_status_key(s), self._on_replay_query),
        ]
        self._thread = threading.Thread(target=self.server.run, args=(self._stop,), name="samba-server", daemon=True)
        self._thread.start()
        log.info("server up: session %r, cameras %s", s, ", ".join(self.server.rig.names))
        return self

    # zenoh callbacks: short, never raise
    def _on_markers(self, sample) -> None:
        try:
            mote = zk.mote_id_from_key(str(sample.key_expr)) or "?"
            att = sample.attachment
            arrival = None
            if att is not None:  # a packet republished by samba-replay: its recorded timing
                arrival = self._replay_clock.arrival_ns(att.to_bytes(), self.server.clock(),
                                                        self.server.last_arrival_ns)
            # a replay (possibly faster than real time) is solved whole: max_lag_ms is for live motes
            replaying = arrival is not None
            if replaying != self._replaying:
                self._replaying = replaying
                self.server.skip_seqs = set() if replaying else None
            if self.server.ingest(mote, sample.payload.to_bytes(), arrival_ns=arrival) and replaying:
                self._replay_clock.taken_in()
        except Exception:  # pragma: no cover - defensive: a callback must not die
            log.exception("ingest failed")

    def _on_liveliness(self, sample) -> None:
        import zenoh

        mote = zk.mote_id_from_key(str(sample.key_expr))
        if mote is None:
            return
        joined = sample.kind == zenoh.SampleKind.PUT
        if joined:
            self.alive.add(mote)
            log.info("mote %s joined", mote)
        else:
            self.alive.discard(mote)
            log.info("mote %s left", mote)
        self.server.mote_event(mote, joined)

    def _on_query(self, query) -> None:
        try:
            query.reply(query.key_expr, self.server.calibration_toml)
        except Exception:  # pragma: no cover
            log.exception("calibration query failed")

    def _on_replay_query(self, query) -> None:
        try:
            status = {**self._replay_clock.progress(), "backlog": self.server.backlog}
            query.reply(query.key_expr, json.dumps(status))
        except Exception:  # pragma: no cover
            log.exception("replay status query failed")

    def _publish(self, msg: PoseMessage) -> None:
        self._pub.put(encode_pose(msg))
        if self._pub_json is not None:
            self._pub_json.put(pose_to_json(msg))

    def close(self) -> None:
        """Stop ingesting, process what is queued, flush the last frames, close (idempotent)."""
        for d in self._decls:  # no new packets from here on
            try:
                d.undeclare()
            except Exception:  # pragma: no cover
                pass
        self._decls = []
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
            if self._thread.is_alive():  # pragma: no cover - a stuck solve
                log.error("processing thread did not stop; last frames not flushed")
            else:
                try:
                    self.server.finish()
                except Exception:  # pragma: no cover
                    log.exception("final flush failed")
            self._thread = None
        if self._z is not None:
            self._z.close()
            self._z = None

    def __enter__(self) -> "LiveServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
