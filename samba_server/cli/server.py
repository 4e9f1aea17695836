"""``samba-server``: the live server (Zenoh in, poses out); the work is in :mod:`samba_server.app`."""

from __future__ import annotations

import argparse
import sys

from samba_common.calib import CalibrationError
from samba_common.config import ConfigError
from samba_server.app import add_network_args, add_placement_arg, build_server, load_server_configs, run_live, setup_logging
from samba_server.record import RecorderError


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-server", description="Live Samba server: mote packets in, skeleton out.")
    ap.add_argument("--calibration", required=True, help="calibration.toml (camera names = mote ids)")
    add_network_args(ap)
    ap.add_argument("--record", metavar="TAKE.mcap", help="record packets, calibration and poses")
    ap.add_argument("--export", metavar="JOINTS.npz", help="write every pose to joints.npz at exit")
    ap.add_argument("--db", help="motion database (.npz) for the solver (default: the shipped one)")
    ap.add_argument("--subject", metavar="SUBJECT.toml",
                    help="subject (bone lengths + skin-marker offsets) from samba-subject calibrate; default: "
                         "measured live: the standard pose tells skin landmarks from joint centres and gives "
                         "the bone lengths, skin offsets are calibrated from the first second after it "
                         "([reconstruct] placement, subject_seconds)")
    add_placement_arg(ap)
    ap.add_argument("--config", help="server TOML (default: the packaged configs/server.toml)")
    ap.add_argument("--fps", type=float, help="nominal mote frame rate (overrides [sync] fps)")
    ap.add_argument("--http", metavar="[HOST:]PORT", help="serve the browser viewer")
    ap.add_argument("--duration", type=float, help="stop after this many seconds")
    ap.add_argument("--status", action="store_true", help="print a live status line on stderr")
    ap.add_argument("-v", "--verbose", action="count", default=0)
    args = ap.parse_args(argv)
    setup_logging(args.verbose)
    try:
        configs = load_server_configs(args.config, args.placement, fps=args.fps)
        server = build_server(args.calibration, configs, args.db, args.record, subject=args.subject)
    except (ConfigError, CalibrationError, RecorderError, OSError, ValueError) as exc:
        print(f"samba-server: {exc}", file=sys.stderr)
        return 1
    return run_live(server, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
