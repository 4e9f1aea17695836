"""A procedural motion (no data files needed): stepping in place while swinging the arms,
turning slowly, with the hands crossing in front of the body now and then."""

from __future__ import annotations

import numpy as np

from samba_common.skeleton import J, N_JOINTS

from .tpose import tpose

#: default bone lengths (m), BONE_TYPES order
DEFAULT_LENGTHS = np.array([0.36, 0.20, 0.50, 0.25, 0.28, 0.26, 0.45, 0.44])


def synthetic_motion(seconds: float = 3.0, fps: float = 60.0, turn_deg: float = 40.0) -> tuple[np.ndarray, np.ndarray]:
    """(joints (F, 13, 3) m, t (F,) s): a subject at the origin facing +Y (turning by up to
    ``turn_deg``), arms swinging from the T-pose down to the sides and across the chest,
    knees lifting alternately."""
    t = np.arange(int(round(seconds * fps))) / fps
    base = tpose(DEFAULT_LENGTHS)
    out = np.repeat(base[None], len(t), axis=0)
    ua, fa, th, sh = DEFAULT_LENGTHS[4], DEFAULT_LENGTHS[5], DEFAULT_LENGTHS[6], DEFAULT_LENGTHS[7]
    for k, tk in enumerate(t):
        ph = 2 * np.pi * 0.5 * tk
        for side, s in (("left", -1.0), ("right", 1.0)):
            sh_p = base[J[f"{side}_shoulder"]]
            # arm elevation: 0 = horizontal (T-pose), -70 deg = down; swing forward/back
            elev = np.radians(-35 + 35 * np.cos(ph))
            fwd = np.radians(50) * (0.5 - 0.5 * np.cos(ph)) * (1 if s > 0 else 1)
            d_up = np.array([s * np.cos(elev) * np.cos(fwd), np.cos(elev) * np.sin(fwd) * 1.0, np.sin(elev)])
            elbow = sh_p + ua * d_up
            bend = np.radians(60) * (0.5 - 0.5 * np.cos(ph))
            d_fa = np.array([s * np.cos(elev + 0) * np.cos(fwd + bend) * 0.9 - s * 0.25 * np.sin(bend),
                             np.cos(elev) * np.sin(fwd + bend), np.sin(elev)])
            d_fa /= np.linalg.norm(d_fa)
            out[k, J[f"{side}_elbow"]] = elbow
            out[k, J[f"{side}_wrist"]] = elbow + fa * d_fa
            # legs: knee lift alternating
            lift = max(0.0, np.sin(ph + (0 if s > 0 else np.pi))) * np.radians(45)
            hip = base[J[f"{side}_hip"]]
            spread = 0.08 / (th + sh)  # feet apart as in the T-pose
            knee = hip + th * np.array([s * spread, np.sin(lift), -np.cos(lift)])
            out[k, J[f"{side}_knee"]] = knee
            out[k, J[f"{side}_ankle"]] = knee + sh * np.array([s * spread, 0.0, -1.0])
        # a slow turn about the vertical axis through the hips
        yaw = np.radians(turn_deg) * np.sin(2 * np.pi * 0.15 * tk)
        c, s_ = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1.0]])
        out[k] = out[k] @ R.T
    assert out.shape == (len(t), N_JOINTS, 3)
    return out, t
