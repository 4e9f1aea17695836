"""``samba-mote``: run one camera mote (capture, detection, tracking, publishing).

Exit codes: 0 ok (source ended or stopped by SIGINT/SIGTERM), 1 runtime error, 2 usage.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from dataclasses import replace

from samba_common.config import ConfigError
from samba_common.zenoh_util import DEFAULT_SESSION

log = logging.getLogger("samba_mote")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="samba-mote", description="Run a Samba camera mote: capture frames, detect and "
                                "label the markers, publish marker packets over Zenoh or a serial line.")
    p.add_argument("--id", required=True, help="mote id = camera name in calibration.toml (e.g. cam0)")
    p.add_argument("--source", required=True,
                   help="v4l2:/dev/video0?width=160&height=120&fps=60 | file:cam0.avi (played in real time "
                        "like a camera; file:cam0.avi?realtime=0 as fast as possible, &start=UNIX_S to start "
                        "several file motes in step) | images:dir/%%04d.png | sim:?cam=cam0&clip=take.bvh")
    p.add_argument("--session", default=DEFAULT_SESSION, help="Zenoh session name (key prefix samba/NAME/...)")
    p.add_argument("--transport", default="zenoh",
                   help="zenoh (default) or serial:/dev/ttyUSB0?baud=921600 (use samba-gateway on the host)")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT", help="zenoh endpoint to connect to, "
                   "e.g. tcp/192.168.1.10:7447 (repeatable; default: the server's default tcp/127.0.0.1:7447)")
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT", help="zenoh endpoint to listen on")
    p.add_argument("--mode", default="peer", choices=["peer", "client"], help="zenoh mode")
    p.add_argument("--scouting", action="store_true", help="enable zenoh multicast scouting (off by default)")
    p.add_argument("--tls", metavar="KEYS_DIR", help="mutual TLS as this mote with KEYS_DIR/ca.crt and "
                   "KEYS_DIR/motes/ID.crt|key from samba-keys (endpoints tls/HOST:PORT; docs/security.md)")
    p.add_argument("--config", help="mote TOML config ([detect] and [track] tables), e.g. configs/mote.toml")
    p.add_argument("--calibration", help="calibration.toml to use (else asked from the server over zenoh)")
    p.add_argument("--calibration-timeout", type=float, default=2.0, help="s to wait for the server's calibration")
    p.add_argument("--unlabelled", action="store_true", help="publish all blobs unlabelled (wand calibration)")
    p.add_argument("--record", metavar="OUT.mcap", help="keep a local MCAP copy of everything published")
    p.add_argument("--preview", metavar="DIR", help="write an annotated PNG every 30 frames into DIR")
    p.add_argument("--max-frames", type=int, help="stop after this many frames")
    p.add_argument("-v", "--verbose", action="count", default=0, help="log more (-v info, -vv debug)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    from samba_common.calib import CalibrationError, CameraRig
    from samba_mote.pipeline import MotePipeline, load_mote_config
    from samba_mote.runner import MoteRunner
    from samba_mote.sources import SourceGone, open_source
    from samba_mote.transports import (McapRecorder, Resilient, SerialTransport, TransportError, ZenohTransport,
                                       parse_serial_url)

    if args.tls:  # keys that are missing will not appear: fail now rather than retry
        from samba_common import keys

        try:
            keys.check_endpoints(args.listen + args.connect, "endpoint")
        except ValueError as exc:
            print(f"samba-mote: {exc}", file=sys.stderr)
            return 2
        try:
            keys.mote_settings(args.tls, args.id)
        except keys.KeysError as exc:
            print(f"samba-mote: {exc}", file=sys.stderr)
            return 1
    try:
        cfg = load_mote_config(args.config)
        if args.unlabelled:
            cfg = replace(cfg, track=replace(cfg.track, mode="unlabelled"))
        rig = CameraRig.load(args.calibration) if args.calibration else None
        if args.transport.startswith("serial:"):
            url, baud = parse_serial_url(args.transport)

            def factory():
                return SerialTransport(url, baud)
        elif args.transport == "zenoh":
            def factory():
                return ZenohTransport(args.id, args.session, args.mode, tuple(args.listen), tuple(args.connect),
                                      args.scouting, tls=args.tls)
        else:
            raise ValueError(f"unknown transport {args.transport!r}: use zenoh or serial:DEVICE?baud=N")
        open_source(args.source).close()  # fail early on a bad URL (a missing camera is retried later)
    except (ConfigError, CalibrationError) as exc:  # a bad or missing file: runtime error naming it
        print(f"samba-mote: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # a bad --source URL or --transport
        print(f"samba-mote: {exc}", file=sys.stderr)
        return 2
    except SourceGone as exc:  # a missing file will not appear: fail now, do not retry
        print(f"samba-mote: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        log.warning("source not available yet (%s); will retry", exc)

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    transport = Resilient(factory, what=args.transport)
    recorder = None
    try:
        if rig is None and isinstance(transport.inner, ZenohTransport) and not args.unlabelled:
            raw = transport.inner.fetch_calibration(args.calibration_timeout)
            if raw:
                try:
                    rig = CameraRig.loads(raw, path="<server calibration>")
                    log.info("calibration received from the server (%d cameras)", len(rig))
                except CalibrationError as exc:
                    log.warning("server calibration unusable (%s); labelling from the image layout", exc)
            else:
                log.info("no calibration from the server; labelling from the image layout")
        pipeline = MotePipeline(cfg, args.id, calibration=rig)
        recorder = McapRecorder(args.record, args.id) if args.record else None
        runner = MoteRunner(lambda: open_source(args.source), pipeline, transport, recorder=recorder,
                            preview_dir=args.preview, max_frames=args.max_frames, source_label=args.source)
        stats = runner.run(stop)
    except (TransportError, OSError) as exc:
        print(f"samba-mote: {exc}", file=sys.stderr)
        return 1
    finally:
        transport.close()
        if recorder is not None:
            recorder.close()
    stats.send_failures = max(stats.send_failures, transport.dropped)
    print(f"samba-mote {args.id}: {stats.summary()}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
