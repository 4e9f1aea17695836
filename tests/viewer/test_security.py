"""Who may use the viewer: its own origin only, loopback Host names only, a token beyond loopback.

A real websocket client on loopback sends the headers a browser would send; the last test opens
a page from another origin in headless Chromium (skipped without it) that tries to connect and
start a recording.
"""

from __future__ import annotations

import http.server
import shutil
import subprocess
import threading
import time
import urllib.error
import urllib.parse
import urllib.request

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from samba_server.viewer import Viewer
from samba_server.viewer.server import is_loopback

from .test_protocol import _until


def _ws(viewer, origin=None, host=None, path="/ws", **kw):
    """WebSocket to the viewer on 127.0.0.1, asking for ``host`` (the Host header) if given."""
    import socket

    sock = socket.create_connection(("127.0.0.1", viewer.port), timeout=5)
    return connect(f"ws://{host or f'127.0.0.1:{viewer.port}'}{path}", sock=sock, origin=origin,
                   open_timeout=5, **kw)


def _refused(fn) -> int:
    with pytest.raises(InvalidStatus) as exc:
        fn().close()
    return exc.value.response.status_code


def test_same_origin_page_connects_and_records(viewer):
    with _ws(viewer, origin=f"http://127.0.0.1:{viewer.port}") as ws:
        _until(ws, "hello")
        ws.send('{"type": "record", "start": true}')
        ws.send('{"type": "record", "start": false}')
        _ws_wait(lambda: viewer.calls == [True, False])
    with _ws(viewer, origin=f"http://localhost:{viewer.port}", host=f"localhost:{viewer.port}") as ws:
        _until(ws, "hello")
    assert viewer.stats.refused == 0


def _ws_wait(cond, timeout=5.0):
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end and not cond():
        time.sleep(0.01)
    assert cond()


@pytest.mark.parametrize("origin", ["http://evil.example", "http://127.0.0.1:1", "null",
                                    "http://127.0.0.1.evil.example"])
def test_cross_origin_websocket_is_refused(viewer, origin):
    assert _refused(lambda: _ws(viewer, origin=origin)) == 403
    assert viewer.calls == [] and viewer.stats.refused == 1 and viewer.stats.clients == 0


def test_dns_rebinding_host_is_refused(viewer):
    """A page at evil.example resolving to 127.0.0.1 has a matching Origin and Host: refused by name."""
    host = f"evil.example:{viewer.port}"
    assert _refused(lambda: _ws(viewer, origin=f"http://{host}", host=host)) == 403
    req = urllib.request.Request(viewer.url, headers={"Host": host})
    with pytest.raises(urllib.error.HTTPError) as exc:
        urllib.request.urlopen(req, timeout=5)
    assert exc.value.code == 403


def test_token_required_beyond_loopback():
    assert is_loopback("127.0.0.1") and is_loopback("::1") and is_loopback("localhost")
    assert not is_loopback("0.0.0.0") and not is_loopback("192.168.1.10")
    far = Viewer("0.0.0.0", 8080)  # not started: only its token and URL are checked
    assert far.token and len(far.token) >= 20 and far.url.endswith(f"?token={far.token}")
    assert Viewer("127.0.0.1", 8080).token is None and "token" not in Viewer("127.0.0.1", 8080).url


def test_token_is_checked(tmp_path):
    calls: list = []
    with Viewer("127.0.0.1", 0, on_record=calls.append, token="s3cret-token") as v:
        base = f"http://127.0.0.1:{v.port}/"
        with pytest.raises(urllib.error.HTTPError) as exc:
            urllib.request.urlopen(base, timeout=5)
        assert exc.value.code == 403
        res = urllib.request.urlopen(v.url, timeout=5)
        cookie = res.headers["Set-Cookie"]
        assert "s3cret-token" in cookie and "SameSite=Strict" in cookie and "HttpOnly" in cookie
        origin = f"http://127.0.0.1:{v.port}"
        assert _refused(lambda: _ws(v, origin=origin)) == 403
        assert _refused(lambda: _ws(v, origin=origin, path="/ws?token=wrong")) == 403
        with _ws(v, origin=origin, path="/ws?token=s3cret-token") as ws:
            _until(ws, "hello")
        with connect(f"ws://127.0.0.1:{v.port}/ws", origin=origin, open_timeout=5,
                     additional_headers={"Cookie": "samba_viewer_token=s3cret-token"}) as ws:
            _until(ws, "hello")
        # the right token from the wrong origin is still refused
        assert _refused(lambda: _ws(v, origin="http://evil.example", path="/ws?token=s3cret-token")) == 403
        assert calls == [] and v.stats.refused == 4


CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")

EVIL_PAGE = """<!doctype html><html><body><script>
function report(r) { fetch("/result?r=" + encodeURIComponent(r)); }
let settled = false;
const ws = new WebSocket("ws://127.0.0.1:%(port)d/ws");
ws.onopen = () => { settled = true; report("open");
  ws.send(JSON.stringify({type: "record", start: true})); };
ws.onmessage = (e) => { report("read:" + e.data.slice(0, 20)); };
ws.onerror = () => { if (!settled) { settled = true; report("refused"); } };
</script></body></html>"""


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (apt-get install -y chromium)")
def test_a_page_from_another_origin_cannot_connect_or_record(tmp_path, viewer):
    """The page reports what its websocket did back to its own server; the test waits in real time.

    (A ``--virtual-time-budget`` with ``--dump-dom`` could end before the handshake settled on a
    loaded machine, reading "pending".)
    """
    page = (EVIL_PAGE % {"port": viewer.port}).encode()
    results: list[str] = []
    reported = threading.Event()

    class Evil(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # noqa: N802 - http.server's naming
            if self.path.startswith("/result?r="):
                results.append(urllib.parse.unquote(self.path.split("=", 1)[1]))
                reported.set()
                body = b""
            else:
                body = page
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *a):
            pass

    evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Evil)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--no-first-run", f"--user-data-dir={tmp_path / 'profile'}",
           f"http://127.0.0.1:{evil.server_address[1]}/"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        reported.wait(timeout=90)
        time.sleep(0.5)  # anything the page does after its first report (a message read) lands too
    finally:
        proc.kill()
        stderr = proc.communicate(timeout=30)[1]
        evil.shutdown()
    assert results, f"the page never reported: {stderr[-2000:]}"
    assert results == ["refused"], results
    assert viewer.calls == [] and viewer.stats.refused >= 1
