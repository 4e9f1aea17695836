"""``samba-sim``: render a simulated take (videos + ground truth + calibration).

Exit codes: 0 ok, 1 runtime error (also a missing or unreadable input file), 2 usage.
"""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import replace
from pathlib import Path

_STANCES = ("hip", "apart", "together")  # samba_mote.sim.tpose.STANCES (kept import-free here)
_CODECS = ("ffv1", "mjpg", "h264")  # samba_mote.sim.take.CODECS


def _stance(text: str) -> str | float:
    key = text.strip().lower()
    if key in _STANCES:
        return key
    try:
        value = float(key)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {'|'.join(_STANCES)} or metres, not {text!r}") from None
    if not -0.3 <= value <= 0.5:
        raise argparse.ArgumentTypeError(f"{value} m is not a stance (-0.3 .. 0.5 m)")
    return value


def _pose_at(text: str) -> tuple[float, float] | None:
    if text.strip().lower() == "start":
        return None
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y in metres or 'start', not {text!r}") from None
    return (x, y)


def _blackout(text: str) -> tuple[float, float]:
    try:
        start, seconds = (float(v) for v in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:SECONDS, not {text!r}") from None
    if start < 0 or seconds <= 0:
        raise argparse.ArgumentTypeError(f"{text!r}: START must be >= 0 and SECONDS > 0")
    return (start, seconds)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, not {text}")
    return value


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="samba-sim",
        description="Render simulated camera videos of the 8 markers (cam0.avi ...), ground truth "
        "(joints.npz, markers.npz, truth2d.npz) and calibration.toml. The take starts with the standard "
        "T-pose at --pose-at, then walks (1 m/s) and blends into the clip's first frame. The defaults are "
        "as hostile as real takes: feet at hip width (knee and ankle blobs touch at 5 m), the pose at "
        "the volume centre away from where a walk starts, the body hiding markers.")
    p.add_argument("out", help="output directory")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--bvh", help="BVH clip, e.g. a CMU clip: 02_01.bvh (default: a built-in synthetic walk)")
    src.add_argument("--joints", help="joints.npz (docs/formats.md)")
    p.add_argument("--calibration", help="calibration.toml of the rig (default: default_rig(--cameras))")
    p.add_argument("--cameras", type=int, default=4, choices=[2, 4], help="default rig size (default 4)")
    p.add_argument("--rig-only", action="store_true", help="only write OUT/calibration.toml of the default rig")
    p.add_argument("--start", type=float, default=0.0, help="start of the clip excerpt (s)")
    p.add_argument("--seconds", type=_positive,
                   help="length of the excerpt (s); default whole clip (synthetic: 3 s). Longer than the "
                   "clip: a warning, and all of it")
    p.add_argument("--fps", type=_positive, default=60.0, help="frame rate of the videos (default 60)")
    p.add_argument("--noise", type=float, default=3.0, help="sensor noise sigma (grey levels; default 3)")
    p.add_argument("--distractors", type=int, default=3, help="static distractors per camera (default 3)")
    p.add_argument("--no-occlusion", action="store_true",
                   help="markers never hidden by the body (default: capsules around the bones and torso hide them)")
    p.add_argument("--no-center", action="store_true", help="keep the clip's horizontal position")
    p.add_argument("--stance", type=_stance, default="hip", metavar="hip|apart|together|M",
                   help="feet of the T-pose (default hip): hip = ankles straight below the hips (at hip "
                   "width), apart = each ankle 0.12 m outside its hip, together = feet touching (ankles ~0.06 m from the "
                   "midline), or M metres each ankle stands outside its hip (negative: legs converging)")
    p.add_argument("--pose-at", type=_pose_at, default=(0.0, 0.0), metavar="X,Y|start",
                   help="where the T-pose stands (m; default 0,0, the volume centre); the lead-in then walks at "
                   "1 m/s to where the clip starts. 'start': stand where the clip starts. "
                   "Negative X: --pose-at=-1,2")
    p.add_argument("--blackout", type=_blackout, action="append", default=[], metavar="START:SECONDS",
                   help="no marker visible in any camera for SECONDS from START (s of the output take, "
                   "lead-in included); noise and distractors still render. Repeatable")
    p.add_argument("--codec", choices=_CODECS, default="ffv1",
                   help="video codec (default ffv1): ffv1 = lossless grey; mjpg = Motion-JPEG (yuvj420p, "
                   "as USB cameras send); h264 = if this OpenCV can encode it (else MPEG-4 mp4v with a warning, or an error); "
                   "camN.mp4 when the AVI container refuses the codec")
    p.add_argument("--skin", action="store_true",
                   help="markers on skin landmarks (acromion, lateral epicondyle, lateral malleolus, back of the "
                        "wrist) with this subject's offsets (typical +-15 %%, from --seed) instead of joint centres")
    p.add_argument("--wobble", type=float, default=0.0, metavar="MM",
                   help="with --skin: soft-tissue wobble sigma in mm (e.g. 5; default 0)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-v", "--verbose", action="count", default=0)
    args = p.parse_args(argv)
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    from samba_common.bvh import BvhError
    from samba_common.calib import CalibrationError, CameraRig, default_rig
    from samba_common.config import ConfigError
    from samba_common.formats import FormatError
    from samba_mote.sim.render import SimConfig
    from samba_mote.sim.take import make_take

    def warn(message: str) -> None:
        print(f"samba-sim: {message}", file=sys.stderr)

    out = Path(args.out)
    try:
        for path in (args.calibration, args.bvh, args.joints):
            if path and not Path(path).is_file():
                raise FileNotFoundError(f"{path}: file not found")
        rig = CameraRig.load(args.calibration) if args.calibration else default_rig(args.cameras)
        if args.rig_only:
            out.mkdir(parents=True, exist_ok=True)
            rig.save(out / "calibration.toml")
            print(f"wrote {out / 'calibration.toml'}: {len(rig)} cameras", file=sys.stderr)
            return 0
        cfg = replace(SimConfig(), fps=args.fps, noise_sigma=args.noise, n_distractors=args.distractors,
                      occlusion=not args.no_occlusion, tpose_stance=args.stance, pose_at=args.pose_at,
                      blackout=tuple(args.blackout), codec=args.codec)
        source = args.bvh or args.joints
        if args.wobble < 0 or (args.wobble and not args.skin):
            raise ValueError("--wobble needs --skin and a value >= 0 (mm)")
        offsets = None
        if args.skin:
            import numpy as np

            from samba_common.markerset import vary_offsets
            offsets = vary_offsets(np.random.default_rng(args.seed))
        take = make_take(out, source, rig=rig, config=cfg, seed=args.seed, start=args.start, seconds=args.seconds,
                         center=not args.no_center, on_warning=warn, offsets=offsets, wobble=args.wobble / 1000.0)
    except (CalibrationError, FormatError, BvhError, ConfigError, OSError) as exc:  # the input files
        print(f"samba-sim: {exc}", file=sys.stderr)
        return 1
    except ValueError as exc:  # values that do not fit the input (e.g. --start past the end)
        print(f"samba-sim: {exc}", file=sys.stderr)
        return 2
    codec = args.codec if take.fourcc.lower() == args.codec else f"{args.codec} as {take.fourcc}"
    if take.videos and take.videos[0].suffix != ".avi":
        codec += f" {take.videos[0].suffix}"
    stance = args.stance if isinstance(args.stance, str) else "custom"
    pose = "clip start" if args.pose_at is None else f"{args.pose_at[0]:g},{args.pose_at[1]:g}"
    extra = f", blackout {' '.join(f'{s:g}+{d:g} s' for s, d in args.blackout)}" if args.blackout else ""
    print(f"wrote {out}: {len(take.t)} frames x {len(rig)} cameras ({codec}, stance {stance} {take.stance:+.2f} m, "
          f"pose at {pose}, lead-in {take.n_tpose / args.fps:.2f} s{extra})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
