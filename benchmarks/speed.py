"""Per-frame solve time of the reconstruction, pinned to one core.

Times ``Reconstructor.solve`` (alignment, KD-tree search, pseudo-poses, local PCA prior, linear
start, Levenberg-Marquardt) frame by frame on held-out takes (a database without the take's
subject), for Samba's default (K neighbours and N pseudo-poses each from
configs/reconstruct.toml), for K=10, N=10 (the thesis' choice: 23.5 ms, 49 iterations) and for K=100, N=0
(thesis: 88.6 ms, 78 iterations), and the default on the same takes with skin markers solved
through the marker model (known offsets), side by side in one run. Prints median and p95 ms/frame and
mean LM iterations, and records them in docs/BENCHMARKS.md.

    python benchmarks/speed.py [--data ../shared/data/cmu-bvh] [--seconds 20]
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core: no BLAS threads
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _record import record  # noqa: E402

from samba_common.body import prepend_standard_pose  # noqa: E402
from samba_common.bvh import load_bvh, resample  # noqa: E402
from samba_server.recon.db import load_default_db  # noqa: E402
from samba_server.recon.evaluate import observe, vary_body  # noqa: E402
from samba_server.recon.proportions import estimate_lengths  # noqa: E402
from samba_server.recon.reconstruct import ReconstructConfig, Reconstructor  # noqa: E402
from samba_common.markerset import markers_from_joints, vary_offsets  # noqa: E402
from samba_common.skeleton import MARKER_JOINT  # noqa: E402

CLIPS = ("002_05", "005_02", "006_10")  # punch, dance, basketball
DEFAULT = f"K={ReconstructConfig().k}, N={ReconstructConfig().pseudo} (default)"
SKIN = "default, skin markers + offsets"


def time_take(rec: Reconstructor, markers: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Seconds and LM iterations per frame."""
    secs, iters = np.empty(len(t)), np.empty(len(t))
    for i in range(len(t)):
        t0 = time.perf_counter()
        r = rec.solve(markers[i], t[i])
        secs[i] = time.perf_counter() - t0
        iters[i] = r.iterations
    return secs, iters


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", default=str(Path(__file__).resolve().parents[1].parent / "shared/data/cmu-bvh"))
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--fps", type=float, default=30.0)
    ap.add_argument("--rounds", type=int, default=3, help="repeat the timing (the VM's speed drifts)")
    ap.add_argument("--no-record", action="store_true")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    rng = np.random.default_rng(3)
    full = load_default_db()
    configs = {DEFAULT: ReconstructConfig(), "K=10, N=10": replace(ReconstructConfig(), k=10, pseudo=10),
               "K=100, N=0": replace(ReconstructConfig(), k=100, pseudo=0)}
    results: dict[str, list] = {name: [[], [], []] for name in (*configs, SKIN)}  # per-round medians, all ms, iterations
    takes = []
    for clip in CLIPS:
        take = load_bvh(Path(args.data) / f"{clip}.bvh")
        joints, _t = resample(take.joints, take.t, args.fps)
        truth, _lengths = vary_body(joints[: int(args.seconds * args.fps)], rng)
        truth = prepend_standard_pose(truth, args.fps)
        t = np.arange(len(truth)) / args.fps
        markers = observe(truth, rng)
        db = full.without(lambda n, s=clip.split("_")[0]: n.startswith(s + "_"))
        lengths = estimate_lengths(markers, db.mean_lengths)
        recs = {name: Reconstructor(db, cfg, lengths) for name, cfg in configs.items()}
        # skin markers (landmark offsets, samba_common.markerset) solved through the marker model; own
        # random stream so the joint-centre takes keep their draws
        srng = np.random.default_rng([3, len(takes)])
        offsets = vary_offsets(srng)
        skin = markers_from_joints(truth, offsets) + (markers - truth[:, list(MARKER_JOINT)])
        recs[SKIN] = (Reconstructor(db, configs[DEFAULT], estimate_lengths(skin, db.mean_lengths, offsets), offsets), skin)
        takes.append((markers, t, recs))
    for _round in range(args.rounds):
        for name in (*configs, SKIN):  # configurations side by side in every round
            secs, iters = [], []
            for markers, t, recs in takes:
                rec = recs[name]
                if name == SKIN:
                    rec, markers = rec
                time_take(rec, markers[:5], t[:5])  # compile / warm up
                rec.reset()
                s_, i_ = time_take(rec, markers, t)
                secs.append(s_)
                iters.append(i_)
            ms = 1e3 * np.concatenate(secs)
            results[name][0].append(np.median(ms))
            results[name][1].append(ms)
            results[name][2].append(np.concatenate(iters))
    rows = ["| configuration | frames | median ms/frame | p95 ms/frame | round medians (ms) | mean LM iterations |",
            "|---|---|---|---|---|---|"]
    for name, (medians, all_ms, iters) in results.items():
        ms, it = np.concatenate(all_ms), np.concatenate(iters)
        rows.append(f"| {name} | {len(ms) // args.rounds} | {np.median(ms):.3f} | {np.percentile(ms, 95):.3f} | "
                    f"{', '.join(f'{m:.3f}' for m in medians)} | {it.mean():.1f} |")
    print("\n".join(rows))
    if not args.no_record:
        record("Reconstruction speed (benchmarks/speed.py)",
               [f"Reconstructor.solve per frame, one core, {args.rounds} rounds, held-out takes {', '.join(CLIPS)} ({args.seconds:g} s each "
                f"at {args.fps:g} fps, plus 1 s standard pose), 3 mm noise, 5 % missing markers. Target: <= 0.3 ms/frame "
                "median; thesis: 23.5 ms and 49 iterations (K=10, N=10) vs 88.6 ms and 78 iterations (K=100, N=0).",
                "", *rows])
    return 0


if __name__ == "__main__":
    sys.exit(main())
