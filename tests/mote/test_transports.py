"""Transports on real channels: Zenoh on loopback (scouting off), pyserial loop://, the
serial->Zenoh gateway, MCAP recording, backoff on failures, and the samba-mote CLI."""

from __future__ import annotations

import os
import queue
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import serial
import zenoh

from samba_common import zenoh_util as zk
from samba_common.framing import FrameReader
from samba_common.wire import FLAG_TRACKED, decode_packet, decode_status, encode_packet, encode_status, MoteStatus
from samba_mote.pipeline import MotePipeline
from samba_mote.runner import MoteRunner
from samba_mote.sources import open_source
from samba_mote.transports import InprocBus, InprocTransport, McapRecorder, Resilient, SerialTransport, ZenohTransport


def _server(port: int):
    return zenoh.open(zk.make_config(listen=[f"tcp/127.0.0.1:{port}"]))


def test_key_expressions() -> None:
    assert zk.markers_key("s1", "cam0") == "samba/s1/mote/cam0/markers"
    assert zk.liveliness_key("s1", "cam0") == "samba/s1/mote/cam0"
    assert zk.status_key("s1", "*") == "samba/s1/mote/*/status"
    assert zk.calibration_key("s1") == "samba/s1/calibration"
    assert zk.pose_json_key("s1") == "samba/s1/pose/json"
    assert zk.mote_id_from_key("samba/s1/mote/cam3/markers") == "cam3"
    with pytest.raises(ValueError):
        zk.markers_key("a/b", "cam0")


def test_first_reply_tells_an_answer_an_error_and_nobody_apart(free_port: int) -> None:
    """What the mote's calibration fetch and the replay's progress poll rely on: a reply's
    payload, an error reply's reason (the mote logs it, the player asks again), and None for a
    key nobody serves (the player falls back), over real Zenoh on loopback."""
    server = _server(free_port)
    client = zenoh.open(zk.make_config(connect=[f"tcp/127.0.0.1:{free_port}"]))
    qs = [server.declare_queryable("t/ok", lambda q: q.reply(q.key_expr, b"calibration")),
          server.declare_queryable("t/err", lambda q: q.reply_err(b"no calibration loaded"))]
    try:
        deadline = time.monotonic() + 5.0
        while zk.first_reply(client, "t/ok", 0.5)[0] is None and time.monotonic() < deadline:
            time.sleep(0.05)  # until the sessions have met
        assert zk.first_reply(client, "t/ok", 2.0) == (b"calibration", None)
        assert zk.first_reply(client, "t/err", 2.0) == (None, "no calibration loaded")
        t0 = time.monotonic()
        assert zk.first_reply(client, "t/nobody", 2.0) == (None, None)
        assert time.monotonic() - t0 < 1.5  # nobody serves it: the query ends at once
    finally:
        for q in qs:
            q.undeclare()
        client.close()
        server.close()


def test_zenoh_mote_to_server_loopback(free_port: int, small_take) -> None:
    server = _server(free_port)
    inbox: queue.Queue = queue.Queue()
    status: queue.Queue = queue.Queue()
    alive: list = []
    calib_text = small_take.rig.dumps().encode()
    subs = [server.declare_subscriber(zk.markers_key("t1", "*"), lambda s: inbox.put(s.payload.to_bytes())),
            server.declare_subscriber(zk.status_key("t1", "*"), lambda s: status.put(s.payload.to_bytes())),
            server.liveliness().declare_subscriber(zk.liveliness_key("t1", "*"),
                                                   lambda s: alive.append((str(s.key_expr), str(s.kind))), history=True),
            server.declare_queryable(zk.calibration_key("t1"), lambda q: q.reply(q.key_expr, calib_text))]
    try:
        mote = ZenohTransport("cam0", "t1", connect=(f"tcp/127.0.0.1:{free_port}",))
        assert mote.wait_matched(5.0)
        raw = mote.fetch_calibration(2.0)
        assert raw == calib_text
        from samba_common.calib import CameraRig

        rig = CameraRig.loads(raw)
        pipe = MotePipeline(None, "cam0", calibration=rig)
        runner = MoteRunner(lambda: open_source(f"file:{small_take.video('cam0')}?realtime=0"), pipe, Resilient(lambda: mote),
                            status_period=0.05, max_frames=60)
        stats = runner.run()
        assert stats.frames == 60 and stats.packets_sent == 60 and stats.send_failures == 0
        got = [decode_packet(inbox.get(timeout=2.0)) for _ in range(60)]
        assert [p.seq for p in got] == list(range(60))
        last = got[-1]
        assert last.mote_id == "cam0" and (last.width, last.height) == (160, 120)
        tracked = last.labels[(last.flags & FLAG_TRACKED) > 0]
        assert len(set(tracked.tolist()) & set(range(8))) >= 6  # labelled from the T-pose
        assert decode_status(status.get(timeout=2.0)).mote_id == "cam0"
        mote.close()
        deadline = time.monotonic() + 2.0
        while len(alive) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert alive[0] == ("samba/t1/mote/cam0", "SampleKind.PUT")
        assert alive[1] == ("samba/t1/mote/cam0", "SampleKind.DELETE")
    finally:
        for s in subs:
            s.undeclare()
        server.close()


def test_serial_loop_round_trip() -> None:
    t = SerialTransport("loop://")
    sent = []
    for i in range(50):
        p = MotePipeline(None, "m1").process(i * 16_666_667, np.full((120, 160), 10, np.uint8))
        p.seq = i
        sent.append(encode_packet(p))
        t.send_markers(sent[-1])
    t.send_status(encode_status(MoteStatus("m1", 5, fps=60.0)))
    reader, got = FrameReader(), []
    while chunk := t.port.read(4096):
        got += list(reader.feed(chunk))
    t.close()
    assert got[:50] == sent and reader.errors == 0
    assert decode_status(got[50]).fps == 60.0


def test_gateway_serial_to_zenoh(free_port: int) -> None:
    from samba_common.framing import frame
    from samba_mote.gateway import Gateway

    server = _server(free_port)
    inbox: queue.Queue = queue.Queue()
    sub = server.declare_subscriber(zk.markers_key("g", "*"), lambda s: inbox.put((str(s.key_expr), s.payload.to_bytes())))
    gw_session = zenoh.open(zk.make_config(connect=[f"tcp/127.0.0.1:{free_port}"]))
    port = serial.serial_for_url("loop://", timeout=0.05)
    packets = []
    for i in range(20):
        p = MotePipeline(None, "cam7").process(i, np.zeros((120, 160), np.uint8))
        packets.append(encode_packet(p))
    gw = Gateway(gw_session, "g", lambda: port)
    stop = threading.Event()
    th = threading.Thread(target=gw.run, args=(stop,))
    th.start()
    try:
        time.sleep(1.0)  # let the gateway's publisher match the server
        port.write(b"\x05junk\x00")  # a corrupt frame is dropped and counted
        for b in packets:
            port.write(frame(b))
        port.write(frame(b"SMBM-not-a-packet"))
        got = [inbox.get(timeout=3.0) for _ in range(20)]
    finally:
        stop.set()
        th.join(5.0)
        gw.close()
        sub.undeclare()
        gw_session.close()
        server.close()
    assert all(k == "samba/g/mote/cam7/markers" for k, _ in got)
    assert [b for _, b in got] == packets
    assert gw.stats.packets == 20 and gw.stats.bad_frames == 1 and gw.stats.bad_payloads == 1


def test_resilient_backoff_counts_and_recovers() -> None:
    bus = InprocBus()
    got: list = []
    bus.subscribe(lambda kind, payload: got.append((kind, payload)))
    attempts = []

    def factory():
        attempts.append(time.monotonic())
        if len(attempts) < 3:
            raise OSError("network down")
        return InprocTransport(bus)

    r = Resilient(factory, backoff=0.05, max_backoff=0.2)
    assert r.inner is None and r.errors == 1
    deadline = time.monotonic() + 3.0
    while not r.send_markers(b"x") and time.monotonic() < deadline:
        time.sleep(0.01)
    assert got == [("markers", b"x")]
    assert r.errors == 2 and r.dropped >= 1 and len(attempts) == 3


def test_mcap_record(tmp_path, small_take) -> None:
    from mcap.reader import make_reader

    rec = McapRecorder(tmp_path / "cam0.mcap", "cam0")
    pipe = MotePipeline(None, "cam0")
    runner = MoteRunner(lambda: open_source(f"file:{small_take.video('cam0')}?realtime=0"), pipe, InprocTransport(InprocBus()),
                        recorder=rec, max_frames=25)
    runner.run()
    rec.close()
    with open(tmp_path / "cam0.mcap", "rb") as fh:
        msgs = [(c.topic, m.data) for _s, c, m in make_reader(fh).iter_messages(topics=["/mote/cam0/markers"])]
    assert len(msgs) == 25
    assert [decode_packet(d).seq for _, d in msgs] == list(range(25))


def test_runner_reopens_failing_source(small_take) -> None:
    from samba_mote.sources import SourceError

    calls = []

    class Flaky:
        size, fps = (160, 120), 60.0

        def __init__(self):
            self.n = 0

        def read(self):
            self.n += 1
            if len(calls) == 1 and self.n == 5:
                raise SourceError("unplugged")
            return self.n * 16_666_667, small_take.cameras[0].frames[self.n]

        def close(self):
            pass

    def opener():
        calls.append(1)
        if len(calls) == 2:
            raise SourceError("still unplugged")
        return Flaky()

    runner = MoteRunner(opener, MotePipeline(None, "cam0"), InprocTransport(InprocBus()), max_frames=12,
                        reopen_backoff=0.01)
    stats = runner.run()
    assert stats.frames == 12 and stats.source_errors == 2 and stats.reopen_count == 1 and len(calls) == 3


def test_cli_serial_record_and_exit_codes(tmp_path, small_take) -> None:
    from samba_mote.cli.mote import main

    out = tmp_path / "rec.mcap"
    assert main(["--id", "cam1", "--source", f"file:{small_take.video('cam1')}?realtime=0", "--transport", "serial:loop://",
                 "--calibration", str(small_take.out_dir / "calibration.toml"), "--record", str(out),
                 "--preview", str(tmp_path / "preview"), "--max-frames", "40"]) == 0
    assert out.stat().st_size > 1000
    assert len(list((tmp_path / "preview").glob("cam1_*.png"))) == 2  # frames 1 and 31
    assert main(["--id", "cam1", "--source", "nope:x", "--transport", "serial:loop://"]) == 2
    with pytest.raises(SystemExit) as exc:
        main(["--source", "sim:"])
    assert exc.value.code == 2


def test_cli_sigterm_clean_shutdown(free_port: int) -> None:
    env = dict(os.environ, OPENCV_LOG_LEVEL="ERROR")
    proc = subprocess.Popen([sys.executable, "-m", "samba_mote.cli.mote", "--id", "cam0", "--source",
                             "sim:?seconds=3&loop=1", "--listen", f"tcp/127.0.0.1:{free_port}",
                             "--calibration-timeout", "0.2"], stderr=subprocess.PIPE, text=True, env=env)
    try:
        time.sleep(4.0)
        assert proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "ended: stopped" in err and "frames in" in err


def test_mote_package_imports_without_scipy() -> None:
    """Motes are small boards: the mote code must not pull in scipy."""
    code = ("import sys; import samba_mote.cli.mote, samba_mote.cli.gateway, samba_mote.gateway, samba_mote.pipeline, "
            "samba_mote.sources, samba_mote.transports, samba_mote.runner; "
            "assert 'scipy' not in sys.modules, 'scipy imported'")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=60)
