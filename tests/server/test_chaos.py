"""The fault harness against the server: what the server reports must equal what was injected.

Virtual clock (exact counts, minutes of take in seconds): loss with bursts, ±20 ms jitter,
reordering, duplicates, late and malformed packets, a stranger's packets, clock offsets of
±2 s and drifts of ±200 ppm, a mote killed and restarted. Real Zenoh on loopback: the same
faults through :class:`ChaosRelay`, then the server killed and restarted while the motes
run, and the router between them restarted.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from samba_common import zenoh_util as zk
from samba_common.calib import default_rig
from samba_server.chaos import ChaosLink, ChaosRelay, FaultConfig, simulate
from samba_server.live import LiveServer
from samba_server.server import Server, ServerConfig
from samba_server.simmotes import SimMotes
from samba_server.sync import SyncConfig

from .conftest import free_endpoint, overloaded, short_take

T0 = 1_700_000_000_000_000_000


def _virtual_server(clock: list[int], n_motes: int = 4, max_wait_ms: float = 45.0) -> Server:
    return Server(default_rig(n_motes), config=ServerConfig(keep_history=False),
                  sync_config=SyncConfig(max_wait_ms=max_wait_ms), clock=lambda: clock[0])


@pytest.mark.parametrize("faults,kill", [
    (FaultConfig(loss=0.30, burst=4.0, jitter_ms=20.0, duplicate=0.03, late=0.01, malformed=0.01, unknown=0.01,
                 offsets_ms=(0.0, 2000.0, -2000.0, 750.0), drift_ppm=(0.0, 200.0, -200.0, 100.0), seed=1),
     {3: (8.0, 10.0)}),
    (FaultConfig(loss=0.05, burst=1.0, jitter_ms=2.0, base_latency_ms=3.0, duplicate=0.01, late=0.005,
                 malformed=0.02, unknown=0.0, offsets_ms=(-1500.0, 30.0, 0.0, 1999.0),
                 drift_ppm=(-150.0, 0.0, 50.0, 200.0), seed=2), {}),
])
def test_reported_counts_equal_injected(faults, kill):
    joints, _ = short_take(2.0)
    clock = [T0]
    server = _virtual_server(clock)
    seconds = 30.0 if kill else 20.0
    r = simulate(server, joints, 60.0, seconds, faults, kill=kill, clock=clock, t0_ns=T0)
    inj, rep = r.injected["total"], r.server
    sent = inj["sent"]
    assert sent == 4 * 60 * seconds - sum(int((b - a) * 60) for a, b in kill.values())
    assert abs(inj["lost"] / sent - faults.loss) < 0.05 and inj["reordered"] >= (100 if faults.jitter_ms > 10 else 0)
    # drops by cause: injected == reported (within 1 % of the packets sent; exact here)
    tol = 0.01 * sent
    assert abs(rep["drops"]["late"] - inj["late"]) <= tol, (rep["drops"], inj)
    assert abs(rep["drops"]["duplicate"] - inj["duplicate"]) <= tol
    assert rep["drops"]["malformed"] == inj["malformed"]
    assert rep["drops"]["unknown_mote"] == inj["unknown"]
    assert rep["drops"]["queue_overflow"] == 0
    # every packet that arrived in time is in a frame: frames and degraded frames as expected
    assert abs(rep["frames"] - r.expected_frames) <= 0.01 * r.expected_frames
    for m, st in rep["motes"].items():
        # after a restart the clock filter starts afresh: for up to 0.5 s its estimate may still
        # be off by the jitter, and the mote's packets can miss their frame (docs/reliability.md)
        allowed = max(2, 0.01 * r.expected_frames) + 30 * st["restarts"]
        assert abs(st["missing"] - r.expected_missing[m]) <= allowed, (m, st, r.expected_missing)
        assert abs(st["late"] - r.injected["motes"][m]["late"]) <= max(1, 0.01 * sent / 4)
        assert st["duplicate"] == r.injected["motes"][m]["duplicate"]
    assert rep["degraded"] >= max(r.expected_missing.values())
    if kill:
        assert rep["motes"]["cam3"]["restarts"] >= 1  # (a loss burst > dead_after_ms counts as one too)
    # clock estimates: offset = mote clock - server clock, up to the minimum latency
    min_latency_ms = faults.base_latency_ms - faults.jitter_ms
    rig = default_rig(4)
    for i, m in enumerate(rig.names):
        st = rep["motes"][m]
        off = faults.offsets_ms[i % len(faults.offsets_ms)]
        drift = faults.drift_ppm[i % len(faults.drift_ppm)]
        t_end_s = seconds
        expected_off = off + drift * 1e-6 * t_end_s * 1e3 - min_latency_ms
        assert abs(st["clock_offset_ms"] - expected_off) < 2.0, (m, st, expected_off)
        assert st["drift_ppm"] is not None and abs(st["drift_ppm"] - drift) < 40.0, (m, st, drift)
    # latency stays bounded by the wait for late packets
    assert np.percentile(r.latency_ms, 99) < faults.base_latency_ms + faults.jitter_ms + 45.0 + 20.0


def test_link_counts_and_damage_are_what_it_says():
    """The fault model itself: damaged packets never decode, strangers decode as strangers."""
    from samba_common.wire import PacketError, decode_packet, encode_packet
    from samba_server.simmotes import make_packet

    link = ChaosLink(FaultConfig(loss=0.2, burst=3.0, duplicate=0.1, malformed=0.3, unknown=0.2, late=0.1,
                                 offsets_ms=(1000.0,), drift_ppm=(100.0,), seed=5), ["cam0"])
    rng = np.random.default_rng(0)
    uv, vis = np.full((8, 2), 50.0), np.ones(8, bool)
    kinds = {"ok": 0, "bad": 0, "stranger": 0}
    for k in range(2000):
        t = T0 + k * 16_666_667
        data = encode_packet(make_packet("cam0", k, t, uv, vis, (160, 120), rng, 0.0))
        for _arr, key, out in link.process("cam0", data, t):
            try:
                pkt = decode_packet(out)
            except PacketError:
                kinds["bad"] += 1
                continue
            if key == "cam0":
                kinds["ok"] += 1
                assert pkt.t_ns == t + 1_000_000_000 + int(100e-6 * (t - T0)) or abs(
                    pkt.t_ns - (t + 1e9 + 100e-6 * (t - T0))) <= 1
            else:
                assert pkt.mote_id == key == "chaos-stranger"
                kinds["stranger"] += 1
    c = link.totals()
    assert kinds["bad"] == c.malformed and kinds["stranger"] == c.unknown
    assert kinds["ok"] == c.delivered + c.duplicate and c.delivered + c.lost == c.sent == 2000
    assert 0.15 < c.lost / c.sent < 0.25


def _wait(pred, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.05)
    return pred()


def test_zenoh_relay_server_restart_and_router_restart():
    import zenoh

    joints, _ = short_take(1.0)
    rig = default_rig(4)
    router_ep = free_endpoint()
    router = zenoh.open(zk.make_config(mode="router", listen=[router_ep]))
    faults = FaultConfig(loss=0.1, burst=2.0, jitter_ms=5.0, base_latency_ms=6.0, duplicate=0.02, late=0.01,
                         malformed=0.01, unknown=0.01, offsets_ms=(0.0, 1500.0, -2000.0, 300.0),
                         drift_ppm=(0.0, 200.0, -200.0, 0.0), seed=7)
    link = ChaosLink(faults, rig.names)
    # behind a router everybody is a Zenoh client (peers would expect a full mesh)
    sim = SimMotes(rig, joints, 60.0, "raw", [router_ep], loop=True, mode="client")
    relay = ChaosRelay(link, "raw", "live", connect=[router_ep], mode="client")

    def make_server() -> tuple[Server, LiveServer]:
        s = Server(rig, config=ServerConfig(keep_history=False), sync_config=SyncConfig(max_wait_ms=30.0))
        return s, LiveServer(s, session="live", connect=[router_ep], mode="client").start()

    server, live = make_server()
    try:
        relay.start()
        assert sim.open_all(timeout=10)
        sim.start()
        # phase 1: faults through the relay; counts checked against the link's
        assert _wait(lambda: server.stats.frames > 360, 30), server.report()
        time.sleep(4.0)
        relay_done = link.totals()
        live.close()  # phase 2: the server is killed while the motes run ...
        rep = server.report()
        sent = relay_done.sent
        assert rep["drops"]["malformed"] <= relay_done.malformed and relay_done.malformed - rep["drops"]["malformed"] <= 0.01 * sent
        assert rep["drops"]["unknown_mote"] <= relay_done.unknown and relay_done.unknown - rep["drops"]["unknown_mote"] <= 0.01 * sent
        assert abs(rep["drops"]["duplicate"] - relay_done.duplicate) <= 0.01 * sent
        # over a real network on a shared 2-core box, real scheduling delays add some late
        # packets of their own (exact equality is checked on the virtual clock above); on an
        # overloaded machine many more (245 against 22 injected, with two benchmarks beside)
        assert relay_done.late - 0.01 * sent <= rep["drops"]["late"], (rep, relay_done)
        if not overloaded():
            assert rep["drops"]["late"] <= relay_done.late + 0.04 * sent, (rep, relay_done)
        for i, m in enumerate(rig.names):
            assert abs(rep["motes"][m]["clock_offset_ms"] - faults.offsets_ms[i]) < 15.0, rep["motes"][m]
        time.sleep(1.0)
        server, live = make_server()  # ... and started again: it picks the motes up
        assert _wait(lambda: len(server.sync.alive()) == 4 and server.stats.frames > 60, 15), server.report()
        # phase 3: the router is restarted under everybody
        router.close()
        time.sleep(0.5)
        router = zenoh.open(zk.make_config(mode="router", listen=[router_ep]))
        before = server.stats.frames
        assert _wait(lambda: server.stats.frames > before + 120 and len(server.sync.alive()) == 4, 20), server.report()
        assert server.stats.frames > 0 and not server.stats.queue_overflow
    finally:
        sim.stop()
        relay.close()
        live.close()
        router.close()


def test_samba_chaos_cli(capsys):
    from samba_server.cli.chaos import main

    code = main(["sim", "--seconds", "6", "--loss", "0.2", "--burst", "3", "--jitter-ms", "10", "--duplicate", "0.05",
                 "--late", "0.02", "--malformed", "0.02", "--unknown", "0.02", "--offsets-ms", "0,1500,-2000,5",
                 "--drift-ppm", "0,200,-200,0", "--kill", "2:2:3"])
    out = capsys.readouterr().out
    assert code == 0, out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines() if line.split()}
    sent = int(out.split()[0])
    for cause in ("late", "duplicate", "malformed"):
        assert abs(int(rows[cause][0]) - int(rows[cause][1])) <= 0.01 * sent  # injected == reported ± 1 %
    assert "cam2" in rows and int(rows["cam2"][-1]) >= 1  # the restart (a held-back old packet may add one)
    with pytest.raises(SystemExit) as exc:
        main(["sim", "--loss", "2"])
    assert exc.value.code == 2
