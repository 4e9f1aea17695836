"""Recordings under abuse: ``kill -9`` of a recording server at 20 random moments, a full disk
(a real 256 kB tmpfs when the test may mount one, else a file-size limit in a child process),
and a target that cannot be written."""

from __future__ import annotations

import logging
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from samba_server.record import POSE_TOPIC, Recorder, TakeReader

# A zygote: imports the server once, then forks one recording server per "go PATH" line. Each
# child runs a real Server with a Recorder (processing thread writing poses, the main thread
# ingesting 4 motes x 60 fps of simulated packets) and prints how many packets it ingested.
_ZYGOTE = r"""
import os, sys, threading, time
import numpy as np
from samba_common.calib import default_rig
from samba_common.wire import encode_packet
from samba_server.record import Recorder
from samba_server.server import Server, ServerConfig
from samba_server.simmotes import make_packet

rig = default_rig(4)
rng = np.random.default_rng(0)
uv = np.full((8, 2), 60.0) + np.arange(16).reshape(8, 2)
vis = np.ones(8, bool)
print("ready", flush=True)
for line in sys.stdin:
    path = line.split(" ", 1)[1].strip()
    pid = os.fork()
    if pid:
        print("pid", pid, flush=True)
        os.waitpid(pid, 0)
        print("reaped", flush=True)
        continue
    server = Server(rig, recorder=Recorder(path), config=ServerConfig(keep_history=False))
    stop = threading.Event()
    threading.Thread(target=server.run, args=(stop,), daemon=True).start()
    t0, k, n = time.time_ns(), 0, 0
    while True:
        t_cap = t0 + int(k * 1e9 / 60)
        while time.time_ns() < t_cap:
            time.sleep(0.001)
        for m, name in enumerate(rig.names):
            server.ingest(name, encode_packet(make_packet(name, k, t_cap, uv, vis, (160, 120), rng, 0.0)))
            n += 1
        k += 1
        if k % 3 == 0:
            print("n", n, flush=True)
"""


def test_kill_9_at_20_random_moments_loses_at_most_the_last_second(tmp_path):
    proc = subprocess.Popen([sys.executable, "-c", _ZYGOTE], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            text=True)
    lines: list[tuple[float, str]] = []
    cond = threading.Condition()

    def read() -> None:
        for line in proc.stdout:
            with cond:
                lines.append((time.monotonic(), line.strip()))
                cond.notify_all()

    threading.Thread(target=read, daemon=True).start()

    def wait_for(prefix: str, start: int, timeout: float = 60.0) -> int:
        deadline = time.monotonic() + timeout
        with cond:
            while True:
                for i in range(start, len(lines)):
                    # (a child killed mid-print leaves a partial line in front of the zygote's)
                    if lines[i][1].startswith(prefix) or (prefix == "reaped" and lines[i][1].endswith(prefix)):
                        return i
                assert time.monotonic() < deadline, (f"no {prefix!r} from the recording process", lines[-5:],
                                                     proc.poll())
                cond.wait(0.1)

    rnd = random.Random(15)
    try:
        i = wait_for("ready", 0)
        for round_ in range(20):
            path = tmp_path / f"killed{round_}.mcap"
            proc.stdin.write(f"go {path}\n")
            proc.stdin.flush()
            i = wait_for("pid", i + 1)
            pid = int(lines[i][1].split()[1])
            i = wait_for("n ", i + 1)  # recording
            time.sleep(rnd.uniform(0.05, 2.5))
            killed = time.monotonic()
            os.kill(pid, signal.SIGKILL)
            j = wait_for("reaped", i + 1)
            counts = [(t, int(s.split()[1])) for t, s in lines[i:j] if re.fullmatch(r"n \d+", s)]
            older = max((n for t, n in counts if t <= killed - 1.0), default=0)
            reader = TakeReader(path)
            got = list(reader)  # opens, never raises
            packets = [m.sequence for m in got if m.mote_id]
            assert packets == list(range(len(packets))), f"round {round_}: gap in the recorded packets"
            assert len(packets) >= older, (round_, len(packets), older)
            if packets:  # the calibration comes first in the file
                assert sum(m.topic == "/calibration" for m in got) == 1
            if older > 60:
                assert any(m.topic == POSE_TOPIC for m in got)
            i = j
    finally:
        proc.stdin.close()
        proc.kill()
        proc.wait(timeout=10)


def _tmpfs(path: Path, size_kb: int) -> bool:
    """Mount a small tmpfs at ``path`` (root only); False if not possible here."""
    path.mkdir()
    if os.geteuid() != 0 or not shutil.which("mount"):
        return False
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(path)], capture_output=True)
    return r.returncode == 0


_T0 = time.time_ns()


def _feed(server, k0: int, n: int, rng) -> None:
    """n frames (k0..k0+n-1) of 4 motes at 60 fps of capture time, through ingest and processing
    (fed a little faster than real time; the recorder's flush timer runs on the real clock)."""
    from samba_common.wire import encode_packet
    from samba_server.simmotes import make_packet

    uv, vis = np.full((8, 2), 60.0) + np.arange(16).reshape(8, 2), np.ones(8, bool)
    for k in range(k0, k0 + n):
        t = _T0 + k * 16_666_667
        for name in server.rig.names:
            server.ingest(name, encode_packet(make_packet(name, k, t, uv, vis, (160, 120), rng, 0.0)), arrival_ns=t)
        server.process_pending()
        time.sleep(0.002)


def test_full_disk_one_error_stream_goes_on_new_file_when_space_returns(tmp_path, caplog):
    from samba_common.calib import default_rig
    from samba_server.server import Server, ServerConfig

    mnt = tmp_path / "small"
    if not _tmpfs(mnt, 256):
        pytest.skip("cannot mount a tmpfs here (not root); test_record.py covers a simulated ENOSPC")
    try:
        filler = mnt / "filler"
        filler.write_bytes(b"\0" * 150_000)
        take = mnt / "take.mcap"
        # flush every 0.1 s and keep at most 20 kB in memory while the disk is full
        rec = Recorder(take, flush_interval_s=0.1, max_pending_bytes=20_000)
        server = Server(default_rig(4), recorder=rec, config=ServerConfig(keep_history=True))
        rng = np.random.default_rng(0)
        caplog.set_level(logging.INFO, logger="samba_server.record")
        k = 0
        while not rec.stats.dropped and k < 5000:  # until the disk is full and the backlog too
            _feed(server, k, 20, rng)
            k += 20
        assert rec.stats.dropped and "disk full" in caplog.text
        errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
        assert len(errors) == 1, [r.getMessage() for r in errors]  # one clear error, not one per message
        assert str(take) in errors[0].getMessage()
        poses_full = len(server.poses)
        _feed(server, k, 60, rng)  # the live stream goes on while the disk is full
        k += 60
        assert len(server.poses) >= poses_full + 55
        assert len([r for r in caplog.records if r.levelno >= logging.ERROR]) == 1
        filler.unlink()  # space returns
        t_end = time.monotonic() + 5
        while len(rec.stats.files) < 2 and time.monotonic() < t_end:
            _feed(server, k, 10, rng)
            k += 10
        assert len(rec.stats.files) == 2 and "continues in" in caplog.text
        _feed(server, k, 30, rng)
        rec.close()
        first, second = rec.stats.files
        a, b = TakeReader(first), TakeReader(second)
        got_a, got_b = list(a), list(b)
        assert not a.truncated and not b.truncated  # both closed with their summary
        seq_a = [m.sequence for m in got_a if m.mote_id]
        assert seq_a == list(range(len(seq_a)))  # the first file: gap-free up to the full disk
        seq_b = [m.sequence for m in got_b if m.mote_id]
        assert seq_b and seq_b == list(range(seq_b[0], seq_b[0] + len(seq_b))) and seq_b[0] > seq_a[-1]
        assert sum(m.topic == "/calibration" for m in got_b) == 1  # the new file stands alone
        assert any(m.topic == POSE_TOPIC for m in got_b)
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_disk_full_for_long_ends_the_file_and_a_new_one_starts_when_space_returns(tmp_path, caplog):
    """The backlog never fits (the disk stays full past hold_s): the file is ended where it is,
    and the take goes on in a new file as soon as the user frees space."""
    from samba_common.calib import default_rig
    from samba_server.server import Server, ServerConfig

    mnt = tmp_path / "small"
    if not _tmpfs(mnt, 256):
        pytest.skip("cannot mount a tmpfs here (not root)")
    try:
        filler = mnt / "filler"
        filler.write_bytes(b"\0" * 200_000)
        take = mnt / "take.mcap"
        rec = Recorder(take, flush_interval_s=0.1, hold_s=0.5)
        server = Server(default_rig(4), recorder=rec, config=ServerConfig(keep_history=True))
        rng = np.random.default_rng(0)
        caplog.set_level(logging.INFO, logger="samba_server.record")
        k = 0
        t_end = time.monotonic() + 20
        while "ended after" not in caplog.text and time.monotonic() < t_end:
            _feed(server, k, 10, rng)
            k += 10
        assert "ended after" in caplog.text and rec.stats.dropped
        assert len([r for r in caplog.records if r.levelno >= logging.ERROR]) == 1
        _feed(server, k, 30, rng)  # still full: nothing new is created, the stream goes on
        k += 30
        assert rec.stats.files == [take] and len(server.poses) >= k - 20
        filler.unlink()
        t_end = time.monotonic() + 5
        while len(rec.stats.files) < 2 and time.monotonic() < t_end:
            _feed(server, k, 10, rng)
            k += 10
        assert len(rec.stats.files) == 2 and "continues in" in caplog.text
        _feed(server, k, 20, rng)
        rec.close()
        first = list(TakeReader(take))
        assert first and [m.sequence for m in first if m.mote_id] == list(range(sum(1 for m in first if m.mote_id)))
        b = TakeReader(rec.stats.files[1])
        got = list(b)
        assert not b.truncated and sum(m.topic == "/calibration" for m in got) == 1
        assert sum(1 for m in got if m.mote_id) >= 4 * 20
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def test_read_only_target_one_error_and_the_server_goes_on(tmp_path, caplog):
    from samba_common.calib import default_rig
    from samba_server.app import record_toggle
    from samba_server.server import Server

    mnt = tmp_path / "ro"
    if _tmpfs(mnt, 64):
        subprocess.run(["mount", "-o", "remount,ro", str(mnt)], check=True)
    else:
        mnt = Path("/proc")  # read-only for everyone
    try:
        server = Server(default_rig(4))
        toggle = record_toggle(server, mnt)
        caplog.set_level(logging.INFO)
        toggle(True)
        assert server.recorder is None
        errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
        assert len(errors) == 1 and "cannot start recording" in errors[0] and str(mnt) in errors[0]
        _feed(server, 0, 30, np.random.default_rng(0))
        assert len(server.poses) >= 25
    finally:
        if mnt != Path("/proc"):
            subprocess.run(["umount", "-l", str(mnt)], capture_output=True)
