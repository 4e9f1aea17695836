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

from samba_common import zenoh_util as zk
from samba_common.calib import default_rig
from samba_server.app import Status, build_server, load_server_configs, run_live, setup_logging
from samba_server.server import Server
from samba_server.simmotes import SimMotes, SimNetwork, load_demo_take


DEFAULT_PORT = 7447


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def port_free(host: str, port: int) -> bool:
    """True when ``host:port`` can be bound for TCP now."""
    try:
        with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as Zenoh does: TIME_WAIT is no obstacle
            s.bind((host, port))
        return True
    except OSError:
        return False


def demo_endpoints(listen: str | None, tls: bool) -> tuple[str, str]:
    """(server listen endpoint, endpoint the simulated motes connect to).

    Default: loopback port 7447, or a free loopback port when 7447 is taken. ``listen`` as
    given (e.g. ``tcp/0.0.0.0:7447`` to be reachable from the LAN); motes then connect over
    loopback. Raises ValueError on a malformed endpoint.
    """
    proto = "tls" if tls else "tcp"
    if listen is None:
        port = DEFAULT_PORT if port_free("127.0.0.1", DEFAULT_PORT) else free_port()
        ep = f"{proto}/127.0.0.1:{port}"
        return ep, ep
    scheme, sep, addr = listen.partition("/")
    host, colon, port = addr.rpartition(":")
    if not sep or not colon or scheme not in ("tcp", "tls") or not port.isdigit() or not host:
        raise ValueError(f"--listen {listen!r}: use PROTO/HOST:PORT, e.g. {proto}/127.0.0.1:7447")
    if tls and scheme != "tls":
        raise ValueError(f"--listen {listen!r}: with --tls use tls/HOST:PORT")
    local = "127.0.0.1" if host in ("0.0.0.0", "[::]") else host
    return listen, f"{scheme}/{local}:{port}"


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
    ap.add_argument("--listen", metavar="ENDPOINT", help="where the server listens (default: tcp/127.0.0.1:7447, "
                    "or a free loopback port if 7447 is taken; tcp/0.0.0.0:7447 to be reachable from the LAN)")
    ap.add_argument("--session", default=zk.DEFAULT_SESSION, help="session name, keys samba/NAME/... "
                    "(default: %(default)s)")
    ap.add_argument("--tls", metavar="KEYS_DIR", help="mutual TLS + access control; KEYS_DIR is created with "
                    "samba-keys (motes cam0..camN, client 'viewer') if it holds no keys yet")
    ap.add_argument("--quiet", action="store_true", help="no status line")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    args = ap.parse_args(argv)
    if not 0.0 <= args.drop < 1.0:
        ap.error("--drop must be in [0, 1)")
    try:
        zk.calibration_key(args.session)
        listen, mote_ep = demo_endpoints(args.listen, bool(args.tls))
    except ValueError as exc:
        ap.error(str(exc))
    setup_logging(args.verbose)
    rig = default_rig(args.motes)
    if args.tls:
        from samba_common import keys

        try:
            if not (Path(args.tls) / "ca.key").exists() and not (Path(args.tls) / "ca.crt").exists():
                keys.init_keys(args.tls, motes=list(rig.names), clients=["viewer"])
                print(f"samba-demo: created session keys in {args.tls} (samba-keys init)", file=sys.stderr)
            for name in rig.names:
                keys.mote_settings(args.tls, name)
        except (keys.KeysError, ValueError) as exc:
            print(f"samba-demo: {exc}", file=sys.stderr)
            return 1
    tmp = tempfile.TemporaryDirectory(prefix="samba-demo-")
    calib = Path(tmp.name) / "calibration.toml"
    rig.save(calib)
    try:
        server: Server = build_server(calib, load_server_configs(), record=args.record)
    except (OSError, ValueError) as exc:
        print(f"samba-demo: {exc}", file=sys.stderr)
        return 1
    joints, _t = load_demo_take()
    net = SimNetwork(drop=args.drop, jitter_ms=args.jitter_ms, offsets_ms=(0.0, args.offset_ms),
                     phases_ms=(0.0, 1.0, -1.5, 2.0))
    sim = SimMotes(rig, joints, 60.0, args.session, [mote_ep], net, loop=True, tls=args.tls)
    run_args = argparse.Namespace(session=args.session, listen=[listen], connect=[], scouting=False, http=args.http,
                                  duration=args.duration, export=args.export, status=not args.quiet,
                                  tls=args.tls, quiet=True)
    started = threading.Event()
    tty = sys.stderr.isatty()

    def on_tick(snap: dict) -> None:
        if not started.is_set():
            started.set()
            # the server is listening now: one line a user can copy (stdout, so it can be captured)
            tls_hint = f" --tls {args.tls}" if args.tls else ""
            print(f"samba-demo: session {args.session} on {listen} (poses on {zk.pose_key(args.session)}); "
                  f"connect with: --connect {mote_ep} --session {args.session}{tls_hint}", flush=True)
            threading.Thread(target=lambda: sim.start() if sim.open_all() else None, daemon=True).start()
        if not args.quiet:
            line = Status.line(snap)
            sys.stderr.write(("\r" + line + "  ") if tty else line + "\n")
            sys.stderr.flush()

    print(f"samba-demo: {args.motes} simulated motes -> server; Ctrl-C to stop", file=sys.stderr)
    try:
        code = run_live(server, run_args, on_tick=on_tick, before_close=sim.stop, summary=False)
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
