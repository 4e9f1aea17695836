"""Two file motes on real Zenoh (loopback) -> live server -> recording; the recording replays
exactly in-process (``samba-replay --out``) and, republished at full speed into a second live
server (``samba-replay --speed max --connect``), gives every frame with the same grouping."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from samba_mote.pipeline import MotePipeline
from samba_mote.runner import MoteRunner
from samba_mote.sources import SourceGone, open_source
from samba_mote.transports import ZenohTransport
from samba_server.app import build_server, load_server_configs, make_reconstructor
from samba_server.live import LiveServer
from samba_server.replay import Player, replay_into, take_calibration
from samba_server.server import Server, ServerConfig

from .conftest import free_endpoint


@pytest.fixture(scope="module")
def file_take(tmp_path_factory):
    from samba_mote.sim import SimConfig, make_take

    return make_take(tmp_path_factory.mktemp("fm"), None, rig=2, seconds=1.0, seed=3,
                     config=SimConfig(tpose_stance="apart", pose_at=None))


def _run_motes(take, endpoint: str, session: str) -> list:
    """Both motes play their video in real time from the same start instant, like cameras."""
    start = time.time() + 1.0
    stats = [None, None]

    def run(i: int, cam: str) -> None:
        tr = ZenohTransport(cam, session, connect=(endpoint,))
        try:
            tr.wait_matched(5.0)
            runner = MoteRunner(lambda: open_source(f"file:{take.video(cam)}?start={start}"),
                                MotePipeline(None, cam, calibration=take.rig), tr)
            stats[i] = runner.run()
        finally:
            tr.close()

    threads = [threading.Thread(target=run, args=(i, cam)) for i, cam in enumerate(("cam0", "cam1"))]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout=60)
    return stats


def _replay_server(take_path, configs) -> Server:
    toml = take_calibration(take_path)
    from samba_common.calib import CameraRig

    return Server(CameraRig.loads(toml, path=str(take_path)), toml, make_reconstructor(None, configs.reconstruct),
                  ServerConfig(**{**configs.server.__dict__, "max_lag_ms": 0.0}), configs.sync, configs.triangulate,
                  label_config=configs.labelling)


def _same(a: list, b: list, servers: tuple = ()) -> None:
    """Poses ``a`` and ``b`` equal frame by frame; a failure names the frames that differ with
    their views, markers and flags, and the servers' per-mote sync counters (``servers``)."""
    assert len(a) == len(b)
    ja, jb = np.stack([p.joints for p in a]), np.stack([p.joints for p in b])
    diff = ~np.isclose(np.nan_to_num(ja), np.nan_to_num(jb), atol=1e-9, rtol=0).all(axis=(1, 2))
    diff |= (np.isnan(ja) != np.isnan(jb)).any(axis=(1, 2))
    if diff.any():
        frames = [(int(i), [(p.n_views, p.n_markers, p.flags) for p in (a[i], b[i])]) for i in np.nonzero(diff)[0][:5]]
        sync = [{m: (st.received, st.late, st.duplicate, st.missing) for m, st in srv.sync.motes.items()}
                for srv in servers]
        raise AssertionError(f"{int(diff.sum())} of {len(a)} poses differ; first (frame, [(views, markers, flags) "
                             f"a, b]): {frames}; sync (received, late, duplicate, missing) per server: {sync}")
    assert [p.t_ns - a[0].t_ns for p in a] == [p.t_ns - b[0].t_ns for p in b]


def test_file_motes_live_replay_and_max_speed(tmp_path, file_take) -> None:
    configs = load_server_configs()  # the packaged live settings, max_lag_ms included
    take_path = tmp_path / "take.mcap"
    endpoint = free_endpoint()
    server = build_server(file_take.out_dir / "calibration.toml", configs, record=str(take_path))
    with LiveServer(server, session="fm", listen=[endpoint]):
        stats = _run_motes(file_take, endpoint, "fm")
        time.sleep(0.5)
    server.recorder.close()
    n_video = len(file_take.cameras[0].frames) if hasattr(file_take.cameras[0], "frames") else None
    assert all(s is not None and s.end_reason == "source ended" for s in stats)
    assert stats[0].frames == stats[1].frames and (n_video is None or stats[0].frames == n_video)
    # real time, like a camera: about the file's 60 fps, not as fast as possible
    assert stats[0].seconds >= 0.8 * stats[0].frames / 60.0
    live = server.poses
    assert len(live) >= 0.95 * stats[0].frames
    # a loaded 2-core machine may fall behind the motes: the server then skips solves (max_lag_ms),
    # flags and counts them; the frames it had time for are solved
    assert sum(p.solved for p in live) >= 0.5 * (len(live) - server.stats.solve_skipped)

    # samba-replay --out: exactly the live poses (frames whose solve live skipped are skipped again)
    rep = _replay_server(take_path, configs)
    replay_into(rep, take_path)
    _same(live, rep.poses, (server, rep))

    # samba-replay --speed max --connect: a second live server gets every frame, grouped as recorded,
    # and solves them all (equal to an in-process replay that skips nothing)
    endpoint2 = free_endpoint()
    server2 = build_server(file_take.out_dir / "calibration.toml", configs)
    with LiveServer(server2, session="fm2", listen=[endpoint2]):
        sent = Player(take_path, "fm2", connect=[endpoint2], speed=None).play()
    assert sent == sum(s.packets_sent for s in stats)
    assert server.skip_seqs is None and server2.skip_seqs is not None  # live motes vs a replay (see below)
    ref = _replay_server(take_path, configs)
    replay_into(ref, take_path, solve_all=True)  # samba-replay --out --solve-all: without the recorded skips
    _same(ref.poses, server2.poses, (ref, server2))
    assert sum(p.solved for p in server2.poses) >= sum(p.solved for p in live)


def test_a_live_server_too_slow_to_solve_says_so_and_the_recording_solves_all(tmp_path, file_take, capsys) -> None:
    """A live server behind its motes skips solves (max_lag_ms, here so small that every frame is
    late): at the end it says how many, warns with the reason and the way out, and exits 3;
    ``samba-replay --out`` gives the live poses (none solved), ``--solve-all`` solves them."""
    from dataclasses import replace

    from samba_common.formats import load_joints
    from samba_server.app import _take_summary
    from samba_server.cli.replay import main as replay_main

    configs = load_server_configs()
    configs = replace(configs, server=replace(configs.server, max_lag_ms=1e-6))
    take_path, endpoint = tmp_path / "take.mcap", free_endpoint()
    server = build_server(file_take.out_dir / "calibration.toml", configs, record=str(take_path))
    with LiveServer(server, session="slow", listen=[endpoint]):
        _run_motes(file_take, endpoint, "slow")
        time.sleep(0.5)
    server.recorder.close()
    n = server.stats.frames
    assert n > 30 and server.stats.solve_skipped == n and server.stats.solved == 0
    capsys.readouterr()
    assert _take_summary(server) == 3
    err = capsys.readouterr().err
    assert f"{n} frames, 0 solved, {n} solves skipped" in err
    assert "WARNING: only 0 of" in err and "fell behind" in err and "--solve-all" in err

    assert replay_main([str(take_path), "--out", str(tmp_path / "live.npz")]) == 0
    assert "--solve-all solves them" in capsys.readouterr().err
    assert not np.isfinite(load_joints(tmp_path / "live.npz").joints).all(axis=(1, 2)).any()
    assert replay_main([str(take_path), "--out", str(tmp_path / "all.npz"), "--solve-all"]) == 0
    joints = load_joints(tmp_path / "all.npz").joints
    assert len(joints) == n and np.isfinite(joints).all(axis=(1, 2)).sum() >= 0.5 * n


@pytest.mark.parametrize("replaying", [False, True])
def test_a_server_behind_a_replay_keeps_its_frames_whole(replaying: bool) -> None:
    """A server that falls behind a replay at full speed (its clock past the recorded stamps)
    must not release a frame by the wall clock while the frame's last packet is on its way:
    it would solve the frame from one view and drop the other as late, unlike the recording
    (CI once lost the last frame's second view so). Live motes keep the wall clock: a frame
    waiting for a dead mote is released when the queue runs dry."""
    from samba_common.calib import default_rig
    from samba_common.wire import encode_packet
    from samba_server.simmotes import make_packet

    t0, period = 1_700_000_000_000_000_000, 16_666_667
    clock = [t0]
    server = Server(default_rig(2), clock=lambda: clock[0])
    server.skip_seqs = set() if replaying else None
    rng = np.random.default_rng(0)
    uv, vis = np.full((8, 2), 50.0), np.ones(8, bool)

    def put(cam: str, k: int) -> None:
        pkt = make_packet(cam, k, t0 + k * period, uv, vis, (160, 120), rng, 0.0)
        server.ingest(cam, encode_packet(pkt), arrival_ns=t0 + k * period + 2_000_000)

    for k in range(3):
        put("cam0", k)
        put("cam1", k)
    server.process_pending()
    n, incomplete, late = len(server.poses), server.sync.frames_incomplete, server.sync.motes["cam1"].late
    put("cam0", 3)
    clock[0] = t0 + 10_000_000_000  # the server is 10 s behind the stamps; the queue runs dry
    server.process_pending(timeout=0.001)
    put("cam1", 3)
    server.process_pending()
    server.finish()
    assert len(server.poses) == n + 1
    if replaying:  # frame 3 waited for its second view, as in an in-process replay
        assert (server.sync.frames_incomplete, server.sync.motes["cam1"].late) == (incomplete, late)
    else:  # live: released at once without cam1, whose packet then came too late
        assert (server.sync.frames_incomplete, server.sync.motes["cam1"].late) == (incomplete + 1, late + 1)


def _packet_take(path, n_frames: int = 120) -> int:
    """A recorded 2-mote take of ``n_frames`` frames at 60 fps; returns its packet count."""
    from samba_common.calib import default_rig
    from samba_common.wire import encode_packet
    from samba_server.record import Recorder
    from samba_server.simmotes import make_packet

    rig = default_rig(2)
    rng = np.random.default_rng(0)
    uv, vis = np.full((8, 2), 50.0), np.ones(8, bool)
    with Recorder(path, calibration_toml=rig.dumps().encode()) as rec:
        for k in range(n_frames):
            for name in rig.names:
                t = 1_000_000_000 + k * 16_666_667
                rec.write_packet(name, encode_packet(make_packet(name, k, t, uv, vis, (160, 120), rng, 0.05)),
                                 t + 500_000)
    return n_frames * len(rig.names)


def test_replay_waits_for_a_stalled_server_and_reports_losses(tmp_path, capsys) -> None:
    """samba-replay --connect --speed max leaves only once the server has taken in and processed
    every packet, even when the server stalls (a recorder blocked on the disk: its Zenoh
    callback stops taking packets in, its poses stop for longer than the player's quiet wait).
    A server that loses packets makes samba-replay say so and exit 1."""
    from samba_common.calib import default_rig
    from samba_server.cli.replay import main as replay_main

    path = tmp_path / "take.mcap"
    n = _packet_take(path)
    server = Server(default_rig(2))
    ingest, calls = server.ingest, [0]

    def stalling(*a, **kw) -> bool:
        calls[0] += 1
        if calls[0] == 50:
            time.sleep(1.5)
        return ingest(*a, **kw)

    handle, handled = server._handle, [0]

    def counting(item) -> list:
        out = handle(item)
        handled[0] += item[0] == "packet"
        return out

    server.ingest, server._handle = stalling, counting
    endpoint = free_endpoint()
    with LiveServer(server, session="st", listen=[endpoint]):
        player = Player(path, "st", connect=[endpoint], speed=None)
        assert player.play() == n
        # every packet processed (not the backlog: the player's motes leave as it ends, and a
        # loaded machine may not have handled those two leaves yet)
        assert calls[0] == n and handled[0] == n and player.taken_in == n
    assert len(server.poses) == n // 2

    lossy = Server(default_rig(2))
    lossy_ingest, seen = lossy.ingest, [0]

    def losing(*a, **kw) -> bool:  # every 10th packet dropped, as by a full queue
        seen[0] += 1
        return seen[0] % 10 != 0 and lossy_ingest(*a, **kw)

    lossy.ingest = losing
    endpoint = free_endpoint()
    t0 = time.monotonic()
    with LiveServer(lossy, session="lo", listen=[endpoint]):
        code = replay_main([str(path), "--connect", endpoint, "--session", "lo", "--speed", "max"])
    assert code == 1 and time.monotonic() - t0 < 20
    assert f"{n} packets published, the server took in {n - n // 10}" in capsys.readouterr().err


def test_missing_video_file_fails_at_once(tmp_path) -> None:
    from samba_mote.cli.mote import main

    with pytest.raises(SourceGone, match="not found"):
        open_source(f"file:{tmp_path / 'missing.avi'}")
    t0 = time.monotonic()
    assert main(["--id", "cam0", "--source", f"file:{tmp_path / 'missing.avi'}", "--transport", "serial:loop://"]) == 1
    assert time.monotonic() - t0 < 5.0
