"""Live browser viewer: one HTTP + WebSocket server on its own thread.

The server process calls a small thread-safe API (:class:`Viewer`); the page (``static/``)
draws the skeleton and markers in 3D (three.js, vendored), each mote's 2D blobs, a status
panel, and has start/stop recording buttons.

Library choice: ``websockets`` (pure Python on asyncio, no dependencies) serves both the
static files (``process_request``) and the ``/ws`` WebSocket on one port.

Flow control: the newest pose and the newest blobs of each mote are kept in slots and sent at
most ``max_rate`` times per second, so a fast server never queues data for a slow browser; a
browser whose socket buffer is still full when the next message is due skips that message
(counted in :attr:`Viewer.stats`). Status messages are sent as they come.

Messages (JSON text frames, server -> page)::

    {"type": "hello", "joint_names": [...13], "marker_names": [...8], "bones": [[i, j], ...],
     "recording": bool}
    {"type": "pose", "seq": n, "t": s, "t0": s (first pose of the session), "joints": [[x, y, z] | null, ...13],
     "markers": [[x, y, z] | null, ...8], "quality": {...}}                    world m, Z up
    (quality: residual_m, n_markers, label_mode, label_margin_m, flags, poor: [reasons], ...)
    {"type": "blobs", "mote": id, "size": [w, h], "uv": [[u, v], ...], "labels": [0..7 | 255]}
    {"type": "status", ...whatever dict the server publishes (motes, fps, latency_ms, drops,
     recording)...}

page -> server: ``{"type": "record", "start": true|false}`` calls ``on_record(start)``.

Who may connect (``docs/security.md``): a browser's WebSocket is accepted only from the page's
own origin (its ``Origin`` header must be ``http://`` + the ``Host`` it asked for, or one of
``allowed_origins``), so another site open in the same browser can neither read the poses nor
start a recording. Bound to loopback, the ``Host`` must be a loopback name (no DNS rebinding).
Bound beyond loopback, every request needs the viewer's token (``?token=...`` in the printed
URL; the page then keeps it in a same-site cookie). Refusals are counted in :attr:`Viewer.stats`.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import mimetypes
import secrets
import threading
from collections.abc import Callable
from dataclasses import dataclass
from importlib.resources import files
from typing import Any

import numpy as np

from samba_common.skeleton import BONES, JOINT_NAMES, MARKER_NAMES

log = logging.getLogger(__name__)

TOKEN_COOKIE = "samba_viewer_token"
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1", "[::1]")
STATIC_FILES = ("index.html", "viewer.js", "viewer.css", "three.module.min.js", "LICENSE.three.txt")
WRITE_BUFFER_LIMIT = 256 * 1024  # bytes queued for one browser before messages to it are skipped


class ViewerError(OSError):
    """The viewer could not start (port taken, bad address)."""


@dataclass
class ViewerStats:
    """Counters: poses published by the server / sent to browsers, messages skipped for slow
    browsers, bad client messages, clients connected now."""

    poses_published: int = 0
    poses_sent: int = 0
    skipped: int = 0
    bad_client_messages: int = 0
    bad_published: int = 0
    clients: int = 0
    refused: int = 0


def _rows(a: np.ndarray | None, n: int) -> list:
    """(n, k) float array -> list of rows rounded to 0.01 mm/px, a row with any NaN -> None."""
    if a is None:
        return [None] * n
    a = np.round(np.asarray(a, dtype=np.float64).reshape(n, -1), 5)
    ok = np.isfinite(a).all(axis=1)
    return [r if k else None for r, k in zip(a.tolist(), ok.tolist())]


def _clean(obj: Any) -> Any:
    """JSON-safe copy: numpy scalars/arrays to Python, NaN/inf to None."""
    if isinstance(obj, dict):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def _pose_json(seq: int, item: tuple) -> str:
    t, joints, markers, quality, t0 = item
    return json.dumps({"type": "pose", "seq": seq, "t": _clean(t), "t0": _clean(t0),
                       "joints": _rows(joints, len(JOINT_NAMES)),
                       "markers": _rows(markers, len(MARKER_NAMES)), "quality": _clean(quality)}, allow_nan=False)


def _blobs_json(mote: str, uv: np.ndarray, labels: np.ndarray | None, size: tuple[int, int]) -> str:
    lab = np.full(len(uv), 255, dtype=int) if labels is None else np.asarray(labels, dtype=int).reshape(-1)
    return json.dumps({"type": "blobs", "mote": mote, "size": list(size), "uv": _rows(uv, len(uv)),
                       "labels": [int(v) for v in lab[: len(uv)]]}, allow_nan=False)


class Viewer:
    """HTTP + WebSocket server for the live page, running an asyncio loop in a daemon thread.

    ``Viewer(host, port)`` (port 0 picks a free one; read :attr:`port` after :meth:`start`),
    ``on_record(start: bool)`` is called (on the viewer thread) when a page presses
    start/stop recording; keep it short. All ``publish_*`` methods are thread-safe and never
    block; before :meth:`start` or after :meth:`stop` they are no-ops.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8080,
                 on_record: Callable[[bool], None] | None = None, max_rate: float = 60.0,
                 token: str | None = None, allowed_origins: tuple[str, ...] = ()):
        """token: required of every request; default None = none on loopback, a random one
        when ``host`` is not a loopback address. allowed_origins: more origins (e.g.
        ``"https://mocap.lab.example"``) whose pages may connect besides the viewer's own."""
        self.host = host
        self.loopback = is_loopback(host)
        self.token = token if token is not None else (None if self.loopback else secrets.token_urlsafe(18))
        self.allowed_origins = tuple(o.rstrip("/").lower() for o in allowed_origins)
        self.port = port
        self.on_record = on_record
        self.max_rate = max_rate
        self.stats = ViewerStats()
        self._lock = threading.Lock()
        self._pose: tuple | None = None
        self._t0: float | None = None  # t of the session's first pose (s)
        self._t_last = float("-inf")
        self._blobs: dict[str, tuple] = {}
        self._status: str | None = None
        self._recording = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._stop_event: asyncio.Event | None = None
        self._clients: set = set()
        self._static = {name: files("samba_server.viewer").joinpath("static", name) for name in STATIC_FILES}

    # ------------------------------------------------------------------ public API
    @property
    def url(self) -> str:
        """The page's address, e.g. ``http://127.0.0.1:8080/`` (with ``?token=...`` when one is needed)."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        if host in ("0.0.0.0", "[::]", ""):  # all interfaces: give this machine's name
            import socket

            host = socket.gethostname()
        return f"http://{host}:{self.port}/" + (f"?token={self.token}" if self.token else "")

    def start(self, timeout: float = 5.0) -> "Viewer":
        """Bind and serve in a background thread; raises ViewerError if the port cannot be bound."""
        if self._thread is not None:
            return self
        ready = threading.Event()
        failure: list[BaseException] = []
        self._thread = threading.Thread(target=self._run, args=(ready, failure), name="samba-viewer", daemon=True)
        self._thread.start()
        if not ready.wait(timeout):
            raise ViewerError(f"viewer did not start on {self.host}:{self.port} within {timeout} s")
        if failure:
            self._thread.join(1.0)
            self._thread = None
            exc = failure[0]
            raise ViewerError(f"cannot serve the viewer on {self.host}:{self.port}: {exc}") from exc
        log.info("viewer on %s", self.url)
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Close all connections and the server; idempotent."""
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        if self._stop_event is not None:
            loop.call_soon_threadsafe(self._stop_event.set)
        thread.join(timeout)
        self._thread = None
        self._loop = None

    def publish_pose(self, t: float, joints: np.ndarray, markers: np.ndarray | None = None,
                     quality: dict | None = None) -> None:
        """Latest pose. t: seconds; joints: (13, 3) world m Z up (NaN rows unsolved);
        markers: (8, 3) world m NaN = missing; quality: small dict (residual_m, n_markers, ...)."""
        if self._loop is None:
            return
        m = None if markers is None else np.array(markers, dtype=np.float64)
        t = float(t)
        with self._lock:
            # the session's first pose (or the first after time went back, e.g. a new replay):
            # the page shows t - t0, the time since the start
            if self._t0 is None or t < self._t_last - 1.0:
                self._t0 = t
            self._t_last = t
            t0 = self._t0
        item = (t, np.array(joints, dtype=np.float64), m, dict(quality or {}), t0)
        with self._lock:  # encoded by the pump, at most max_rate times per second
            self.stats.poses_published += 1
            self._pose = (self.stats.poses_published, item)

    def publish_blobs(self, mote_id: str, uv: np.ndarray, labels: np.ndarray | None = None,
                      size: tuple[int, int] = (160, 120)) -> None:
        """Latest blobs of one mote. uv: (N, 2) pixels; labels: (N,) 0..7 or 255 (unlabelled);
        size: (width, height) of the mote's image."""
        if self._loop is None:
            return
        item = (np.array(uv, dtype=np.float64).reshape(-1, 2), None if labels is None else np.array(labels),
                (int(size[0]), int(size[1])))
        with self._lock:
            self._blobs[str(mote_id)] = item

    def publish_status(self, status: dict) -> None:
        """Status panel content: e.g. {"motes": {id: {"alive", "fps", "drops"}}, "fps",
        "latency_ms", "drops", "recording"}; any JSON-able dict is shown."""
        if self._loop is None:
            return
        status = dict(status)
        if "recording" in status:
            self._recording = bool(status["recording"])
        msg = json.dumps({"type": "status", **_clean(status)}, allow_nan=False)
        with self._lock:
            self._status = msg
        try:
            self._loop.call_soon_threadsafe(self._send_all, msg)
        except (RuntimeError, AttributeError):  # stopping concurrently: nothing to send to
            pass

    def __enter__(self) -> "Viewer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------ the loop
    def _run(self, ready: threading.Event, failure: list) -> None:
        loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._main(ready, failure))
        except BaseException as exc:  # noqa: BLE001 - reported to start() or logged
            if not ready.is_set():
                failure.append(exc)
                ready.set()
            else:
                log.exception("viewer stopped on an error")
        finally:
            loop.close()

    async def _main(self, ready: threading.Event, failure: list) -> None:
        from websockets.asyncio.server import serve

        self._stop_event = asyncio.Event()
        async with serve(self._handler, self.host, self.port, process_request=self._http,
                         compression=None, max_size=64 * 1024, ping_interval=20) as server:
            sock = next(iter(server.sockets))
            self.port = sock.getsockname()[1]
            self._loop = asyncio.get_running_loop()
            ready.set()
            pump = asyncio.create_task(self._pump())
            await self._stop_event.wait()
            pump.cancel()
            self._loop = None
            for ws in list(self._clients):
                await ws.close(1001, "viewer stopping")

    async def _pump(self) -> None:
        """Send the newest pose and blobs at most max_rate times per second."""
        period = 1.0 / self.max_rate
        while True:
            await asyncio.sleep(period)
            with self._lock:
                pose, self._pose = self._pose, None
                blobs, self._blobs = list(self._blobs.items()), {}
            if not self._clients:
                continue
            try:
                if pose is not None:
                    self.stats.poses_sent += self._send_all(_pose_json(*pose))
                for mote, item in blobs:
                    self._send_all(_blobs_json(mote, *item))
            except (TypeError, ValueError) as exc:  # bad data from the caller: drop, keep serving
                self.stats.bad_published += 1
                log.warning("viewer: dropped a message it could not encode (%s)", exc)

    def _send_all(self, msg: str) -> int:
        """Send ``msg`` to every browser whose socket buffer is not backed up; returns the count."""
        from websockets.asyncio.server import broadcast

        ready = []
        for ws in list(self._clients):
            transport = getattr(ws, "transport", None)
            if transport is not None and transport.get_write_buffer_size() > WRITE_BUFFER_LIMIT:
                self.stats.skipped += 1
            else:
                ready.append(ws)
        broadcast(ready, msg)  # never blocks; skips connections that are closing
        return len(ready)

    def _http(self, connection, request):
        """Serve static files; return None for /ws so the WebSocket handshake proceeds.
        Requests that fail :meth:`_refusal` get 403 (counted, logged once at info level)."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        path = request.path.split("?", 1)[0]
        why = self._refusal(request, websocket=path == "/ws")
        if why is not None:
            self.stats.refused += 1
            log.info("viewer: refused %s (%s)", path, why)
            return connection.respond(403, f"forbidden: {why}\n")
        if path == "/ws":
            return None
        name = "index.html" if path in ("/", "/index.html") else path.removeprefix("/static/")
        res = self._static.get(name) if path in ("/", "/index.html") or path.startswith("/static/") else None
        if res is None:
            return connection.respond(404, f"not found: {path}\n")
        body = res.read_bytes()
        ctype = mimetypes.guess_type(name)[0] or "application/octet-stream"
        if name.endswith(".js"):
            ctype = "text/javascript"
        headers = Headers([("Content-Type", f"{ctype}; charset=utf-8" if ctype.startswith("text") else ctype),
                           ("Content-Length", str(len(body))), ("Cache-Control", "no-cache"),
                           ("X-Frame-Options", "DENY"), ("X-Content-Type-Options", "nosniff")])
        if self.token:  # the page's WebSocket and script requests then carry it without the query
            headers["Set-Cookie"] = f"{TOKEN_COOKIE}={self.token}; Path=/; HttpOnly; SameSite=Strict"
        return Response(200, "OK", headers, body)

    def _refusal(self, request, websocket: bool) -> str | None:
        """Why ``request`` may not be served (None = allowed): DNS-rebinding Host on loopback,
        a WebSocket from another origin, or a missing/wrong token."""
        headers = request.headers
        hosts, origins = headers.get_all("Host"), headers.get_all("Origin")
        if len(hosts) != 1 or len(origins) > 1:
            return "repeated Host or Origin header"
        host = hosts[0].strip().lower()
        if self.loopback and _host_name(host) not in LOOPBACK_HOSTS:
            return f"Host {host!r} is not this loopback viewer"
        if websocket:
            origin = (origins[0] if origins else "").strip().rstrip("/").lower()
            # browsers always send Origin on a WebSocket; tools without one are not a web page
            if origin and origin not in (f"http://{host}", f"https://{host}", *self.allowed_origins):
                return f"WebSocket from origin {origin!r}, not the viewer's own (http://{host})"
        if self.token:
            given = _query_param(request.path, "token") or _cookie(headers.get("Cookie") or "", TOKEN_COOKIE)
            if not given or not secrets.compare_digest(given.encode(), self.token.encode()):
                return "token missing or wrong (open the URL printed by the server)"
        return None

    async def _handler(self, ws) -> None:
        self._clients.add(ws)
        self.stats.clients = len(self._clients)
        try:
            await ws.send(json.dumps({"type": "hello", "joint_names": list(JOINT_NAMES),
                                      "marker_names": list(MARKER_NAMES), "bones": [list(b) for b in BONES],
                                      "recording": self._recording}))
            with self._lock:
                status = self._status
            if status is not None:
                await ws.send(status)
            async for raw in ws:
                self._on_client_message(raw)
        except Exception as exc:  # noqa: BLE001 - one browser's trouble never stops the viewer
            log.debug("viewer client closed: %s", exc)
        finally:
            self._clients.discard(ws)
            self.stats.clients = len(self._clients)

    def _on_client_message(self, raw: str | bytes) -> None:
        try:
            msg = json.loads(raw)
            if msg.get("type") != "record" or not isinstance(msg.get("start"), bool):
                raise ValueError(f"unknown message {str(raw)[:80]!r}")
        except (ValueError, AttributeError) as exc:
            self.stats.bad_client_messages += 1
            log.warning("viewer: ignored a bad message from a page (%s)", exc)
            return
        log.info("viewer: page asks to %s recording", "start" if msg["start"] else "stop")
        if self.on_record is not None:
            try:
                self.on_record(msg["start"])
            except Exception:  # noqa: BLE001 - the callback's failure must not kill the viewer
                log.exception("on_record callback failed")


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and "localhost"."""
    import ipaddress

    h = host.strip("[]").lower()
    if h == "localhost":
        return True
    try:
        return ipaddress.ip_address(h).is_loopback
    except ValueError:
        return False


def _host_name(host_header: str) -> str:
    """``Host`` header without its port: "127.0.0.1:8080" -> "127.0.0.1", "[::1]:80" -> "[::1]"."""
    if host_header.startswith("["):
        return host_header.split("]", 1)[0] + "]"
    name = host_header.rsplit(":", 1)[0] if host_header.count(":") == 1 else host_header
    return "127.0.0.1" if name.startswith("127.") else name


def _query_param(path: str, name: str) -> str | None:
    from urllib.parse import parse_qs, urlsplit

    vals = parse_qs(urlsplit(path).query).get(name)
    return vals[0] if vals else None


def _cookie(header: str, name: str) -> str | None:
    for part in header.split(";"):
        k, _, v = part.strip().partition("=")
        if k == name:
            return v
    return None
