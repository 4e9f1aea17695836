"""``samba-export TAKE --format bvh|c3d|trc|csv --out FILE``: write a take for other tools."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from samba_common.formats import FormatError
from samba_server.export import WRITERS, export_take
from samba_server.export.bvh import BvhExportReport
from samba_server.export.take import TakeError, load_take

log = logging.getLogger("samba_server.export")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="samba-export",
        description="Export a Samba take (joints.npz or take.mcap) to BVH (Blender: Y up, cm), "
                    "C3D (mm, Z up), TRC (OpenSim: mm, Y up) or CSV (metres, Z up).")
    p.add_argument("take", type=Path, help="joints.npz (FORMATS.md) or a take.mcap recording")
    p.add_argument("--format", "-f", choices=sorted(WRITERS),
                   help="output format (default: from the --out suffix)")
    p.add_argument("--out", "-o", type=Path, required=True, help="output file")
    p.add_argument("--markers", type=Path, default=None,
                   help="markers.npz with the same frames, added to C3D/TRC as <name>_marker")
    p.add_argument("-v", "--verbose", action="count", default=0, help="log progress (-vv: debug)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING if args.verbose == 0 else logging.INFO if args.verbose == 1 else logging.DEBUG
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    fmt = args.format or args.out.suffix.lower().lstrip(".")
    if fmt not in WRITERS:
        print(f"samba-export: cannot tell the format from {args.out.name!r}; pass --format "
              f"({'|'.join(sorted(WRITERS))})", file=sys.stderr)
        return 2
    try:
        take = load_take(args.take, args.markers)
        report = export_take(take, fmt, args.out)
    except (TakeError, FormatError) as exc:
        print(f"samba-export: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"samba-export: cannot write {args.out}: {exc}", file=sys.stderr)
        return 1
    if isinstance(report, BvhExportReport) and report.n_held:
        print(f"samba-export: {report.n_held} of {report.n_frames} frames had missing joints "
              f"(held the last complete pose)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
