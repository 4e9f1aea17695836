"""Rebuild the sample take shipped in the package (samba_common/data/sample_markers.npz).

A few seconds of CMU clip 006_01 (walk, subject 6), re-posed on a body with other
proportions, with one second of the standard pose first, 3 mm marker noise and 5 % missing
markers; the ground truth goes to sample_joints.npz beside it.

    python scripts/make_sample.py ../shared/data/cmu-bvh/006_01.bvh
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from samba_common.body import prepend_standard_pose
from samba_common.bvh import load_bvh, put_on_floor, resample
from samba_common.formats import save_joints, save_markers
from samba_server.recon.evaluate import observe, vary_body

DATA = Path(__file__).resolve().parents[1] / "samba_common" / "data"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bvh", help="source BVH clip")
    ap.add_argument("--seconds", type=float, default=6.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=2026)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    take = load_bvh(args.bvh)
    joints, _t = resample(put_on_floor(take.joints), take.t, args.fps)
    joints, _lengths = vary_body(joints[: int(args.seconds * args.fps)], rng)
    joints = prepend_standard_pose(joints, args.fps)
    t = np.arange(len(joints)) / args.fps
    save_markers(DATA / "sample_markers.npz", observe(joints, rng), t)
    save_joints(DATA / "sample_joints.npz", joints, t)
    print(f"wrote {len(t)} frames to {DATA}")


if __name__ == "__main__":
    main()
