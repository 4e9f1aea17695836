"""Simulated motes on Zenoh for the demo, tests and the latency benchmark.

Each mote projects the markers of a known take into its camera (``samba_mote.sim`` geometry:
lens distortion, image bounds, body occlusion), adds centroid noise, and publishes
``MarkerPacket`` s on its own Zenoh session with a liveliness token, like a real mote whose
tracker labels correctly. Network effects are simulated: packet loss, delivery jitter,
a per-mote clock offset and phase, and killing/restarting a mote mid-take.

The demo and the latency benchmark publish :func:`load_demo_take`: the shipped
``samba_common/data/demo_take.npz``, 8 s of joints derived from the CMU Graphics Lab Motion
Capture Database (subject 2, trial 5). "The data used in this project was obtained from
mocap.cs.cmu.edu. The database was created with funding from NSF EIA-0196217."
"""

from __future__ import annotations

import heapq
import logging
import threading
import time
from dataclasses import dataclass, field
from importlib.resources import files

import numpy as np

from samba_common import zenoh_util as zk
from samba_common.calib import CameraRig
from samba_common.wire import FLAG_TRACKED, MarkerPacket, encode_packet

log = logging.getLogger(__name__)


@dataclass
class SimNetwork:
    """Simulated imperfections. offsets_ms / phases_ms: per mote (cycled); kill: {mote index:
    (stop s, restart s)} relative to the start of the take."""

    drop: float = 0.0
    jitter_ms: float = 0.0
    base_latency_ms: float = 0.0
    offsets_ms: tuple[float, ...] = (0.0,)
    phases_ms: tuple[float, ...] = (0.0,)
    noise_px: float = 0.05
    kill: dict[int, tuple[float, float]] = field(default_factory=dict)
    seed: int = 0


def load_demo_take() -> tuple[np.ndarray, np.ndarray]:
    """The shipped clip with the standard pose in front: ((F, 13, 3) m, (F,) s) at 60 fps."""
    from samba_mote.sim.tpose import prepend_tpose

    with files("samba_common").joinpath("data", "demo_take.npz").open("rb") as fh, np.load(fh, allow_pickle=False) as z:
        joints, t = z["joints"].astype(float), z["t"].astype(float)
    j, t, _ = prepend_tpose(joints, t, 60.0)
    return j, t


def project_take(rig: CameraRig, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """joints (F, 13, 3) -> uv (C, F, 8, 2) raw pixels, visible (C, F, 8) bool."""
    from samba_mote.sim.render import SimConfig, project_markers

    cfg = SimConfig()
    uvs, vis = [], []
    for cam in rig.cameras:
        uv, _r, v = project_markers(cam, joints, cfg)
        uvs.append(uv)
        vis.append(v & np.isfinite(uv).all(axis=2))
    return np.stack(uvs), np.stack(vis)


def make_packet(mote_id: str, seq: int, t_ns: int, uv: np.ndarray, visible: np.ndarray, size: tuple[int, int],
                rng: np.random.Generator, noise_px: float) -> MarkerPacket:
    """MarkerPacket of one mote frame: uv (8, 2) px, visible (8,) bool."""
    idx = np.flatnonzero(visible)
    pts = uv[idx] + rng.normal(0.0, noise_px, (len(idx), 2)) if noise_px > 0 else uv[idx]
    return MarkerPacket(mote_id, seq, int(t_ns), size[0], size[1], 128, idx.astype(np.uint8),
                        pts.astype(np.float32), np.full(len(idx), 12, np.uint16),
                        np.full(len(idx), FLAG_TRACKED, np.uint8))


class SimMotes:
    """Publish a take from simulated motes (one Zenoh session each) in a background thread.

    joints (F, 13, 3) at ``fps``; ``loop`` repeats the take. ``ground_truth(t_ns)`` gives the
    frame index shown at a server time.
    """

    def __init__(self, rig: CameraRig, joints: np.ndarray, fps: float, session: str, connect: list[str],
                 net: SimNetwork | None = None, loop: bool = False, tls: str | None = None, mode: str = "peer"):
        """tls: keys folder (samba-keys): each mote connects with its own certificate."""
        self.rig = rig
        self.tls = tls
        self.mode = mode  #: Zenoh mode of the motes' sessions ("client" behind a router)
        self.joints = joints
        self.fps = fps
        self.session = session
        self.connect = list(connect)
        self.net = net or SimNetwork()
        self.loop = loop
        self.uv, self.visible = project_take(rig, joints)
        self.sent = 0
        self.dropped = 0
        self.start_ns = 0
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._sessions: dict[int, object] = {}
        self._pubs: dict[int, object] = {}
        self._tokens: dict[int, object] = {}

    def _open(self, m: int, wait_match: float = 0.0) -> None:
        """Open mote m's session; with ``wait_match`` only publish once the server matched."""
        import zenoh

        name = self.rig.names[m]
        extra = None
        if self.tls:
            from samba_common.keys import mote_settings

            extra = mote_settings(self.tls, name)
        z = zenoh.open(zk.make_config(mode=self.mode, connect=self.connect, extra=extra))
        self._sessions[m] = z
        self._tokens[m] = z.liveliness().declare_token(zk.liveliness_key(self.session, name))
        pub = z.declare_publisher(zk.markers_key(self.session, name), express=True)
        deadline = time.monotonic() + wait_match
        while wait_match and not pub.matching_status.matching and time.monotonic() < deadline:
            time.sleep(0.005)
        self._pubs[m] = pub

    def _close(self, m: int) -> None:
        z = self._sessions.pop(m, None)
        self._pubs.pop(m, None)
        self._tokens.pop(m, None)
        if z is not None:
            z.close()

    def open_all(self, timeout: float = 5.0) -> bool:
        """Open every mote session and wait until each publisher matches the server."""
        for m in range(len(self.rig.names)):
            self._open(m)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(p.matching_status.matching for p in self._pubs.values()):
                return True
            time.sleep(0.01)
        return False

    def start(self, start_ns: int | None = None) -> "SimMotes":
        if not self._sessions:
            self.open_all()
        self.start_ns = start_ns or time.time_ns() + 50_000_000
        self._thread = threading.Thread(target=self._run, name="sim-motes", daemon=True)
        self._thread.start()
        return self

    def frame_of(self, t_ns: int) -> int:
        """Take frame index captured at server time ``t_ns`` (nearest)."""
        return int(round((t_ns - self.start_ns) * self.fps / 1e9))

    def _run(self) -> None:
        net, C, F = self.net, len(self.rig.names), len(self.joints)
        rng = np.random.default_rng(net.seed)
        period = 1e9 / self.fps
        heap: list[tuple[int, int, int, int]] = []  # (send time, mote, frame k, seq)
        seqs = [0] * C
        killed: set[int] = set()
        k_next = 0
        try:
            while not self._stop.is_set():
                # schedule the next capture of every mote
                t_cap = self.start_ns + k_next * period
                if not self.loop and k_next >= F:
                    if not heap:
                        break
                elif k_next < F or self.loop:
                    if len(heap) < 4 * C:
                        for m in range(C):
                            cap = int(t_cap + net.phases_ms[m % len(net.phases_ms)] * 1e6)
                            lat = net.base_latency_ms + rng.uniform(-net.jitter_ms, net.jitter_ms) + net.jitter_ms
                            heapq.heappush(heap, (cap + int(lat * 1e6), m, k_next, 0))
                        k_next += 1
                        continue
                send, m, k, _ = heap[0]
                now = time.time_ns()
                if send > now:
                    time.sleep(min((send - now) / 1e9, 0.005))
                    continue
                heapq.heappop(heap)
                t_rel = (k * period) / 1e9
                if m in net.kill:
                    stop_s, restart_s = net.kill[m]
                    if stop_s <= t_rel < restart_s:
                        if m not in killed:
                            killed.add(m)
                            self._close(m)
                            log.info("sim mote %s killed", self.rig.names[m])
                        continue
                    if m in killed and t_rel >= restart_s:
                        killed.discard(m)
                        # reopen in the background: the other motes keep streaming meanwhile
                        threading.Thread(target=self._open, args=(m, 3.0), daemon=True).start()
                        seqs[m] = 0
                        log.info("sim mote %s restarted", self.rig.names[m])
                if rng.random() < net.drop:
                    self.dropped += 1
                    seqs[m] += 1
                    continue
                cap = int(self.start_ns + k * period + net.phases_ms[m % len(net.phases_ms)] * 1e6)
                t_mote = cap + int(net.offsets_ms[m % len(net.offsets_ms)] * 1e6)
                fk = k % F
                pkt = make_packet(self.rig.names[m], seqs[m], t_mote, self.uv[m, fk], self.visible[m, fk],
                                  self.rig.cameras[m].size, rng, net.noise_px)
                seqs[m] += 1
                pub = self._pubs.get(m)
                if pub is not None:
                    pub.put(encode_packet(pkt))
                    self.sent += 1
        finally:
            self.done.set()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for m in list(self._sessions):
            self._close(m)

    def __enter__(self) -> "SimMotes":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()


def _main(argv: list[str] | None = None) -> int:
    """``python -m samba_server.simmotes --connect EP --session S --motes 4 --fps 60 --duration 5``:
    run simulated motes in their own process (used by benchmarks/latency.py)."""
    import argparse

    from samba_common.calib import default_rig

    ap = argparse.ArgumentParser(prog="python -m samba_server.simmotes")
    ap.add_argument("--connect", required=True)
    ap.add_argument("--session", default="bench")
    ap.add_argument("--motes", type=int, default=4)
    ap.add_argument("--fps", type=float, default=60.0)
    ap.add_argument("--duration", type=float, default=5.0)
    ap.add_argument("--tls", help="keys folder (samba-keys) for mutual TLS")
    args = ap.parse_args(argv)
    joints, _ = load_demo_take()
    sim = SimMotes(default_rig(args.motes), joints, args.fps, args.session, [args.connect], loop=True,
                   tls=args.tls)
    if not sim.open_all(timeout=10):
        print("not matched", flush=True)
        return 1
    print("ready", flush=True)
    sim.start()
    time.sleep(args.duration)
    sim.stop()
    print(f"sent {sim.sent}", flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover
    import sys

    sys.exit(_main())
