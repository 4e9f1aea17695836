"""Synthetic takes for the export tests: a walking-like motion built from fixed bone lengths,
so a faithful BVH must reproduce it exactly (independent of the exporter's own maths)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from samba_common.skeleton import J

BONES_M = dict(hip_width=0.26, shoulder_width=0.36, torso=0.52, neck=0.24, upper_arm=0.29,
               forearm=0.26, thigh=0.44, shin=0.42)


def synthetic_joints(n_frames: int = 120, fps: float = 60.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(F, 13, 3) world metres Z up, subject roughly facing +Y, walking and turning; (F,) s."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_frames) / fps
    ph = rng.uniform(0, 2 * np.pi, 12)
    w = 2 * np.pi * 1.1 * t

    def rot(seq, *angles):
        return Rotation.from_euler(seq, np.stack(angles, -1))

    B = BONES_M
    out = np.zeros((n_frames, 13, 3))
    hipmid = np.stack([0.2 * np.sin(0.5 * w), 0.8 * t, 0.95 + 0.02 * np.sin(2 * w)], -1)
    R_p = rot("zyx", 0.6 * np.sin(0.3 * w + ph[0]), 0.05 * np.sin(w), 0.04 * np.sin(w + ph[1]))
    out[:, J["left_hip"]] = hipmid + R_p.apply([-B["hip_width"] / 2, 0, 0])
    out[:, J["right_hip"]] = hipmid + R_p.apply([B["hip_width"] / 2, 0, 0])
    R_t = R_p * rot("xz", 0.15 + 0.1 * np.sin(w + ph[2]), 0.3 * np.sin(w + ph[3]))
    shmid = hipmid + R_t.apply([0, 0, B["torso"]])
    out[:, J["left_shoulder"]] = shmid + R_t.apply([-B["shoulder_width"] / 2, 0, 0])
    out[:, J["right_shoulder"]] = shmid + R_t.apply([B["shoulder_width"] / 2, 0, 0])
    out[:, J["head"]] = shmid + (R_t * rot("xy", 0.2 * np.sin(w + ph[4]), 0.1 * np.sin(w))).apply([0, 0, B["neck"]])
    for k, side in enumerate(("left", "right")):
        s = -1.0 if side == "left" else 1.0
        sw = np.sin(w + np.pi * k)
        R_th = R_p * rot("xy", 0.5 * sw, s * 0.1 * np.sin(w + ph[5 + k]))
        knee = out[:, J[f"{side}_hip"]] + R_th.apply([0, 0, -B["thigh"]])
        R_sh = R_th * rot("x", -0.6 * (1 + np.sin(w + np.pi * k + 1.0)))
        out[:, J[f"{side}_knee"]] = knee
        out[:, J[f"{side}_ankle"]] = knee + R_sh.apply([0, 0, -B["shin"]])
        # arm: hanging down and swinging, abducted a little
        R_ua = R_t * rot("yx", s * (0.3 + 0.2 * np.sin(w + ph[7 + k])), -0.5 * sw)
        elbow = out[:, J[f"{side}_shoulder"]] + R_ua.apply([0, 0, -B["upper_arm"]])
        R_fa = R_ua * rot("x", 0.3 + 0.6 * (1 + np.sin(w + ph[9 + k])))
        out[:, J[f"{side}_elbow"]] = elbow
        out[:, J[f"{side}_wrist"]] = elbow + R_fa.apply([0, 0, -B["forearm"]])
    return out, t


@pytest.fixture
def walk():
    """A 2 s synthetic walk at 60 fps: (joints (120, 13, 3), t (120,))."""
    return synthetic_joints()
