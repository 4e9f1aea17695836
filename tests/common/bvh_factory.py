"""Writes small synthetic BVH files with classic CMU joint names for tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

# (name, parent, offset in cm, Y up)
CMU_JOINTS = [
    ("Hips", None, (0, 95, 0)),
    ("LHipJoint", "Hips", (0, 0, 0)),
    ("LeftUpLeg", "LHipJoint", (9, -3, 0)),
    ("LeftLeg", "LeftUpLeg", (0, -44, 0)),
    ("LeftFoot", "LeftLeg", (0, -42, 0)),
    ("RHipJoint", "Hips", (0, 0, 0)),
    ("RightUpLeg", "RHipJoint", (-9, -3, 0)),
    ("RightLeg", "RightUpLeg", (0, -44, 0)),
    ("RightFoot", "RightLeg", (0, -42, 0)),
    ("LowerBack", "Hips", (0, 5, 0)),
    ("Spine", "LowerBack", (0, 20, 0)),
    ("Neck", "Spine", (0, 22, 0)),
    ("Head", "Neck", (0, 10, 0)),
    ("LeftShoulder", "Spine", (3, 20, 0)),
    ("LeftArm", "LeftShoulder", (14, 0, 0)),
    ("LeftForeArm", "LeftArm", (28, 0, 0)),
    ("LeftHand", "LeftForeArm", (25, 0, 0)),
    ("RightShoulder", "Spine", (-3, 20, 0)),
    ("RightArm", "RightShoulder", (-14, 0, 0)),
    ("RightForeArm", "RightArm", (-28, 0, 0)),
    ("RightHand", "RightForeArm", (-25, 0, 0)),
]


def write_cmu_bvh(path: Path, n_frames: int = 40, seed: int = 0, fps: float = 60.0) -> Path:
    """A walking-ish synthetic motion: legs and arms swing, the root moves forward."""
    rng = np.random.default_rng(seed)
    children: dict[str | None, list[str]] = {}
    for name, parent, _o in CMU_JOINTS:
        children.setdefault(parent, []).append(name)
    offsets = {n: o for n, _p, o in CMU_JOINTS}
    lines = ["HIERARCHY"]

    def emit(name: str, depth: int) -> None:
        pad = "  " * depth
        kind = "ROOT" if depth == 0 else "JOINT"
        lines.append(f"{pad}{kind} {name}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET {' '.join(f'{v:.4f}' for v in offsets[name])}")
        if depth == 0:
            lines.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{pad}  CHANNELS 3 Zrotation Xrotation Yrotation")
        for c in children.get(name, []):
            emit(c, depth + 1)
        if name not in children:
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            lines.append(f"{pad}    OFFSET 0 -5 0")
            lines.append(f"{pad}  }}")
        lines.append(f"{pad}}}")

    emit("Hips", 0)
    order = [n for n, _p, _o in CMU_JOINTS]
    lines += ["MOTION", f"Frames: {n_frames}", f"Frame Time: {1.0 / fps:.6f}"]
    phase0 = rng.uniform(0, 2 * np.pi)
    for f in range(n_frames):
        ph = phase0 + 2 * np.pi * f / 30.0
        vals = [0.0, 0.0, 2.0 * f, 0.0, 0.0, 0.0]  # root moves along +Z (forward)
        for name in order[1:]:
            rx = 0.0
            if name in ("LeftUpLeg", "RightArm"):
                rx = 25 * np.sin(ph)
            elif name in ("RightUpLeg", "LeftArm"):
                rx = -25 * np.sin(ph)
            elif name in ("LeftLeg", "RightLeg"):
                rx = 20 + 20 * np.sin(ph + (0 if name.startswith("Left") else np.pi))
            rz = 0.0
            if name == "LeftArm":
                rz = -70.0
            elif name == "RightArm":
                rz = 70.0
            elif name in ("LeftForeArm", "RightForeArm"):
                rx = -20 - 15 * np.sin(ph)
            vals += [rz, rx, 0.0]
        lines.append(" ".join(f"{v:.5f}" for v in vals))
    path.write_text("\n".join(lines) + "\n")
    return path
