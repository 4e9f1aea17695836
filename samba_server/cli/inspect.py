"""``samba-inspect take.mcap``: what is in a take (motes, frames, drops, rates, duration) and
export of its recorded poses (joints.npz / CSV / plot)."""

from __future__ import annotations

import argparse
import logging
import sys

from samba_server.export.csvfile import write_joints_csv
from samba_server.inspect import pose_arrays, report, summarize


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-inspect", description="Summarise a recorded take and export its poses.")
    ap.add_argument("take", help="take.mcap")
    ap.add_argument("--export", metavar="JOINTS.npz", help="write the recorded poses as joints.npz")
    ap.add_argument("--csv", metavar="OUT.csv", help="write the recorded poses as CSV")
    ap.add_argument("--plot", metavar="OUT.png",
                    help="plot marker visibility per mote, joint trajectories and latency over time")
    ap.add_argument("-v", "--verbose", action="count", default=0, help="log progress (-vv: debug)")
    args = ap.parse_args(argv)
    if args.verbose:
        logging.basicConfig(level=logging.INFO if args.verbose == 1 else logging.DEBUG,
                            format="%(levelname)s %(name)s: %(message)s")
    try:
        s = summarize(args.take)
    except (OSError, ValueError) as exc:
        print(f"samba-inspect: {exc}", file=sys.stderr)
        return 1
    print(report(s))
    joints, t, extra = pose_arrays(s)
    try:
        if args.export:
            from samba_common.formats import save_joints

            save_joints(args.export, joints, t, **extra)
            print(f"wrote {args.export} ({len(t)} frames)")
        if args.csv:
            write_joints_csv(args.csv, joints, t)
            print(f"wrote {args.csv} ({len(t)} frames)")
        if args.plot:
            from samba_server.plots import plot_take

            plot_take(args.take, args.plot)  # all panels: visibility per mote, trajectories, latency
            print(f"wrote {args.plot}")
    except (OSError, ValueError) as exc:
        print(f"samba-inspect: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
