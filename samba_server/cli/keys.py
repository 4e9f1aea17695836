"""``samba-keys``: a session CA and the certificates of the server, the motes and pose readers,
for ``--tls DIR`` (mutual TLS + access control, see ``docs/security.md``); the work is in
:mod:`samba_common.keys`.

    samba-keys init keys/ --motes cam0,cam1,cam2,cam3 [--clients laptop] [--host 192.168.1.10]
    samba-keys add-mote keys/ --id cam4
    samba-keys add-client keys/ --id laptop
    samba-keys show keys/ [--session NAME]     (certificates and the generated access control)

Exit codes: 0 ok, 1 runtime error (names the file), 2 usage.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path


def _ids(text: str) -> list[str]:
    """``"cam0,cam1"`` or ``"4"`` (= cam0..cam3) -> ids."""
    text = text.strip()
    if text.isdigit():
        return [f"cam{i}" for i in range(int(text))]
    return [t.strip() for t in text.split(",") if t.strip()]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-keys", description="Session CA and certificates for --tls "
                                 "(mutual TLS and access control between motes, server and readers).")
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("init", help="new session CA, server certificate, and mote/client certificates")
    p.add_argument("dir", help="keys folder to create")
    p.add_argument("--motes", default="4", help="mote ids, e.g. cam0,cam1 or a count N for cam0..camN-1 "
                   "(default: %(default)s)")
    p.add_argument("--clients", default="", help="read-only pose readers, e.g. laptop,viewer (default: none)")
    p.add_argument("--host", action="append", default=[], help="server DNS name or IP to put in its certificate "
                   "besides loopback (repeatable; informative: motes check the CA, not the name)")
    p.add_argument("--force", action="store_true", help="replace an existing CA (every certificate must be re-issued)")
    for name, what in (("add-mote", "a mote"), ("add-client", "a read-only client")):
        q = sub.add_parser(name, help=f"certificate for {what}, signed by the folder's CA")
        q.add_argument("dir")
        q.add_argument("--id", required=True, help="mote id (= camera name) or client name")
    s = sub.add_parser("show", help="list the certificates and print the server's access control")
    s.add_argument("dir")
    from samba_common import zenoh_util as zk

    s.add_argument("--session", default=zk.DEFAULT_SESSION, help="session name (default: %(default)s)")
    for sp in (p, s, *(sub.choices[n] for n in ("add-mote", "add-client"))):
        sp.add_argument("-v", "--verbose", action="store_true", help="log details")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")

    from samba_common import keys

    try:
        if args.cmd == "init":
            motes, clients = _ids(args.motes), _ids(args.clients) if args.clients else []
            try:
                for i in motes + clients:
                    zk.mote_prefix("x", i)
            except ValueError as exc:
                ap.error(str(exc))
            keys.init_keys(args.dir, motes, clients, tuple(args.host), force=args.force)
            print(f"wrote {args.dir}: session CA, server, {len(motes)} mote(s) ({', '.join(motes)})"
                  + (f", {len(clients)} client(s) ({', '.join(clients)})" if clients else ""))
            print(f"server: samba-server ... --tls {args.dir} --listen tls/0.0.0.0:7447")
            if motes:
                print(f"mote:   copy {args.dir}/ca.crt and {args.dir}/motes/{motes[0]}.* to the board, then "
                      f"samba-mote --id {motes[0]} ... --tls {args.dir} --connect tls/SERVER_IP:7447")
        elif args.cmd in ("add-mote", "add-client"):
            try:
                zk.mote_prefix("x", args.id)
            except ValueError as exc:
                ap.error(str(exc))
            ident = (keys.add_mote if args.cmd == "add-mote" else keys.add_client)(args.dir, args.id)
            print(f"wrote {ident.cert} and {ident.key} (restart the server to admit it)")
        else:
            if not (Path(args.dir) / "ca.crt").is_file():
                raise keys.KeysError(f"{Path(args.dir) / 'ca.crt'}: missing (create it with samba-keys init)")
            motes, clients = keys.list_names(args.dir, "motes"), keys.list_names(args.dir, "clients")
            print(f"{args.dir}: server, motes: {', '.join(motes) or '-'}; clients: {', '.join(clients) or '-'}")
            print(json.dumps(keys.access_control(args.session, motes, clients), indent=2))
    except keys.KeysError as exc:
        print(f"samba-keys: {exc}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # `samba-keys show DIR | head` is not an error
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:
        print(f"samba-keys: {getattr(exc, 'filename', None) or args.dir}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
