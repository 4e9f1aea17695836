"""Mote per-frame cost: detection + tracking (MotePipeline.process) on simulated frames.

Renders a simulated take (built-in motion, T-pose lead-in, 8 markers + distractors, noise 3)
for one camera at 160x120, 320x240 and 640x480 (intrinsics and pixel thresholds scaled), runs
the pipeline on one core (``cv2.setNumThreads(1)``) and reports microseconds per frame
(median, p95) for detection alone and for detection + tracking. Target: <= 300 us per
160x120 frame. Writes the section "Mote (benchmarks/mote.py)" of docs/BENCHMARKS.md.

    python benchmarks/mote.py [--seconds 10] [--no-record]
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _record import record  # noqa: E402

from samba_common.calib import Camera, CameraRig, default_rig  # noqa: E402
from samba_mote.detect import DetectConfig, Detector  # noqa: E402
from samba_mote.pipeline import MoteConfig, MotePipeline  # noqa: E402
from samba_mote.sim import SimConfig, make_take  # noqa: E402
from samba_mote.track import TrackConfig  # noqa: E402


def scaled_rig(scale: int) -> CameraRig:
    cams = []
    for c in default_rig(2).cameras:
        K = c.matrix.copy()
        K[:2] *= scale
        K[0, 2] = (K[0, 2] + 0.5) - 0.5 * 1  # keep the principal point at the image centre
        K[0, 2], K[1, 2] = (c.size[0] * scale - 1) / 2, (c.size[1] * scale - 1) / 2
        cams.append(dataclasses.replace(c, size=(c.size[0] * scale, c.size[1] * scale), matrix=K))
    return CameraRig(cams)


def scaled_config(scale: int) -> MoteConfig:
    d, t = DetectConfig(), TrackConfig()
    return MoteConfig(
        detect=dataclasses.replace(d, min_area=d.min_area * scale, max_area=d.max_area * scale * scale,
                                   pad=d.pad * scale, static_radius=d.static_radius * scale),
        track=dataclasses.replace(t, gate_px=t.gate_px * scale, gate_growth=t.gate_growth * scale,
                                  gate_max=t.gate_max * scale, merge_margin=t.merge_margin * scale,
                                  split_min_px=t.split_min_px * scale, split_margin=t.split_margin * scale),
    )


def measure(scale: int, seconds: float) -> dict[str, float]:
    rig = scaled_rig(scale)
    take = make_take("unused", None, rig=rig, config=SimConfig(blur=0.45 * scale), seconds=seconds, write=False)
    cam = take.cameras[0]
    cfg = scaled_config(scale)
    det = Detector(cfg.detect)
    t_det = []
    for f in cam.frames:
        t0 = time.perf_counter()
        det.detect(f)
        t_det.append(time.perf_counter() - t0)
    pipe = MotePipeline(cfg, cam.name, calibration=rig)
    t_all = []
    labelled = 0
    for t, f in zip(take.t, cam.frames):
        t0 = time.perf_counter()
        p = pipe.process(int(t * 1e9), f)
        t_all.append(time.perf_counter() - t0)
        labelled += int(((p.labels < 8) & (p.flags & 1 > 0)).sum())
    d, a = np.asarray(t_det[10:]) * 1e6, np.asarray(t_all[10:]) * 1e6
    return {"frames": len(cam.frames), "det_med": float(np.median(d)), "det_p95": float(np.percentile(d, 95)),
            "all_med": float(np.median(a)), "all_p95": float(np.percentile(a, 95)),
            "labelled": labelled / len(cam.frames), "init": pipe.tracker.initialised}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0, help="length of the simulated take")
    ap.add_argument("--no-record", action="store_true", help="do not write docs/BENCHMARKS.md")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    rows = ["| frame | frames | detection median / p95 (us) | detection + tracking median / p95 (us) "
            "| labelled markers per frame |", "|---|---|---|---|---|"]
    for scale in (1, 2, 4):
        r = measure(scale, args.seconds)
        size = f"{160 * scale}x{120 * scale}"
        print(f"{size}: detection {r['det_med']:.0f} / {r['det_p95']:.0f} us, detection+tracking "
              f"{r['all_med']:.0f} / {r['all_p95']:.0f} us (median / p95), {r['labelled']:.1f} labelled per frame")
        rows.append(f"| {size} | {r['frames']} | {r['det_med']:.0f} / {r['det_p95']:.0f} | "
                    f"{r['all_med']:.0f} / {r['all_p95']:.0f} | {r['labelled']:.1f} |")
    rows += ["", "One core (`cv2.setNumThreads(1)`), simulated take with the built-in motion, 8 markers, 3 static "
             "distractors, noise sigma 3. Target <= 300 us per 160x120 frame (detection + tracking)."]
    if not args.no_record:
        record("Mote (benchmarks/mote.py)", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
