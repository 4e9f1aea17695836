"""samba-demo as a user reaches it: the stdout line names the endpoint and session, and a Zenoh
client given exactly those receives the JSON poses (encoding application/json)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time

import pytest

from samba_common import zenoh_util as zk

from .conftest import free_endpoint

zenoh = pytest.importorskip("zenoh")


def test_demo_prints_how_to_reach_it_and_serves_there():
    ep = free_endpoint()
    proc = subprocess.Popen([sys.executable, "-m", "samba_server.cli.demo", "--duration", "8", "--quiet",
                             "--session", "t13", "--listen", ep], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        line = proc.stdout.readline()
        m = re.search(r"session (\S+) on (\S+) .*connect with: --connect (\S+) --session (\S+)", line)
        assert m, f"no endpoint/session line on stdout: {line!r}"
        assert m.group(1) == "t13" and m.group(2) == ep and m.group(3) == ep and m.group(4) == "t13"
        poses, encodings = [], set()

        def on(sample):
            encodings.add(str(sample.encoding))
            poses.append(json.loads(sample.payload.to_bytes()))

        with zenoh.open(zk.make_config(mode="client", connect=[m.group(3)])) as z:
            z.declare_subscriber(zk.pose_json_key(m.group(4)), on)
            end = time.monotonic() + 30
            while len(poses) < 30 and time.monotonic() < end and proc.poll() is None:
                time.sleep(0.05)
        assert len(poses) >= 30, f"{len(poses)} poses reached a client from the printed line"
        assert encodings == {"application/json"}
        assert any("solved" in p["flags"] for p in poses)
    finally:
        out, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err[-2000:]


def test_demo_rejects_a_bad_listen_endpoint():
    proc = subprocess.run([sys.executable, "-m", "samba_server.cli.demo", "--listen", "7447"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--listen" in proc.stderr
