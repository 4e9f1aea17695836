"""``samba-demo``: the whole system on one machine. Simulated motes (a take shipped in the
package, looped) publish marker packets over Zenoh on loopback to a live server on a free
port; a status line shows fps, latency, motes alive and drops until Ctrl-C or ``--duration``.

The shipped take is :func:`samba_server.simmotes.load_demo_take`; the server is built and run
by :mod:`samba_server.app`.
"""

from __future__ import annotations

import argparse
import socket
import sys
import tempfile
import threading
from pathlib import Path

from samba_common.calib import default_rig
from samba_server.app import Status, build_server, load_server_configs, run_live, setup_logging
from samba_server.server import Server
from samba_server.simmotes import SimMotes, SimNetwork, load_demo_take


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-demo", description="Simulated motes + live server on this machine.")
    ap.add_argument("--motes", type=int, choices=(2, 4), default=4, help="simulated cameras (default: 4)")
    ap.add_argument("--duration", type=float, help="stop after this many seconds (default: until Ctrl-C)")
    ap.add_argument("--drop", type=float, default=0.0, help="fraction of packets lost (e.g. 0.1)")
    ap.add_argument("--jitter-ms", type=float, default=0.0, help="delivery jitter, +/- ms")
    ap.add_argument("--offset-ms", type=float, default=0.0, help="clock offset of every other mote, ms")
    ap.add_argument("--http", metavar="[HOST:]PORT", help="serve the browser viewer (e.g. 8080)")
    ap.add_argument("--record", metavar="TAKE.mcap", help="record the demo take")
    ap.add_argument("--export", metavar="JOINTS.npz", help="write the poses at exit")
    ap.add_argument("--quiet", action="store_true", help="no status line")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    args = ap.parse_args(argv)
    if not 0.0 <= args.drop < 1.0:
        ap.error("--drop must be in [0, 1)")
    setup_logging(args.verbose)
    rig = default_rig(args.motes)
    tmp = tempfile.TemporaryDirectory(prefix="samba-demo-")
    calib = Path(tmp.name) / "calibration.toml"
    rig.save(calib)
    try:
        server: Server = build_server(calib, load_server_configs(), record=args.record)
    except (OSError, ValueError) as exc:
        print(f"samba-demo: {exc}", file=sys.stderr)
        return 1
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    joints, _t = load_demo_take()
    net = SimNetwork(drop=args.drop, jitter_ms=args.jitter_ms, offsets_ms=(0.0, args.offset_ms),
                     phases_ms=(0.0, 1.0, -1.5, 2.0))
    sim = SimMotes(rig, joints, 60.0, "demo", [endpoint], net, loop=True)
    run_args = argparse.Namespace(session="demo", listen=[endpoint], connect=[], scouting=False, http=args.http,
                                  duration=args.duration, export=args.export, status=not args.quiet)
    started = threading.Event()
    tty = sys.stderr.isatty()

    def on_tick(snap: dict) -> None:
        if not started.is_set():
            started.set()
            threading.Thread(target=lambda: sim.start() if sim.open_all() else None, daemon=True).start()
        if not args.quiet:
            line = Status.line(snap)
            sys.stderr.write(("\r" + line + "  ") if tty else line + "\n")
            sys.stderr.flush()

    print(f"samba-demo: {args.motes} simulated motes -> server on {endpoint}; Ctrl-C to stop", file=sys.stderr)
    try:
        code = run_live(server, run_args, on_tick=on_tick, before_close=sim.stop)
    finally:
        sim.stop()
        tmp.cleanup()
    st = server.stats
    late = sum(m.late for m in server.sync.motes.values())
    print(f"\nsamba-demo: {st.frames} frames, {st.solved} solved, {st.packets} packets, "
          f"{sim.dropped} lost on the (simulated) network, {late} late, {st.bad_packets} bad", file=sys.stderr)
    return code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
