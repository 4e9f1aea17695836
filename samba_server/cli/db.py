"""``samba-db``: build, extend and describe motion databases."""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from samba_common.bvh import BvhError
from samba_common.config import ConfigError
from samba_common.formats import FormatError
from samba_common.progress import Progress
from samba_common.skeleton import BONE_TYPES
from samba_server.recon.db import MotionDB, build_db, default_db_path

EXAMPLES = """examples:
  samba-db build ../shared/data/cmu-bvh --out samba_common/data/default_db.npz   # rebuild the shipped DB
  samba-db build my_takes/*.bvh --add-to default --out my_db.npz                # add your own captures
  samba-db info my_db.npz
"""


def _expand(sources: list[str]) -> list[Path]:
    out: list[Path] = []
    for s in sources:
        p = Path(s)
        if p.is_dir():
            out.extend(sorted(p.glob("*.bvh")) + sorted(p.glob("*.BVH")))
        else:
            out.append(p)
    return out


def _info(db: MotionDB, path: str) -> str:
    names = [str(n) for n in db.clip_names]
    n_clips = sum(not n.endswith("~mirror") for n in names)
    mirrored = len(names) - n_clips
    lines = [f"{path}: {len(db)} poses from {n_clips} clips at {db.fps:g} fps"
             + (f" ({mirrored} of them also mirrored left-right)" if mirrored else "")]
    lines.append("mean bone lengths (m): " + ", ".join(f"{n} {v:.3f}" for n, v in zip(BONE_TYPES, db.mean_lengths)))
    counts = np.bincount(db.clip, minlength=len(db.clip_names))
    shown = [f"{n} ({c})" for n, c in zip(db.clip_names, counts) if not str(n).endswith("~mirror")]
    lines.append("clips: " + ", ".join(shown[:60]) + (" ..." if len(shown) > 60 else ""))
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-db", description="Build and inspect Samba motion databases.",
                                 epilog=EXAMPLES, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = ap.add_subparsers(dest="cmd", required=True)
    b = sub.add_parser("build", help="build a database from BVH files or folders of them")
    b.add_argument("sources", nargs="+", help="BVH files or folders")
    b.add_argument("--out", required=True, help="output .npz")
    b.add_argument("--mapping", help="BVH->13-joint mapping TOML (default: try configs/bvh/*.toml)")
    b.add_argument("--fps", type=float, default=30.0, help="resampling rate (default 30)")
    b.add_argument("--min-change", type=float, default=4.0, metavar="DEG",
                   help="drop poses until some bone moved this much (default 4 degrees)")
    b.add_argument("--no-mirror", action="store_true", help="do not add left-right mirrored poses")
    b.add_argument("--add-to", metavar="DB", help="extend this database ('default' = the shipped one)")
    i = sub.add_parser("info", help="describe a database")
    i.add_argument("db", help="database .npz ('default' = the shipped one)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        if args.cmd == "info":
            path = default_db_path() if args.db == "default" else Path(args.db)
            print(_info(MotionDB.load(path), str(path)))
            return 0
        files = _expand(args.sources)
        if not files:
            print("samba-db: no BVH files found in the given sources", file=sys.stderr)
            return 2
        base = None
        if args.add_to:
            base = MotionDB.load(default_db_path() if args.add_to == "default" else args.add_to)
            have = {str(n) for n in base.clip_names}
            dup = [f for f in files if f.stem in have]
            files = [f for f in files if f.stem not in have]
            if dup:
                print(f"samba-db: {len(dup)} clip(s) already in {args.add_to}, not added again: "
                      + ", ".join(f.stem for f in dup[:10]) + (" ..." if len(dup) > 10 else ""), file=sys.stderr)
            if not files:
                base.save(args.out)
                print(_info(base, args.out))
                return 0
        with Progress(len(files), "building") as bar:
            db = build_db(files, args.mapping, fps=args.fps, min_change_deg=args.min_change, mirror=not args.no_mirror,
                          progress=lambda _s: bar.update(), base=base)
        db.save(args.out)
        print(_info(db, args.out))
        return 0
    except (BvhError, FormatError, ConfigError, OSError) as exc:
        print(f"samba-db: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
