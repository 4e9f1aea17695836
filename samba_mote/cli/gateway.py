"""``samba-gateway``: republish a serial-line Samba mote onto Zenoh (:class:`samba_mote.gateway.Gateway`).

Exit codes: 0 ok, 1 runtime error, 2 usage.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
import time

from samba_common import zenoh_util as zk
from samba_mote.gateway import Gateway


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="samba-gateway", description="Republish a serial-line Samba mote onto Zenoh.")
    p.add_argument("--serial", required=True, help="serial:/dev/ttyUSB0?baud=921600")
    p.add_argument("--session", default=zk.DEFAULT_SESSION)
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT")
    p.add_argument("--mode", default="peer", choices=["peer", "client"])
    p.add_argument("--scouting", action="store_true")
    p.add_argument("--tls", metavar="KEYS_DIR", help="mutual TLS with the certificate of mote --id from samba-keys "
                   "(KEYS_DIR/ca.crt, KEYS_DIR/motes/ID.*); endpoints tls/HOST:PORT (docs/security.md)")
    p.add_argument("--id", help="with --tls: the serial mote's id (its packets under other ids are refused by the server)")
    p.add_argument("-v", "--verbose", action="count", default=0)
    args = p.parse_args(argv)
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    import serial
    import zenoh

    from samba_mote.transports import parse_serial_url

    try:
        url, baud = parse_serial_url(args.serial)
    except ValueError as exc:
        print(f"samba-gateway: {exc}", file=sys.stderr)
        return 2
    extra = None
    if args.tls:
        from samba_common import keys

        if not args.id:
            p.error("--tls needs --id (the serial mote's id, whose certificate is used)")
        try:
            keys.check_endpoints(args.listen + args.connect, "endpoint")
        except ValueError as exc:
            p.error(str(exc))
        try:
            extra = keys.mote_settings(args.tls, args.id)
        except (keys.KeysError, ValueError) as exc:
            print(f"samba-gateway: {exc}", file=sys.stderr)
            return 1
    try:
        session = zenoh.open(zk.make_config(args.mode, args.listen, args.connect, args.scouting, extra=extra))
    except Exception as exc:
        print(f"samba-gateway: cannot open zenoh session: {exc}", file=sys.stderr)
        return 1
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    gw = Gateway(session, args.session, lambda: serial.serial_for_url(url, baudrate=baud, timeout=0.2))
    t0 = time.monotonic()
    try:
        stats = gw.run(stop)
    finally:
        gw.close()
        session.close()
    print(f"samba-gateway: {stats.summary()} in {time.monotonic() - t0:.1f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
