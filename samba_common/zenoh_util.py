"""Zenoh configuration builder and the Samba key expressions.

Key expressions (``{session}`` and ``{id}`` may be ``*`` in subscriptions)::

    samba/{session}/mote/{id}/markers   binary MarkerPacket (samba_common.wire)
    samba/{session}/mote/{id}           liveliness token of a running mote
    samba/{session}/mote/{id}/status    JSON MoteStatus, about 1 Hz
    samba/{session}/calibration         queryable served by the server: calibration.toml bytes
    samba/{session}/replay              queryable served by the server: JSON progress of a replay
    samba/{session}/pose                binary pose packets
    samba/{session}/pose/json           JSON pose packets

``zenoh`` itself is imported lazily by :func:`make_config`, so the key functions are cheap.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from typing import Any

DEFAULT_SESSION = "default"
_CHUNK = re.compile(r"^[A-Za-z0-9_.\-]+$")


def _chunk(value: str, what: str, wildcard: bool = True) -> str:
    if wildcard and value in ("*", "**"):
        return value
    if not isinstance(value, str) or not _CHUNK.match(value):
        raise ValueError(f"invalid {what} {value!r}: use letters, digits, '_', '-', '.'")
    return value


def mote_prefix(session: str, mote_id: str) -> str:
    """``samba/{session}/mote/{id}``: also the liveliness token of the mote."""
    return f"samba/{_chunk(session, 'session')}/mote/{_chunk(mote_id, 'mote id')}"


def liveliness_key(session: str, mote_id: str) -> str:
    """Liveliness token ``samba/{session}/mote/{id}``."""
    return mote_prefix(session, mote_id)


def markers_key(session: str, mote_id: str) -> str:
    """Marker packets ``samba/{session}/mote/{id}/markers``."""
    return mote_prefix(session, mote_id) + "/markers"


def status_key(session: str, mote_id: str) -> str:
    """Status messages ``samba/{session}/mote/{id}/status``."""
    return mote_prefix(session, mote_id) + "/status"


def calibration_key(session: str) -> str:
    """Calibration queryable ``samba/{session}/calibration``."""
    return f"samba/{_chunk(session, 'session')}/calibration"


def replay_status_key(session: str) -> str:
    """Replay progress queryable ``samba/{session}/replay`` (JSON, see samba_server.replay)."""
    return f"samba/{_chunk(session, 'session')}/replay"


def pose_key(session: str) -> str:
    """Binary poses ``samba/{session}/pose``."""
    return f"samba/{_chunk(session, 'session')}/pose"


def pose_json_key(session: str) -> str:
    """JSON poses ``samba/{session}/pose/json``."""
    return pose_key(session) + "/json"


def mote_id_from_key(key: str) -> str | None:
    """The ``{id}`` part of any ``samba/{session}/mote/{id}[/...]`` key, else None."""
    parts = str(key).split("/")
    if len(parts) >= 4 and parts[0] == "samba" and parts[2] == "mote":
        return parts[3]
    return None


def make_config(mode: str = "peer", listen: Iterable[str] = (), connect: Iterable[str] = (),
                scouting: bool = False, extra: dict[str, Any] | None = None) -> Any:
    """A ``zenoh.Config``.

    mode: "peer" or "client"; listen/connect: endpoints such as ``tcp/127.0.0.1:7447``;
    scouting: multicast scouting on/off (off in tests); extra: more ``key: value`` JSON
    settings (for example ``{"timestamping/enabled": True}``, or the TLS and access-control
    settings of :mod:`samba_common.keys`).

    Without ``listen`` endpoints the session listens nowhere (Zenoh's own default is every
    interface on a random port): a mote or a client that connects out needs no open port.
    Only with ``scouting`` on is Zenoh's default kept, so that scouted peers can reach it.
    """
    import zenoh

    if mode not in ("peer", "client", "router"):
        raise ValueError(f"zenoh mode must be peer, client or router, got {mode!r}")
    cfg = zenoh.Config()
    cfg.insert_json5("mode", json.dumps(mode))
    cfg.insert_json5("scouting/multicast/enabled", json.dumps(bool(scouting)))
    listen, connect = list(listen), list(connect)
    if listen or not scouting:
        cfg.insert_json5("listen/endpoints", json.dumps(listen))
    if connect:
        cfg.insert_json5("connect/endpoints", json.dumps(connect))
    for k, v in (extra or {}).items():
        cfg.insert_json5(k, json.dumps(v))
    return cfg


def first_reply(session: Any, key: str, timeout: float) -> tuple[bytes | None, str | None]:
    """Ask a Zenoh queryable: (payload, None) for the first good reply; (None, reason) when
    the replies were errors or the query failed (Zenoh answers a query nobody finished in
    time with a "Timeout" error: a busy server, ask again); (None, None) when nobody serves
    ``key`` (the query ends at once, without a reply)."""
    reason = None
    try:
        for reply in session.get(key, timeout=timeout):
            if reply.ok is not None:
                return reply.ok.payload.to_bytes(), None
            reason = reason or reply.err.payload.to_bytes()[:200].decode("utf-8", "replace")
    except Exception as exc:
        return None, reason or str(exc) or type(exc).__name__
    return None, reason
