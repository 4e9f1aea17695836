"""MCAP recorder: round trip, truncated tails, kill -9, full disk."""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from samba_server.record import (CALIBRATION_TOPIC, POSE_TOPIC, Recorder, RecorderError, TakeReader, _SafeSink,
                                 iter_messages, markers_topic)


def _payload(i: int) -> bytes:
    return bytes([i % 251]) * (100 + i % 37)


def _record(path: Path, n: int = 60, close: bool = True) -> list[tuple[str, int, bytes]]:
    sent = []
    rec = Recorder(path, calibration_toml=b"[cam_0]\nname = \"cam0\"\n", metadata={"session": "t"})
    for i in range(n):
        mote = f"cam{i % 3}"
        t = 1_000_000_000 + i * 5_000_000
        assert rec.write_packet(mote, _payload(i), arrival_ns=t, capture_ns=t - 1000, seq=i // 3)
        sent.append((markers_topic(mote), t, _payload(i)))
        if i % 10 == 9:
            assert rec.write_pose(b"pose%d" % i, publish_ns=t + 1, frame_ns=t)
            sent.append((POSE_TOPIC, t + 1, b"pose%d" % i))
    if close:
        rec.close()
    return sent


def test_round_trip_and_standard_reader(tmp_path):
    path = tmp_path / "take.mcap"
    sent = _record(path)
    reader = TakeReader(path)
    got = list(reader)
    assert not reader.truncated
    assert got[0].topic == CALIBRATION_TOPIC and got[0].data.startswith(b"[cam_0]")
    assert [(m.topic, m.log_time, m.data) for m in got[1:]] == sent
    assert got[1].mote_id == "cam0" and got[1].publish_time == got[1].log_time - 1000
    # any MCAP tool reads it: the official reader with its summary
    with path.open("rb") as fh:
        r = make_reader(fh)
        assert r.get_summary().statistics.message_count == len(sent) + 1
        assert sum(1 for _ in r.iter_messages(topics=[markers_topic("cam1")])) == 20


def test_truncated_tail_at_every_offset(tmp_path):
    path = tmp_path / "take.mcap"
    sent = _record(path, n=30, close=False)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    last = -1
    full = [(m.topic, m.data) for m in iter_messages(path)]
    assert len(full) == len(sent) + 1
    for offset in [*range(8, len(data), 7), len(data)]:
        cut.write_bytes(data[:offset])
        reader = TakeReader(cut)
        got = [(m.topic, m.data) for m in reader]
        assert got == full[:len(got)], offset  # always a clean prefix
        assert len(got) >= last  # never fewer messages from a longer file
        last = len(got)
        assert reader.truncated
    assert last == len(full)
    cut.write_bytes(data[:4])
    with pytest.raises(ValueError, match="not an MCAP"):
        list(TakeReader(cut))


def test_garbage_tail_is_tolerated(tmp_path):
    path = tmp_path / "take.mcap"
    _record(path, n=12, close=False)
    n = sum(1 for _ in iter_messages(path))
    with path.open("ab") as fh:
        fh.write(b"\x05" + b"\xff" * 8 + os.urandom(50))
    reader = TakeReader(path)
    assert sum(1 for _ in reader) == n
    assert reader.truncated


_CHILD = r"""
import sys, time
from samba_server.record import Recorder
rec = Recorder(sys.argv[1])
i = 0
while True:
    rec.write_packet("cam%d" % (i % 2), bytes([i % 256]) * 120, arrival_ns=i + 1, seq=i)
    i += 1
    if i % 50 == 0:
        print(i, flush=True)
    time.sleep(0.0005)
"""


def test_kill_9_leaves_every_reported_message(tmp_path):
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(path)], stdout=subprocess.PIPE, text=True)
    reported = 0
    deadline = time.monotonic() + 20
    try:
        while reported < 300 and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            reported = int(line)
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    assert reported >= 300
    reader = TakeReader(path)
    got = list(reader)
    assert reader.truncated
    assert len(got) >= reported
    assert [m.sequence for m in got] == list(range(len(got)))


class _FullDisk(_SafeSink):
    """Sink whose disk fills up after ``budget`` bytes."""

    def __init__(self, fd: int, budget: int):
        super().__init__(fd)
        self.budget = budget

    def write(self, data: bytes) -> int:
        if self.pos + len(data) > self.budget:
            # a partial write reaches the file before the error, like a real full disk
            os.write(self.fd, data[: max(self.budget - self.pos, 0)])
            os.ftruncate(self.fd, self.pos)
            os.lseek(self.fd, self.pos, os.SEEK_SET)
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(data)


def test_full_disk_counts_drops_and_resumes(tmp_path, caplog):
    path = tmp_path / "full.mcap"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    sink = _FullDisk(fd, budget=2000)
    rec = Recorder(path, _sink=sink)
    ok = [rec.write_packet("cam0", _payload(i), arrival_ns=i + 1, seq=i) for i in range(40)]
    assert not all(ok) and any(ok)
    assert rec.stats.dropped == ok.count(False)
    assert "disk full" in caplog.text
    sink.budget = 10**9  # space freed: recording resumes
    assert rec.write_packet("cam0", b"after", arrival_ns=99, seq=99)
    rec.close()
    os.close(fd)
    got = list(iter_messages(path))
    kept = [i for i, o in enumerate(ok) if o]
    assert [m.sequence for m in got] == kept + [99]


def test_unwritable_target_is_a_clear_error(tmp_path):
    with pytest.raises(RecorderError, match="cannot create"):
        Recorder(tmp_path / "no" / "such" / "dir.mcap")
    if Path("/dev/full").exists():
        with pytest.raises(RecorderError, match="cannot write"):
            Recorder("/dev/full")
