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

from samba_common.calib import CameraRig, default_rig  # noqa: E402
from samba_mote.detect import DetectConfig, Detector  # noqa: E402
from samba_mote.pipeline import MoteConfig, MotePipeline  # noqa: E402
from samba_mote.sim import SimConfig, make_take  # noqa: E402
from samba_mote.track import TrackConfig  # noqa: E402


def reference_detect(img: np.ndarray, thresh: int = 128, background: int = 30) -> np.ndarray:
    """The TECH.md section 3 snippet (42 us/frame when TECH.md was written): the yardstick
    for how fast this machine is right now."""
    _, mask = cv2.threshold(img, thresh, 255, cv2.THRESH_BINARY)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    rows = []
    h, w = img.shape
    for c in contours:
        x, y, bw, bh = cv2.boundingRect(c)
        x0, y0 = max(x - 1, 0), max(y - 1, 0)
        roi = cv2.subtract(img[y0:min(y + bh + 1, h), x0:min(x + bw + 1, w)], background)
        m = cv2.moments(roi)
        if m["m00"] > 0:
            rows.append((x0 + m["m10"] / m["m00"], y0 + m["m01"] / m["m00"], bw * bh))
    return np.asarray(rows, dtype=np.float32).reshape(-1, 3)


def timed(fn, items, repeats: int) -> np.ndarray:
    """us per call, the best of ``repeats`` passes for each item (the machine is shared)."""
    best = np.full(len(items), np.inf)
    for _ in range(repeats):
        for i, it in enumerate(items):
            t0 = time.perf_counter()
            fn(it)
            best[i] = min(best[i], time.perf_counter() - t0)
    return best * 1e6


def scaled_rig(scale: int) -> CameraRig:
    cams = []
    for c in default_rig(2).cameras:
        K = c.matrix.copy()
        K[:2] *= scale
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


def measure(scale: int, seconds: float, repeats: int) -> dict[str, float]:
    rig = scaled_rig(scale)
    take = make_take("unused", None, rig=rig, config=SimConfig(blur=0.45 * scale, tpose_stance="apart", pose_at=None), seconds=seconds, write=False)
    cam = take.cameras[0]
    frames = list(cam.frames)
    cfg = scaled_config(scale)
    ref = timed(reference_detect, frames, repeats)
    # detection: a fresh detector per pass, so the static mask learns the same way each time
    det_best = np.full(len(frames), np.inf)
    for _ in range(repeats):
        det = Detector(cfg.detect)
        det_best = np.minimum(det_best, timed(det.detect, frames, 1))
    all_best = np.full(len(frames), np.inf)
    labelled, start = 0.0, 0
    for _ in range(repeats):
        pipe = MotePipeline(cfg, cam.name, calibration=rig)
        ts = iter(take.t)
        packets = []

        def step(frame, pipe=pipe, ts=ts, packets=packets):
            packets.append(pipe.process(int(next(ts) * 1e9), frame))

        all_best = np.minimum(all_best, timed(step, frames, 1))
        labelled = float(np.mean([((p.labels < 8) & ((p.flags & 1) > 0)).sum() for p in packets]))
        start = next((i for i, p in enumerate(packets) if (p.labels < 8).any()), 0) + 1
    steady = all_best[start:]  # after the T-pose has been labelled (labelling itself is slower)
    return {"frames": len(frames), "ref_med": float(np.median(ref)), "det_med": float(np.median(det_best)),
            "det_p95": float(np.percentile(det_best, 95)), "all_med": float(np.median(steady)),
            "all_p95": float(np.percentile(steady, 95)), "init_max": float(all_best[:start].max()),
            "labelled": labelled}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0, help="length of the simulated take")
    ap.add_argument("--repeats", type=int, default=3, help="passes per frame (best is kept)")
    ap.add_argument("--no-record", action="store_true", help="do not write docs/BENCHMARKS.md")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    rows = ["| frame | frames | TECH.md reference detector median (us) | detection median / p95 (us) "
            "| detection + tracking median / p95 (us) | labelling frames max (us) | labelled markers per frame |",
            "|---|---|---|---|---|---|---|"]
    for scale in (1, 2, 4):
        r = measure(scale, args.seconds, args.repeats)
        size = f"{160 * scale}x{120 * scale}"
        print(f"{size}: reference {r['ref_med']:.0f} us; detection {r['det_med']:.0f} / {r['det_p95']:.0f} us; "
              f"detection+tracking {r['all_med']:.0f} / {r['all_p95']:.0f} us (median / p95); "
              f"T-pose labelling frames up to {r['init_max']:.0f} us; {r['labelled']:.2f} labelled per frame")
        rows.append(f"| {size} | {r['frames']} | {r['ref_med']:.0f} | {r['det_med']:.0f} / {r['det_p95']:.0f} | "
                    f"{r['all_med']:.0f} / {r['all_p95']:.0f} | {r['init_max']:.0f} | {r['labelled']:.2f} |")
    rows += ["", "One core (`cv2.setNumThreads(1)`), best of several passes per frame (the machine is shared; "
             "the TECH.md reference detector took 42 us/frame when TECH.md was measured, so divide by "
             "reference/42 to compare with that machine state). Simulated take: built-in motion, 8 markers, "
             "3 static distractors, noise sigma 3. Target <= 300 us per 160x120 frame (detection + tracking, "
             "steady state after the T-pose labelling)."]
    if not args.no_record:
        record("Mote (benchmarks/mote.py)", rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
