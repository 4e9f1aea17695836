"""``samba-sim``: render a simulated take (videos + ground truth + calibration).

Exit codes: 0 ok, 1 runtime error, 2 usage.
"""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import replace
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="samba-sim", description="Render simulated camera videos of the 8 markers "
                                "(cam0.avi ...), ground truth (joints.npz, markers.npz, truth2d.npz) and "
                                "calibration.toml. The standard T-pose is prepended to the take.")
    p.add_argument("out", help="output directory")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--bvh", help="BVH clip (e.g. /work/shared/data/cmu-bvh/002_10.bvh)")
    src.add_argument("--joints", help="joints.npz (FORMATS.md)")
    p.add_argument("--calibration", help="calibration.toml of the rig (default: default_rig(--cameras))")
    p.add_argument("--cameras", type=int, default=4, choices=[2, 4], help="default rig size")
    p.add_argument("--rig-only", action="store_true", help="only write OUT/calibration.toml of the default rig")
    p.add_argument("--start", type=float, default=0.0, help="start of the clip excerpt (s)")
    p.add_argument("--seconds", type=float, help="length of the excerpt (s); default whole clip (synthetic: 3 s)")
    p.add_argument("--fps", type=float, default=60.0)
    p.add_argument("--noise", type=float, default=3.0, help="sensor noise sigma (grey levels)")
    p.add_argument("--distractors", type=int, default=3, help="static distractors per camera")
    p.add_argument("--no-occlusion", action="store_true", help="markers never hidden by the body")
    p.add_argument("--no-center", action="store_true", help="keep the clip's horizontal position")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("-v", "--verbose", action="count", default=0)
    args = p.parse_args(argv)
    logging.basicConfig(level=[logging.WARNING, logging.INFO, logging.DEBUG][min(args.verbose, 2)],
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    from samba_common.calib import CalibrationError, CameraRig, default_rig
    from samba_common.formats import FormatError

    from .render import SimConfig
    from .take import make_take

    out = Path(args.out)
    try:
        rig = CameraRig.load(args.calibration) if args.calibration else default_rig(args.cameras)
        if args.rig_only:
            out.mkdir(parents=True, exist_ok=True)
            rig.save(out / "calibration.toml")
            return 0
        cfg = replace(SimConfig(), fps=args.fps, noise_sigma=args.noise, n_distractors=args.distractors,
                      occlusion=not args.no_occlusion)
        source = args.bvh or args.joints
        if source and not Path(source).exists():
            raise ValueError(f"{source}: file not found")
        take = make_take(out, source, rig=rig, config=cfg, seed=args.seed, start=args.start, seconds=args.seconds,
                         center=not args.no_center)
    except (CalibrationError, FormatError, ValueError) as exc:
        print(f"samba-sim: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"samba-sim: {exc}", file=sys.stderr)
        return 1
    if args.verbose:
        print(f"wrote {len(take.t)} frames x {len(rig)} cameras to {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
