"""``samba-replay``: republish a take on Zenoh with its timing, or (``--out``) re-run it through
the server pipeline in-process (:func:`samba_server.replay.replay_into`) and write joints.npz."""

from __future__ import annotations

import argparse
import logging
import sys
import threading
from pathlib import Path

from samba_common.calib import CalibrationError, CameraRig
from samba_common.config import ConfigError
from samba_common.progress import Progress
from samba_server.activity import MoteActivity
from samba_server.app import (add_network_args, export_joints, load_server_configs, make_reconstructor, setup_logging,
                               warn_few_cameras)
from samba_server.record import TakeReader, take_placement
from samba_server.replay import Player, replay_into, take_calibration, take_subject
from samba_server.server import Server, ServerConfig

log = logging.getLogger(__name__)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-replay", description="Replay a recorded take.")
    ap.add_argument("take", help="take.mcap")
    ap.add_argument("--speed", default="1.0", help="1.0 = original timing, 2 = twice as fast, 'max' = no waiting")
    add_network_args(ap)
    ap.add_argument("--out", metavar="JOINTS.npz",
                    help="instead of publishing, re-run the take through the server pipeline in-process "
                         "(exactly the live poses) and write joints.npz")
    ap.add_argument("--solve-all", action="store_true",
                    help="with --out: also solve the frames whose solve the live server skipped because it was "
                         "behind (the poses then differ from the live ones there)")
    ap.add_argument("--calibration", help="calibration.toml (default: the one recorded in the take)")
    ap.add_argument("--db", help="motion database for --out (default: the shipped one)")
    ap.add_argument("--config", help="server TOML for --out")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    args = ap.parse_args(argv)
    setup_logging(args.verbose)
    if args.speed == "max":
        speed = None
    else:
        try:
            speed = float(args.speed)
        except ValueError:
            ap.error("--speed must be a number or 'max'")
        if speed <= 0:
            ap.error("--speed must be > 0")
    try:
        if args.out:
            toml = Path(args.calibration).read_bytes() if args.calibration else take_calibration(args.take)
            if toml is None:
                print("samba-replay: the take has no calibration; pass --calibration", file=sys.stderr)
                return 1
            rig = CameraRig.loads(toml, path=args.calibration or f"{args.take} (its recorded calibration)")
            warn_few_cameras(rig)
            cfg = load_server_configs(args.config, take_placement(args.take))  # placed as live
            subject = take_subject(args.take)  # recorded with --subject: solve with it again
            server = Server(rig, toml, make_reconstructor(args.db, cfg.reconstruct, subject),
                            ServerConfig(**{**cfg.server.__dict__, "max_lag_ms": 0.0}), cfg.sync, cfg.triangulate,
                            label_config=cfg.labelling)
            activity = MoteActivity(rig.names)
            server.packet_listeners.append(activity)
            n = sum(1 for _ in TakeReader(args.take))
            with Progress(n, "samba-replay") as bar:
                reader = replay_into(server, args.take, bar.update, solve_all=args.solve_all)
            frames = export_joints(server, args.out)
            note = " (take truncated: read up to its last complete record)" if reader.truncated else ""
            skipped = server.stats.solve_skipped
            if skipped:
                note += f"; {skipped} solves skipped, as live (the server was behind): --solve-all solves them"
            print(f"wrote {args.out}: {frames} frames, {server.stats.solved} solved{note}", file=sys.stderr)
            for line in activity.notes():
                log.info(line)
            for line in activity.warnings():
                print(f"samba-replay: WARNING: {line}", file=sys.stderr)
            return 0
        stop = threading.Event()
        player = Player(args.take, args.session, args.connect, args.listen, speed)
        try:
            sent = player.play(stop)
        except KeyboardInterrupt:
            stop.set()
            sent = player.sent
        if player.taken_in is not None and player.taken_in < sent:
            print(f"samba-replay: {sent} packets published, the server took in {player.taken_in}", file=sys.stderr)
            return 1
        print(f"samba-replay: {sent} packets published", file=sys.stderr)
        return 0
    except (OSError, ValueError, ConfigError, CalibrationError) as exc:
        print(f"samba-replay: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
