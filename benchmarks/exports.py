"""Export and viewer costs: seconds per format for a 6000-frame take (100 s at 60 fps), BVH
round-trip error on it and on real CMU clips, and the viewer's per-call publish cost.

    python benchmarks/exports.py            # prints the figures and updates docs/BENCHMARKS.md
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _record import record  # noqa: E402

from samba_common.skeleton import MARKER_JOINT  # noqa: E402
from samba_server.export import export_take  # noqa: E402
from samba_server.export.take import ExportTake  # noqa: E402
from samba_server.viewer import Viewer  # noqa: E402
from samba_server.viewer.server import _pose_json  # noqa: E402

CMU = Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu-bvh"


def _synthetic(n: int) -> tuple[np.ndarray, np.ndarray]:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "export"))
    from conftest import synthetic_joints  # the test suite's fixed-bone-length walk

    return synthetic_joints(n, 60.0)


def main() -> int:
    lines = ["| what | figure |", "|---|---|"]
    joints, t = _synthetic(6000)
    take = ExportTake(joints, t, joints[:, list(MARKER_JOINT)], "synthetic")
    with tempfile.TemporaryDirectory() as tmp:
        for fmt in ("bvh", "c3d", "trc", "csv"):
            t0 = time.perf_counter()
            rep = export_take(take, fmt, Path(tmp) / f"take.{fmt}")
            dt = time.perf_counter() - t0
            size = (Path(tmp) / f"take.{fmt}").stat().st_size / 1e6
            lines.append(f"| {fmt.upper()} export, 6000 frames | {dt:.2f} s, {size:.1f} MB |")
            if fmt == "bvh":
                lines.append(f"| BVH FK round trip, fixed bone lengths | max {rep.max_error_m * 1e3:.5f} mm |")
        clips = sorted(CMU.glob("*.bvh"))[:6] if CMU.exists() else []
        if clips:
            from samba_common.bvh import load_bvh

            errs = []
            for c in clips:
                b = load_bvh(c)
                rep = export_take(ExportTake(b.joints, b.t, None, str(c)), "bvh", Path(tmp) / "cmu.bvh")
                errs.append(rep.max_error_m * 1e3)
            lines.append(f"| BVH FK round trip, {len(clips)} CMU clips (bending spine) | max error per clip "
                         f"{', '.join(f'{e:.1f}' for e in errs)} mm |")
    v = Viewer("127.0.0.1", 0).start()
    m = joints[0, list(MARKER_JOINT)]
    t0 = time.perf_counter()
    for i in range(5000):
        v.publish_pose(i, joints[i], m, {"residual_m": 0.003})
    lines.append(f"| Viewer.publish_pose (caller side) | {(time.perf_counter() - t0) / 5000 * 1e6:.1f} us |")
    v.stop()
    t0 = time.perf_counter()
    for i in range(2000):
        _pose_json(i, (0.1, joints[i], m, {"residual_m": 0.003}))
    lines.append(f"| pose JSON encoding (viewer thread, <= 60/s) | {(time.perf_counter() - t0) / 2000 * 1e6:.0f} us |")
    print("\n".join(lines))
    record("Exports and viewer", lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
