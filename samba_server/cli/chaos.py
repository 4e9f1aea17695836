"""``samba-chaos``: the fault harness (docs/reliability.md).

``samba-chaos sim``: simulated motes -> faults -> server on a virtual clock; prints what was
injected next to what the server reported; exit 1 if a drop cause differs by more than 1 % of
the packets sent. ``samba-chaos relay``: sit on Zenoh between motes publishing on session
``--from`` and a server listening on session ``--to`` until Ctrl-C or ``--duration``.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading

from samba_server.app import setup_logging


def _floats(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def _kill(text: str) -> tuple[int, float, float]:
    try:
        m, a, b = text.split(":")
        return int(m), float(a), float(b)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MOTE:STOP_S:RESTART_S, got {text!r}") from None


def _fault_args(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--loss", type=float, default=0.0, help="mean packet loss 0..0.3 (default 0)")
    ap.add_argument("--burst", type=float, default=1.0, help="mean loss burst length in packets (default 1)")
    ap.add_argument("--jitter-ms", type=float, default=0.0, help="delivery jitter ±ms (default 0)")
    ap.add_argument("--latency-ms", type=float, default=None, help="mean delivery delay (default: max(jitter, 1))")
    ap.add_argument("--duplicate", type=float, default=0.0, help="probability of a duplicated packet")
    ap.add_argument("--late", type=float, default=0.0, help="probability a packet is held back --late-ms")
    ap.add_argument("--late-ms", type=float, default=300.0)
    ap.add_argument("--malformed", type=float, default=0.0, help="probability of an extra damaged packet")
    ap.add_argument("--unknown", type=float, default=0.0, help="probability of an extra packet from an unknown mote")
    ap.add_argument("--offsets-ms", type=_floats, default=(0.0,), help="clock offset per mote, e.g. 0,2000,-2000")
    ap.add_argument("--drift-ppm", type=_floats, default=(0.0,), help="clock drift per mote, e.g. 0,200,-200")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("-v", "--verbose", action="count", default=0)


def _faults(args):
    from samba_server.chaos import FaultConfig

    latency = args.latency_ms if args.latency_ms is not None else max(args.jitter_ms, 1.0)
    return FaultConfig(loss=args.loss, burst=args.burst, jitter_ms=args.jitter_ms, base_latency_ms=latency,
                       duplicate=args.duplicate, late=args.late, late_ms=args.late_ms, malformed=args.malformed,
                       unknown=args.unknown, offsets_ms=args.offsets_ms, drift_ppm=args.drift_ppm, seed=args.seed)


def _sim(args) -> int:
    from samba_common.calib import default_rig
    from samba_server.chaos import compare, simulate
    from samba_server.server import Server, ServerConfig
    from samba_server.simmotes import load_demo_take
    from samba_server.sync import SyncConfig

    faults = _faults(args)
    joints, _ = load_demo_take()
    clock = [1_700_000_000_000_000_000]
    server = Server(default_rig(args.motes), config=ServerConfig(keep_history=False),
                    sync_config=SyncConfig(max_wait_ms=max(12.0, 2 * args.jitter_ms + 5)), clock=lambda: clock[0])
    kill = {m: (a, b) for m, a, b in args.kill}
    r = simulate(server, joints, 60.0, args.seconds, faults, kill=kill, clock=clock)
    if args.json:
        print(json.dumps({"injected": r.injected, "reported": r.server, "expected_frames": r.expected_frames,
                          "expected_missing": r.expected_missing}, indent=1))
    sent = r.injected["total"]["sent"]
    worst = 0
    if not args.json:
        print(f"{sent} packets sent, {r.injected['total']['reordered']} reordered; frames {r.server['frames']} "
              f"(expected {r.expected_frames}), degraded {r.server['degraded']}")
        print(f"{'cause':22} {'injected':>9} {'reported':>9}")
    for what, inj, rep in compare(r.injected, r.server):
        if not args.json:
            print(f"{what:22} {inj:9d} {rep if what != 'lost (never arrives)' else '-':>9}")
        if what != "lost (never arrives)":
            worst = max(worst, abs(inj - rep))
    if not args.json:
        print(f"{'mote':8} {'missing':>8} {'expected':>8} {'offset ms':>10} {'drift ppm':>10} restarts")
        for m, st in r.server["motes"].items():
            print(f"{m:8} {st['missing']:8d} {r.expected_missing.get(m, 0):8d} {st['clock_offset_ms']:10.2f} "
                  f"{'-' if st['drift_ppm'] is None else st['drift_ppm']:>10} {st['restarts']}")
    if worst > 0.01 * sent:
        print(f"samba-chaos: reported drops differ from the injected ones by {worst} (> 1 % of {sent})", file=sys.stderr)
        return 1
    return 0


def _relay(args) -> int:
    from samba_server.chaos import ChaosLink, ChaosRelay

    link = ChaosLink(_faults(args), [])
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    try:
        with ChaosRelay(link, args.src, args.dst, connect=args.connect, listen=args.listen, mode=args.mode):
            print(f"samba-chaos: relaying samba/{args.src}/mote/* -> samba/{args.dst}/mote/* (Ctrl-C to stop)",
                  file=sys.stderr)
            stop.wait(args.duration or None)
    except KeyboardInterrupt:
        pass
    except Exception as exc:  # zenoh errors: bad endpoint, port taken
        print(f"samba-chaos: {exc}", file=sys.stderr)
        return 1
    print(json.dumps(link.report(), indent=1))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-chaos", description=__doc__.split("\n\n")[0].strip("`: \n"))
    sub = ap.add_subparsers(dest="cmd", required=True)
    sim = sub.add_parser("sim", help="virtual-clock run: simulated motes -> faults -> server, counts compared")
    sim.add_argument("--seconds", type=float, default=30.0)
    sim.add_argument("--motes", type=int, default=4)
    sim.add_argument("--kill", type=_kill, action="append", default=[], metavar="MOTE:STOP_S:RESTART_S",
                     help="kill mote index MOTE at STOP_S and restart it at RESTART_S (repeatable)")
    sim.add_argument("--json", action="store_true", help="print both reports as JSON")
    _fault_args(sim)
    relay = sub.add_parser("relay", help="Zenoh relay with faults between two sessions")
    relay.add_argument("--from", dest="src", required=True, help="session the motes publish on")
    relay.add_argument("--to", dest="dst", required=True, help="session the server listens on")
    relay.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
    relay.add_argument("--listen", action="append", default=[], metavar="ENDPOINT")
    relay.add_argument("--mode", default="peer", choices=("peer", "client"))
    relay.add_argument("--duration", type=float, default=0.0, help="stop after this many seconds (0 = Ctrl-C)")
    _fault_args(relay)
    args = ap.parse_args(argv)
    setup_logging(args.verbose)
    try:
        _faults(args)
    except ValueError as exc:
        ap.error(str(exc))
    if args.cmd == "sim" and not (1 <= args.motes <= 16 and args.seconds > 0):
        ap.error("--motes must be 1..16 and --seconds > 0")
    return _sim(args) if args.cmd == "sim" else _relay(args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
