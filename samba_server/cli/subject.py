"""``samba-subject``: calibrate a subject (bone lengths + skin-marker offsets) from a take.

    samba-subject calibrate markers.npz --out subject.toml
    samba-subject show subject.toml
"""

from __future__ import annotations

import argparse
import logging
import sys

from samba_common.config import ConfigError, load_section
from samba_common.formats import FormatError, load_markers
from samba_common.subject import SubjectError, load_subject
from samba_server.recon import MotionDB, ProportionError, ReconstructConfig, load_default_db
from samba_server.recon.subject_fit import calibrate_subject

EXAMPLES = """examples:
  samba-subject calibrate take/markers.npz --out subject.toml
  samba-reconstruct take2/markers.npz --subject subject.toml --out joints.npz
  samba-server --calibration calibration.toml --subject subject.toml ...
  samba-subject show subject.toml
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-subject", description=__doc__, epilog=EXAMPLES,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    cal = sub.add_parser("calibrate", help="bone lengths and marker offsets from a take of skin markers")
    cal.add_argument("markers", help="markers.npz (FORMATS.md) of the subject: standard pose + ordinary motion")
    cal.add_argument("--out", required=True, help="output subject.toml")
    cal.add_argument("--db", help="motion database .npz (default: the one shipped with Samba)")
    cal.add_argument("--config", help="TOML file with a [reconstruct] table")
    cal.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    cal.add_argument("-v", "--verbose", action="store_true", help="log details")
    show = sub.add_parser("show", help="print a subject.toml after validating it")
    show.add_argument("subject")
    show.add_argument("-v", "--verbose", action="store_true", help="log details")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if getattr(args, "verbose", False) else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        if args.cmd == "show":
            print(load_subject(args.subject).to_toml(), end="")
            return 0
        cfg = load_section(ReconstructConfig, args.config, "reconstruct")
        take = load_markers(args.markers)
        db = MotionDB.load(args.db) if args.db else load_default_db()
        report = calibrate_subject(take.markers, take.t, db, cfg)
        report.subject.save(args.out)
    except (FormatError, ConfigError, SubjectError) as exc:
        print(f"samba-subject: {exc}", file=sys.stderr)
        return 1
    except ProportionError as exc:
        print(f"samba-subject: {args.markers}: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"samba-subject: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(report.summary())
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
