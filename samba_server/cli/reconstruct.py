"""``samba-reconstruct``: 13-joint skeleton from a labelled 8-marker take (markers.npz -> joints.npz)."""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import replace

import numpy as np

from samba_common.config import ConfigError, load_section
from samba_common.formats import FormatError, load_markers, save_joints
from samba_common.progress import Progress
from samba_common.skeleton import BONE_TYPES
from samba_server.export.csvfile import write_joints_csv
from samba_server.recon import (MotionDB, ProportionError, ReconstructConfig, load_default_db, reconstruct_take,
                                sample_path)

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  samba-reconstruct take/markers.npz --out take/joints.npz
  samba-reconstruct sample --out joints.npz        # the sample take shipped in the package
  samba-reconstruct markers.npz --out joints.npz --db my_db.npz --k 10 --pseudo 10 --csv joints.csv
"""


def summary(info: dict, n_frames: int) -> str:
    """Human summary: frames, unsolved, bridged, mean residual, speed and the subject's bone lengths."""
    status = info["status"]
    res = info["residual"][np.isfinite(info["residual"])]
    lines = [
        f"frames {n_frames}, unsolved {int(np.sum(status == 'unsolved'))}, bridged {int(np.sum(status == 'bridged'))}",
        f"mean marker residual {1000 * res.mean():.1f} mm" if res.size else "mean marker residual n/a",
        f"{info['ms_per_frame']:.2f} ms/frame, {np.mean(info['iterations']):.1f} LM iterations/frame",
        "bone lengths (m): " + ", ".join(f"{n} {v:.3f}" for n, v in zip(BONE_TYPES, info["lengths"])),
    ]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-reconstruct", description=__doc__, epilog=EXAMPLES,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("markers", help="input markers.npz (FORMATS.md), or 'sample' for the take shipped with Samba")
    ap.add_argument("--out", required=True, help="output joints.npz")
    ap.add_argument("--db", help="motion database .npz (default: the one shipped with Samba)")
    ap.add_argument("--k", type=int, help="nearest database poses per frame (default 10)")
    ap.add_argument("--pseudo", type=int, help="pseudo-poses per neighbour (default 10)")
    ap.add_argument("--csv", help="also write the joints as CSV")
    ap.add_argument("--config", help="TOML file with a [reconstruct] table (see configs/reconstruct.toml)")
    ap.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    ap.add_argument("-v", "--verbose", action="store_true", help="log details")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    if (args.k is not None and args.k < 1) or (args.pseudo is not None and args.pseudo < 0):
        ap.error("--k must be >= 1 and --pseudo >= 0")
    try:
        cfg = load_section(ReconstructConfig, args.config, "reconstruct")
        if args.k is not None:
            cfg = replace(cfg, k=args.k)
        if args.pseudo is not None:
            cfg = replace(cfg, pseudo=args.pseudo)
        take = load_markers(sample_path() if args.markers == "sample" else args.markers)
        db = MotionDB.load(args.db) if args.db else load_default_db()
        with Progress(len(take.t), "reconstructing", enabled=None if not args.quiet else False) as bar:
            joints, info = reconstruct_take(take.markers, take.t, db, cfg, progress=bar.update)
        save_joints(args.out, joints, take.t, residual=info["residual"], n_markers=info["n_markers"],
                    status=info["status"], bone_lengths=info["lengths"], bone_types=np.array(BONE_TYPES))
        if args.csv:
            write_joints_csv(args.csv, joints, take.t)
    except (FormatError, ConfigError, ProportionError) as exc:
        print(f"samba-reconstruct: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"samba-reconstruct: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(summary(info, len(take.t)))
    solved = int(np.sum(info["status"] != "unsolved"))
    if solved < 0.5 * len(take.t):
        seen = np.isfinite(take.markers).all(axis=2).sum(axis=1)
        why = (f"only {int(np.sum(seen >= 4))} frames have the 4 markers a pose needs"
               if np.mean(seen >= 4) < 0.5 else "the solver could not follow the markers (see the residuals)")
        print(f"samba-reconstruct: WARNING: only {solved} of {len(take.t)} frames solved: {why}", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
