"""``samba-reconstruct``: 13-joint skeleton from a labelled 8-marker take (markers.npz -> joints.npz)."""

from __future__ import annotations

import argparse
import logging
import sys
import time
from dataclasses import replace

import numpy as np

from samba_common.config import ConfigError, load_section
from samba_common.formats import FormatError, load_markers, save_joints
from samba_common.progress import Progress
from samba_common.skeleton import BONE_TYPES, MARKER_NAMES
from samba_common.subject import Subject, SubjectError, load_subject
from samba_server.export.csvfile import write_joints_csv
from samba_server.recon import (MotionDB, ProportionError, ReconstructConfig, load_default_db, reconstruct_take,
                                sample_path)
from samba_server.recon.bounds import guessed_summary
from samba_server.recon.reconstruct import Reconstructor
from samba_server.recon.subject_fit import calibrate_subject, guess_placement

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  samba-reconstruct take/markers.npz --out take/joints.npz
  samba-reconstruct sample --out joints.npz        # the sample take shipped in the package
  samba-reconstruct markers.npz --out joints.npz --db my_db.npz --k 10 --pseudo 10 --csv joints.csv
  samba-reconstruct markers.npz --out joints.npz --subject subject.toml   # from samba-subject calibrate
  samba-reconstruct markers.npz --out joints.npz --placement joint-centres # simulated joint-centre markers

marker placement: markers taped on the skin (acromion, lateral femoral epicondyle, lateral
malleolus, back of the wrist) are the default: the subject's bone lengths and marker offsets
are calibrated from the take itself and the output joints are joint centres. A markers.npz
with marker_placement = "joint_centres" (or --placement joint-centres) is solved with zero
offsets; without that key, auto decides from the take (the hip width its standard pose implies
under each placement, else the marker fit) and the summary says which and why; --subject uses a
calibrated subject.toml.
"""


def summary(info: dict, n_frames: int) -> str:
    """Human summary: frames, unsolved, bridged, mean residual, speed, the subject's bone lengths
    and how many joints are confident (:func:`guessed_summary`)."""
    status = info["status"]
    res = info["residual"][np.isfinite(info["residual"])]
    lines = [
        f"frames {n_frames}, unsolved {int(np.sum(status == 'unsolved'))}, bridged {int(np.sum(status == 'bridged'))}",
        f"mean marker residual {1000 * res.mean():.1f} mm" if res.size else "mean marker residual n/a",
        f"{info['ms_per_frame']:.2f} ms/frame, {np.mean(info['iterations']):.1f} LM iterations/frame",
        "bone lengths (m): " + ", ".join(f"{n} {v:.3f}" for n, v in zip(BONE_TYPES, info["lengths"])),
        guessed_summary(info["joint_bound"], status == "solved"),
    ]
    return "\n".join(lines)


def _subject(args, take, db: MotionDB, cfg: ReconstructConfig) -> tuple[Subject | None, str]:
    """The subject to solve with: --subject, else calibrated from the take (skin markers), else
    None (joint-centre markers: lengths estimated as always). Returns (subject, summary text)."""
    if args.subject:
        subject = load_subject(args.subject)
        return subject, f"subject {args.subject} ({subject.placement})"
    placement, why, report = args.placement, "", None
    if placement == "auto":
        if args.markers == "sample" or str(args.markers) == str(sample_path()):
            placement, why = "joint_centres", "placement: joint centres (the shipped sample is simulated on them)"
        elif "marker_placement" in take.extra:
            placement = str(take.extra["marker_placement"])
            why = f"placement: {placement.replace('_', ' ')} (the file's marker_placement)"
        else:  # decide from the data (samba_server.recon.subject_fit.guess_placement)
            guess = guess_placement(take.markers, take.t, db, cfg)
            placement, report = guess.placement, guess.report
            why = f"placement (auto, from the {guess.evidence}): {placement.replace('_', ' ')}: {guess.reason}"
    else:
        why = f"placement: {placement.replace('-', ' ')} (--placement)"
    placement = placement.replace("-", "_")
    if placement not in ("skin", "joint_centres"):
        raise FormatError(args.markers, "marker_placement", f"must be 'skin' or 'joint_centres', got {placement!r}")
    if placement == "joint_centres":
        return None, why
    if report is None:
        report = calibrate_subject(take.markers, take.t, db, cfg)
    return report.subject, why + "\nskin markers, subject calibrated from the take:\n" + report.summary()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="samba-reconstruct", description=__doc__, epilog=EXAMPLES,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("markers", help="input markers.npz (FORMATS.md), or 'sample' for the take shipped with Samba")
    ap.add_argument("--out", required=True, help="output joints.npz")
    ap.add_argument("--db", help="motion database .npz ('default' or left out: the one shipped with Samba)")
    ap.add_argument("--k", type=int, help="nearest database poses per frame (default 10)")
    ap.add_argument("--pseudo", type=int, help="pseudo-poses per neighbour (default 10)")
    ap.add_argument("--csv", help="also write the joints as CSV")
    ap.add_argument("--subject", help="subject.toml (bone lengths + marker offsets) from samba-subject calibrate")
    ap.add_argument("--placement", choices=("auto", "skin", "joint-centres"), default="auto",
                    help="where the markers sit (default auto: the file's marker_placement, else decided from the "
                         "take: the hip width the standard pose implies, or the marker fit)")
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
        db = MotionDB.load(args.db) if args.db and args.db != "default" else load_default_db()
        t0 = time.perf_counter()
        Reconstructor(db=db, config=cfg).warm_up()  # compile (first run) or load the solver, timed apart
        info_compile_s = time.perf_counter() - t0
        subject, calib_text = _subject(args, take, db, cfg)
        lengths = subject.lengths if subject is not None else None
        offsets = subject.offsets if subject is not None and subject.placement == "skin" else None
        with Progress(len(take.t), "reconstructing", enabled=None if not args.quiet else False) as bar:
            joints, info = reconstruct_take(take.markers, take.t, db, cfg, lengths=lengths, progress=bar.update,
                                            offsets=offsets)
        if subject is None:
            subject = Subject(info["lengths"], placement="joint_centres")
        save_joints(args.out, joints, take.t, residual=info["residual"], n_markers=info["n_markers"],
                    status=info["status"], joint_bound=info["joint_bound"], bone_lengths=info["lengths"],
                    bone_types=np.array(BONE_TYPES), marker_names=np.array(MARKER_NAMES), **subject.metadata())
        if args.csv:
            write_joints_csv(args.csv, joints, take.t)
    except (FormatError, ConfigError, ProportionError, SubjectError) as exc:
        print(f"samba-reconstruct: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"samba-reconstruct: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    if not args.quiet:
        print(summary(info, len(take.t)))
        if calib_text:
            print(calib_text)
        if info_compile_s > 5.0:
            print(f"solver compiled in {info_compile_s:.0f} s (first run on this machine, cached for later runs; "
                  "not counted in ms/frame)")
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
