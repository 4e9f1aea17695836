"""MCAP recorder: round trip, index and schemas for third-party readers, truncated tails,
kill -9, full disk."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from samba_server.record import (CALIBRATION_TOPIC, EVENTS_TOPIC, POSE_TOPIC, Recorder, RecorderError, TakeReader,
                                 _SafeSink, iter_messages, markers_topic)


def _payload(i: int) -> bytes:
    return bytes([i % 251]) * (100 + i % 37)


def _record(path: Path, n: int = 60, close: bool = True, flush_every: int = 0) -> list[tuple[str, int, bytes]]:
    """Record ``n`` packets of 3 motes, a pose every 10; ``flush_every`` > 0 writes a chunk every
    that many packets. Unclosed (``close=False``) takes are flushed: what a crash after the
    last chunk leaves."""
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
        if i == 4:
            assert rec.write_event(b'{"mote_id": "cam1", "event": "join", "t_ns": %d}' % t, t)
            sent.append((EVENTS_TOPIC, t, b'{"mote_id": "cam1", "event": "join", "t_ns": %d}' % t))
        if flush_every and i % flush_every == flush_every - 1:
            assert rec.flush()
    if close:
        rec.close()
    else:
        assert rec.flush()
    return sent


def test_round_trip_and_standard_reader(tmp_path, capsys):
    path = tmp_path / "take.mcap"
    sent = _record(path, flush_every=25)
    assert f"wrote {path}: {len(sent) + 1} messages" in capsys.readouterr().err
    reader = TakeReader(path)
    got = list(reader)
    assert not reader.truncated
    assert got[0].topic == CALIBRATION_TOPIC and got[0].data.startswith(b"[cam_0]")
    assert [(m.topic, m.log_time, m.data) for m in got[1:]] == sent
    assert got[1].mote_id == "cam0" and got[1].publish_time == got[1].log_time - 1000


def test_closed_take_is_indexed_with_schemas(tmp_path):
    """What indexed readers (Foxglove, @mcap/core McapIndexedReader, mcap make_reader) need:
    chunk indexes and message indexes in a summary, and a schema for every channel."""
    path = tmp_path / "take.mcap"
    sent = _record(path, flush_every=25)
    with path.open("rb") as fh:
        r = make_reader(fh)
        summary = r.get_summary()
        assert summary is not None
        assert summary.statistics.message_count == len(sent) + 1
        assert len(summary.chunk_indexes) >= 3  # 60 packets flushed every 25, then the close
        assert all(ci.message_index_offsets for ci in summary.chunk_indexes)
        assert all(ci.compression == "" for ci in summary.chunk_indexes)  # any reader, no codec
        topics = {ch.topic: ch for ch in summary.channels.values()}
        motes = {markers_topic(f"cam{i}") for i in range(3)}
        assert set(topics) == {CALIBRATION_TOPIC, POSE_TOPIC, EVENTS_TOPIC} | motes
        for ch in topics.values():
            assert ch.schema_id in summary.schemas, ch.topic
        schema = {t: summary.schemas[ch.schema_id] for t, ch in topics.items()}
        assert (schema[POSE_TOPIC].name, schema[POSE_TOPIC].encoding) == ("samba.Pose", "text/plain")
        assert b"SMBP" in schema[POSE_TOPIC].data and b"float32" in schema[POSE_TOPIC].data
        m = schema[markers_topic("cam0")]
        assert (m.name, m.encoding) == ("samba.MarkerPacket", "text/plain") and b"SMBM" in m.data
        ev = schema[EVENTS_TOPIC]
        assert ev.encoding == "jsonschema" and topics[EVENTS_TOPIC].message_encoding == "json"
        js = json.loads(ev.data)
        event = json.loads(next(d for t, _, d in sent if t == EVENTS_TOPIC))
        join_required = set(js["required"]) | set(js["allOf"][0]["then"]["required"])
        assert join_required == set(event) and event["event"] in js["properties"]["event"]["enum"]
        assert "subject" in js["properties"]["event"]["enum"]  # the live subject events
        # the index answers a topic query; everything comes back in log_time order
        assert sum(1 for _ in r.iter_messages(topics=[markers_topic("cam1")])) == 20
        times = [msg.log_time for _, _, msg in r.iter_messages()]
        assert len(times) == len(sent) + 1 and times == sorted(times)


def test_binary_schemas_are_enough_to_decode(tmp_path):
    """A third party with only the file: the header layout in the schema record unpacks the
    recorded pose and marker packet, and the listed joint order names the joints."""
    import re
    import struct

    import numpy as np

    from samba_common.pose_wire import PoseMessage, encode_pose
    from samba_common.wire import MarkerPacket, encode_packet

    joints = np.arange(39, dtype=float).reshape(13, 3) / 10
    pose = encode_pose(PoseMessage(seq=7, t_ns=1_700_000_000_123_456_789, joints=joints, flags=1))
    packet = encode_packet(MarkerPacket("cam0", seq=5, t_ns=1_700_000_000_000_000_001, width=160, height=120,
                                        threshold=200, labels=np.array([2], np.uint8),
                                        uv=np.array([[10.5, 20.25]], np.float32), area=np.array([9], np.uint16),
                                        flags=np.array([1], np.uint8)))
    path = tmp_path / "take.mcap"
    with Recorder(path) as rec:
        rec.write_pose(pose, publish_ns=1, frame_ns=1, seq=7)
        rec.write_packet("cam0", packet, arrival_ns=2)
    with path.open("rb") as fh:
        r = make_reader(fh)
        decoded = {}
        for schema, channel, msg in r.iter_messages():
            text = schema.data.decode()
            fmt = re.search(r'header\s+"(<[^"]+)"', text).group(1)  # the documented struct layout
            head = struct.unpack_from(fmt, msg.data)
            decoded[channel.topic] = (head, text, msg.data[struct.calcsize(fmt):])
    head, text, rest = decoded[POSE_TOPIC]
    assert head[0] == b"SMBP" and head[3] == 13 and head[4] == 7 and head[5] == 1_700_000_000_123_456_789
    order = re.search(r"joints \(index order\): (.*)", text).group(1).split(", ")
    xyz = np.frombuffer(rest[:13 * 12], "<f4").reshape(13, 3)  # "joints n_joints x 3 float32"
    assert order[0] == "head" and np.allclose(xyz, joints)
    head, text, rest = decoded[markers_topic("cam0")]
    assert head[0] == b"SMBM" and head[3] == 1 and head[5] == 1_700_000_000_000_000_001 and head[6:8] == (160, 120)
    assert rest[:head[-1]] == b"cam0"  # "mote id  id_len bytes of UTF-8"


_NODE_CHECK = r"""
const fs = require("fs/promises");
const { McapIndexedReader } = require("@mcap/core");
(async () => {
  const fh = await fs.open(process.argv[2], "r");
  const size = (await fh.stat()).size;
  const readable = {
    size: async () => BigInt(size),
    read: async (offset, length) => {
      const buf = new Uint8Array(Number(length));
      await fh.read(buf, 0, Number(length), Number(offset));
      return buf;
    },
  };
  const reader = await McapIndexedReader.Initialize({ readable });
  const topics = {};
  let n = 0;
  for await (const msg of reader.readMessages()) {
    const ch = reader.channelsById.get(msg.channelId);
    topics[ch.topic] = (topics[ch.topic] || 0) + 1;
    n++;
  }
  const schemas = [...reader.schemasById.values()].map((s) => [s.name, s.encoding]);
  console.log(JSON.stringify({ n, topics, chunks: reader.chunkIndexes.length, schemas }));
  await fh.close();
})().catch((e) => { console.error(String(e)); process.exit(1); });
"""


def _mcap_core_dir() -> str | None:
    """A directory whose node_modules holds @mcap/core: $SAMBA_MCAP_JS, else the working dir."""
    for d in (os.environ.get("SAMBA_MCAP_JS"), os.getcwd()):
        if d and (Path(d) / "node_modules" / "@mcap" / "core" / "package.json").exists():
            return d
    return None


def test_typescript_indexed_reader_reads_every_message(tmp_path):
    """@mcap/core (what Foxglove uses) through its indexed reader. Runs only where node and an
    installed @mcap/core are present (``npm install @mcap/core`` in a directory, then
    SAMBA_MCAP_JS=that directory); the Python index checks above always run."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    js_dir = _mcap_core_dir()
    if js_dir is None:
        pytest.skip("@mcap/core is not installed (set SAMBA_MCAP_JS to a directory with node_modules/@mcap/core)")
    path = tmp_path / "take.mcap"
    sent = _record(path, flush_every=25)
    script = tmp_path / "check.js"
    script.write_text(_NODE_CHECK)
    proc = subprocess.run([node, str(script), str(path)], cwd=js_dir, capture_output=True, text=True, timeout=60,
                          env={**os.environ, "NODE_PATH": str(Path(js_dir) / "node_modules")})
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["n"] == len(sent) + 1 and out["chunks"] >= 3
    assert out["topics"][POSE_TOPIC] == 6 and out["topics"][markers_topic("cam2")] == 20
    assert ["samba.Event", "jsonschema"] in out["schemas"]


def test_truncated_tail_at_every_offset(tmp_path):
    path = tmp_path / "take.mcap"
    sent = _record(path, n=30, close=False, flush_every=4)
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
    assert n == 12 + 1 + 1 + 1  # packets, a pose, an event, the calibration
    with path.open("ab") as fh:
        fh.write(b"\x05" + b"\xff" * 8 + os.urandom(50))
    reader = TakeReader(path)
    assert sum(1 for _ in reader) == n
    assert reader.truncated


_CHILD = r"""
import sys, time
from samba_server.record import Recorder
rec = Recorder(sys.argv[1])
n, pause = int(sys.argv[2]), sys.argv[3] == "pause"
i = 0
while True:
    if i == n and pause:
        print("paused", i, flush=True)
        time.sleep(3600)
    rec.write_packet("cam%d" % (i % 2), bytes([i % 256]) * 120, arrival_ns=i + 1, seq=i)
    i += 1
    if i % 50 == 0:
        print("wrote", i, flush=True)
    time.sleep(0.0005)
"""


def _kill_child(path: Path, n: int, pause: bool, after_s: float) -> tuple[list[tuple[float, int]], float]:
    """Run the recording child; ``after_s`` after it reported ``n`` messages, kill -9 it.
    Returns the (time.monotonic, count) reports and the time of the kill."""
    proc = subprocess.Popen([sys.executable, "-c", _CHILD, str(path), str(n), "pause" if pause else "run"],
                            stdout=subprocess.PIPE, text=True)
    reports: list[tuple[float, int]] = []
    reached = threading.Event()

    def read() -> None:
        for line in proc.stdout:
            reports.append((time.monotonic(), int(line.split()[1])))
            if reports[-1][1] >= n:
                reached.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        reached.wait(30)
        time.sleep(after_s)
    finally:
        killed = time.monotonic()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        reader.join(timeout=10)
        proc.stdout.close()
    return reports, killed


def test_kill_9_keeps_everything_older_than_a_second(tmp_path):
    path = tmp_path / "killed.mcap"
    reports, killed = _kill_child(path, 300, pause=False, after_s=1.5)
    assert reports and reports[-1][1] >= 300
    older = max(n for t, n in reports if t <= killed - 1.0)  # on record more than 1 s before the kill
    reader = TakeReader(path)
    got = list(reader)
    assert reader.truncated  # no summary: read by a linear scan
    assert len(got) >= older >= 300
    assert [m.sequence for m in got] == list(range(len(got)))


def test_kill_9_after_a_pause_keeps_everything(tmp_path):
    """Messages then silence: the flush timer writes the last chunk although nothing follows."""
    path = tmp_path / "paused.mcap"
    reports, _ = _kill_child(path, 120, pause=True, after_s=1.0)
    assert reports[-1][1] == 120
    got = list(TakeReader(path))
    assert [m.sequence for m in got] == list(range(120))


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


def test_full_disk_holds_then_drops_and_resumes(tmp_path, caplog):
    path = tmp_path / "full.mcap"
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    sink = _FullDisk(fd, budget=5000)
    # a chunk per message; up to ~1.5 kB held in memory while the disk is full
    rec = Recorder(path, _sink=sink, flush_interval_s=0.0, max_pending_bytes=1500)
    ok = [rec.write_packet("cam0", _payload(i), arrival_ns=i + 1, seq=i) for i in range(40)]
    assert not all(ok) and any(ok)
    assert rec.stats.dropped == ok.count(False)
    assert rec.stats.pending > 0  # held, not lost
    assert "disk full" in caplog.text
    sink.budget = 10**9  # space freed: the backlog goes out with the next message
    assert rec.write_packet("cam0", b"after", arrival_ns=99, seq=99)
    # the backlog completes the first file; after the gap the take goes on in a new file
    assert rec.stats.pending == 0 and "continues in" in caplog.text
    second = tmp_path / "full-2.mcap"
    assert rec.stats.files == [path, second]
    rec.close()
    os.close(fd)
    got = list(iter_messages(path))
    kept = [i for i, o in enumerate(ok) if o]
    assert [m.sequence for m in got] == kept  # every accepted message before the gap, in order
    with path.open("rb") as fh:
        assert make_reader(fh).get_summary().statistics.message_count == len(kept)
    assert [m.sequence for m in iter_messages(second)] == [99]
    with second.open("rb") as fh:
        assert make_reader(fh).get_summary().statistics.message_count == 1


def test_unwritable_target_is_a_clear_error(tmp_path):
    with pytest.raises(RecorderError, match="cannot create"):
        Recorder(tmp_path / "no" / "such" / "dir.mcap")
    if Path("/dev/full").exists():
        with pytest.raises(RecorderError, match="cannot write"):
            Recorder("/dev/full")
