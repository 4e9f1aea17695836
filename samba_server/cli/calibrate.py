"""``samba-calibrate``: intrinsics, wand extrinsics, floor, self-calibration, simulated takes.

Exit codes: 0 ok, 1 runtime error (unreadable input, data that cannot determine the
calibration), 2 usage error. The quality report goes to stdout; logs to stderr with -v.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from samba_common.body import ANKLE_HEIGHT
from samba_common.calib import CalibrationError, CameraRig, default_rig

log = logging.getLogger("samba_server.calibrate")


def _load_rig(path: str | None, what: str) -> CameraRig:
    if path is None:
        raise CalibrationError(None, None, f"{what}: give the cameras' intrinsics with --calib FILE (from "
                               "`samba-calibrate intrinsics --camera cam0 BOARD_DIR --board ... --out FILE`, "
                               "once per camera; see docs/calibration.md)")
    return CameraRig.load(path)


def _parse_arms(text: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected SHORTxLONG metres, e.g. 0.3x0.4, got {text!r}") from None
    if not 0 < a < b:
        raise argparse.ArgumentTypeError("L-frame arms: 0 < short < long")
    return a, b


class _Counter:
    """Frames-read counter on stderr for work of unknown length; silent if not a TTY."""

    def __init__(self, label: str):
        self.label = label
        self.enabled = sys.stderr.isatty()
        self.n = 0

    def __call__(self, n: int) -> None:
        self.n = n
        if self.enabled and n % 25 == 0:
            sys.stderr.write(f"\r{self.label}: {n}")
            sys.stderr.flush()

    def __enter__(self) -> "_Counter":
        return self

    def __exit__(self, *exc) -> None:
        if self.enabled and self.n:
            sys.stderr.write(f"\r{self.label}: {self.n}\n")


def _progress(label: str):
    c = _Counter(label)
    return c, c


def _floor_from_lframe(rig: CameraRig, take: str, arms, height: float) -> CameraRig:
    from samba_server.calibrate.floor import apply_transform, lframe_transform, triangulate_static
    from samba_server.calibrate.takeio import read_take

    uv = read_take(take, rig.names, 3)
    P = triangulate_static(rig, uv)
    A, b = lframe_transform(P, height, arms)
    out = apply_transform(rig, A, b)
    Pn = P @ A.T + b
    log.info("L-frame markers in the new world (m): %s", np.array2string(Pn, precision=4))
    return out


def cmd_intrinsics(a: argparse.Namespace) -> int:
    from samba_server.calibrate.intrinsics import Board, calibrate_intrinsics

    board = Board.parse(a.board)
    bar, cb = _progress(f"{a.camera} frames")
    with bar:
        res = calibrate_intrinsics(a.camera, a.source, board, step=a.step, fix_k3=not a.k3, progress=cb)
    out = Path(a.out)
    cam = res.camera
    if out.exists():
        rig = CameraRig.load(out)
        if a.camera in rig.names:
            old = rig.camera(a.camera)
            cam.rvec, cam.tvec = old.rvec.copy(), old.tvec.copy()
        rig = rig.replace(cam)
    else:
        rig = CameraRig([cam])
    from samba_server.calibrate.wand import board_priors

    rig.metadata.update(board_priors(a.camera, res.std, res.cov))  # priors of the wand step
    rig.metadata["source"] = "samba-calibrate intrinsics"
    rig.save(out)
    print(f"{a.camera}: rms {res.rms_px:.3f} px from {res.n_views} of {res.n_frames} frames; "
          f"coverage {res.coverage * 100:.0f} % of the image (8x6 cells)")
    print(f"  fx {cam.matrix[0, 0]:.2f} fy {cam.matrix[1, 1]:.2f} cx {cam.matrix[0, 2]:.2f} cy {cam.matrix[1, 2]:.2f}"
          f" dist {np.array2string(cam.dist, precision=4)}")
    pp95 = 1.96 * max(res.std[2], res.std[3])  # px
    print(f"  95 % uncertainty: focal length +-{1.96 * res.std[0]:.2f} px, principal point "
          f"+-{pp95:.2f} px (the wand step refines them)")
    rot = np.degrees(np.arctan(pp95 / cam.matrix[0, 0]))
    if rot > 0.1:  # the principal point and the camera's rotation trade against each other
        print(f"  note: the principal point leaves the camera's rotation uncertain by +-{rot:.2f} deg; "
              "more views (a longer board video, 300+ found) narrow it")
    if res.coverage < 0.5:
        print("  warning: corners cover less than half of the image; move the board into the corners")
    print(f"wrote {out}")
    return 0


def cmd_extrinsics(a: argparse.Namespace) -> int:
    from samba_server.calibrate.takeio import read_take
    from samba_server.calibrate.wand import calibrate_wand

    rig = _load_rig(a.calib or (a.out if Path(a.out).exists() else None), "extrinsics")
    offsets = np.array([0.0, a.wand] if a.wand_mid is None else [0.0, a.wand_mid, a.wand])
    if a.wand_mid is not None and not 0 < a.wand_mid < a.wand:
        raise ValueError("--wand-mid must lie between 0 and --wand")
    bar, cb = _progress("wand frames")
    with bar:
        uv = read_take(a.take, rig.names, len(offsets), cb)
    refine = () if a.fix_intrinsics else None
    out, rep = calibrate_wand(rig, uv, offsets, min_frames=a.min_frames,
                              **({} if refine is None else {"refine": refine}))
    if a.floor:
        out = _floor_from_lframe(out, a.floor, a.lframe, a.lframe_height)
    # say where this file came from (not the intrinsics file's "source")
    intr_src = rig.metadata.get("source")
    out.metadata["source"] = (f"samba-calibrate extrinsics {Path(a.take).name} --wand {a.wand:g}"
                              + (f" --floor {Path(a.floor).name}" if a.floor else ""))
    if intr_src is not None:
        out.metadata["intrinsics_source"] = str(intr_src)
    out.metadata["wand_positions"] = int(rep.n_frames)
    if rep.uncertainty is not None:
        out.metadata["scale_sigma"] = float(rep.uncertainty.scale_sigma)
        out.metadata["centre_95_m"] = [float(v) for v in rep.uncertainty.centre_95_m]
    out.save(a.out)
    print("\n".join(rep.lines()))
    if not a.floor:
        print("world frame is provisional (Z up from the cameras, floor at the lowest wand position): "
              "run `samba-calibrate floor` or pass --floor")
    print(f"wrote {a.out}")
    return 0


def cmd_floor(a: argparse.Namespace) -> int:
    rig = CameraRig.load(a.calib)
    if a.standard_pose:
        from samba_server.calibrate.floor import apply_transform, standard_pose_transform
        from samba_server.calibrate.takeio import read_take
        from samba_server.triangulate import triangulate

        uv = read_take(a.take, rig.names, None, rig=rig, fps=a.fps)[: max(1, int(round(a.seconds * a.fps)))]
        F, C, K, _ = uv.shape
        P = triangulate(rig, uv.transpose(1, 0, 2, 3).reshape(C, F * K, 2)).points.reshape(F, K, 3)
        A, b = standard_pose_transform(P, a.ankle_height)
        out = apply_transform(rig, A, b)
    else:
        out = _floor_from_lframe(rig, a.take, a.lframe, a.lframe_height)
    out.save(a.out or a.calib)
    print(f"wrote {a.out or a.calib}")
    return 0


def cmd_self(a: argparse.Namespace) -> int:
    from samba_server.calibrate.selfcal import self_calibrate
    from samba_server.calibrate.takeio import read_take

    rig = CameraRig.load(a.calib)
    repair = [n.strip() for n in a.repair.split(",")] if a.repair else None
    if not repair and (a.tibia is None) == (a.height is None):
        raise ValueError("give --tibia or --height for the scale (or --repair CAMS)")
    has_poses = any(np.any(c.tvec != 0) for c in rig.cameras)
    uv = read_take(a.take, rig.names, None, rig=rig if has_poses else None, fps=a.fps)
    out, rep = self_calibrate(rig, uv, tibia=a.tibia, height=a.height, repair=repair, fps=a.fps)
    out.save(a.out or a.calib)
    print("\n".join(rep.lines()))
    print(f"wrote {a.out or a.calib}")
    return 0


def cmd_simulate(a: argparse.Namespace) -> int:
    from samba_server.calibrate import simwand

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rig = default_rig(a.cameras)
    rig.save(out / "calibration_true.toml")
    if a.kind == "board":
        import cv2

        from samba_server.calibrate.intrinsics import Board, render_board_views

        board = Board.parse(a.board)
        for cam in rig.cameras:
            d = out / cam.name
            d.mkdir(exist_ok=True)
            for i, img in enumerate(render_board_views(cam, board, a.frames or 600, seed=a.seed)):
                cv2.imwrite(str(d / f"board_{i:03d}.png"), img)
        print(f"wrote board images per camera under {out}")
        return 0
    if a.kind == "wand":
        obs = simwand.simulate_wand(rig, a.frames or 600, a.wand, a.wand_mid, a.noise, a.seed, a.fps)
        offsets = [0.0, a.wand] if a.wand_mid is None else [0.0, a.wand_mid, a.wand]
    elif a.kind == "lframe":
        obs = simwand.simulate_lframe(rig, a.frames or 60, a.noise, a.seed, a.lframe, a.lframe_height, a.fps)
        offsets = None
    else:
        obs = simwand.simulate_subject(rig, a.seconds, a.noise, a.seed, a.fps)
        offsets = None
    simwand.save_observations(out / "take.npz", obs, rig.names, a.kind, offsets)
    if a.videos:
        simwand.write_videos(out, rig, obs, a.fps, seed=a.seed)
    print(f"wrote {out / 'take.npz'} ({len(obs.t)} frames, {a.cameras} cameras) and {out / 'calibration_true.toml'}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="samba-calibrate", description=__doc__.split("\n")[0])
    p.add_argument("-v", "--verbose", action="count", default=0, help="log progress (-vv: debug)")
    sub = p.add_subparsers(dest="cmd", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-v", "--verbose", action="count", default=argparse.SUPPRESS, help="log progress (-vv: debug)")

    s = sub.add_parser("intrinsics", parents=[common], help="K and distortion of one camera from board views")
    s.add_argument("source", help="directory of images, a video file or a glob pattern")
    s.add_argument("--camera", required=True, help="camera name (mote id), e.g. cam0")
    s.add_argument("--board", required=True, help="checkerboard:9x6:0.025 or charuco:5x7:0.04:0.03[:DICT]")
    s.add_argument("--out", required=True, help="calibration.toml to create or update")
    s.add_argument("--step", type=int, default=1, help="use every N-th frame of a video")
    s.add_argument("--k3", action="store_true", help="also estimate k3 (default: fixed at 0)")
    s.set_defaults(func=cmd_intrinsics)

    def lframe_opts(s: argparse.ArgumentParser) -> None:
        s.add_argument("--lframe", type=_parse_arms, default=simwand_arms(), metavar="SHORTxLONG",
                       help="L-frame arm lengths in m (short = +X, long = +Y), default %(default)s")
        s.add_argument("--lframe-height", type=float, default=0.0, help="marker centre height above the floor (m)")

    s = sub.add_parser("extrinsics", parents=[common], help="all camera poses from a wand take (bundle adjustment)")
    s.add_argument("take", help="directory of videos cam0.avi..., an .mcap recording or a .npz take")
    s.add_argument("--wand", type=float, required=True, help="distance between the wand's end markers (m)")
    s.add_argument("--wand-mid", type=float, default=None, help="distance of a third, middle marker from the first end (m)")
    s.add_argument("--calib", help="calibration.toml with the intrinsics (default: --out if it exists)")
    s.add_argument("--out", required=True, help="calibration.toml to write")
    s.add_argument("--floor", help="L-frame take (3 markers) to set origin, Z up and heading")
    s.add_argument("--min-frames", type=int, default=20, help="wand frames two cameras must share")
    s.add_argument("--fix-intrinsics", action="store_true",
                   help="keep the intrinsics as given (default: refine focal length, principal point, k1, k2 "
                        "around them, with the board step's uncertainties as priors)")
    lframe_opts(s)
    s.set_defaults(func=cmd_extrinsics)

    s = sub.add_parser("floor", parents=[common], help="set origin, Z up and heading (L-frame or standard pose)")
    s.add_argument("take", help="L-frame take (unlabelled, 3 markers) or, with --standard-pose, a labelled take")
    s.add_argument("--calib", required=True, help="calibrated cameras")
    s.add_argument("--out", help="output file (default: overwrite --calib)")
    s.add_argument("--standard-pose", action="store_true", help="use a subject standing in the standard pose")
    s.add_argument("--seconds", type=float, default=1.0, help="standard pose: length at the start of the take")
    s.add_argument("--fps", type=float, default=60.0)
    s.add_argument("--ankle-height", type=float, default=ANKLE_HEIGHT, help="ankle marker height above the floor (m)")
    lframe_opts(s)
    s.set_defaults(func=cmd_floor)

    s = sub.add_parser("self", parents=[common], help="self-calibration from a take of the 8 labelled markers")
    s.add_argument("take", help="labelled take: directory of videos, .mcap or .npz")
    s.add_argument("--calib", required=True, help="calibration.toml (intrinsics; poses for --repair)")
    s.add_argument("--out", help="output file (default: overwrite --calib)")
    g = s.add_mutually_exclusive_group()
    g.add_argument("--tibia", type=float, help="knee-to-ankle marker distance (m) for the scale")
    g.add_argument("--height", type=float, help="subject height (m) for the scale")
    g.add_argument("--repair", help="comma-separated cameras to re-pose against the others")
    s.add_argument("--fps", type=float, default=60.0)
    s.set_defaults(func=cmd_self)

    s = sub.add_parser("simulate", parents=[common], help="simulated calibration takes with ground truth (default rig)")
    s.add_argument("kind", choices=["wand", "lframe", "board", "subject"])
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--cameras", type=int, default=4, choices=[2, 4])
    s.add_argument("--frames", type=int, default=0, help="frames (default: wand 600, lframe 60, board 600 views per camera)")
    s.add_argument("--seconds", type=float, default=8.0, help="subject take length")
    s.add_argument("--noise", type=float, default=0.2, help="pixel noise sigma")
    s.add_argument("--wand", type=float, default=0.5)
    s.add_argument("--wand-mid", type=float, default=None)
    s.add_argument("--board", default="checkerboard:7x5:0.03")
    s.add_argument("--fps", type=float, default=60.0)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--videos", action="store_true", help="also render cam0.avi ... (wand, lframe)")
    lframe_opts(s)
    s.set_defaults(func=cmd_simulate)
    return p


def simwand_arms() -> tuple[float, float]:
    from samba_server.calibrate.simwand import LFRAME_ARMS

    return LFRAME_ARMS


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    level = logging.WARNING - 10 * min(args.verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    from samba_server.calibrate.intrinsics import BoardError
    from samba_server.calibrate.takeio import TakeError
    from samba_server.calibrate.wand import CalibrateError

    try:
        return args.func(args)
    except BoardError as exc:
        print(f"samba-calibrate: error: {exc}", file=sys.stderr)
        return 2
    except (CalibrationError, TakeError, CalibrateError, ValueError, OSError) as exc:
        print(f"samba-calibrate: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
