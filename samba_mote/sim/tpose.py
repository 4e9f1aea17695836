"""The standard pose (T-pose, FORMATS.md) built from a take's own bone lengths, and the
smooth lead-in from it to the first frame of the take.

A T-pose stands upright, arms straight out sideways, facing world +Y, so the subject's right
hand points to +X. Joints are world metres, Z up, JOINT_NAMES order.
"""

from __future__ import annotations

import numpy as np

from samba_common.body import bone_lengths
from samba_common.skeleton import BONE_TYPES, J, N_JOINTS

_L = {name: i for i, name in enumerate(BONE_TYPES)}


def tpose(lengths: np.ndarray, hip_xy: np.ndarray = (0.0, 0.0), ankle_z: float = 0.08,
          stance: float = 0.12) -> np.ndarray:
    """T-pose joints (13, 3): lengths (8,) in BONE_TYPES order (metres), hip midpoint at
    ``hip_xy`` (2,), ankles at height ``ankle_z``; facing +Y, right hand toward +X.

    The straight legs spread so that each ankle is ``stance`` m further out than its hip
    (feet about shoulder-width apart, so knee and ankle markers stay apart in the images)."""
    ln = {k: float(lengths[i]) for k, i in _L.items()}
    x0, y0 = float(hip_xy[0]), float(hip_xy[1])
    leg = ln["shin"] + ln["thigh"]
    drop = float(np.sqrt(max(leg ** 2 - stance ** 2, 1e-6)))
    hip_z = ankle_z + drop
    sh_z = hip_z + ln["torso"]
    out = np.zeros((N_JOINTS, 3))
    for side, s in (("left", -1.0), ("right", 1.0)):  # the subject's right is +X
        hx = x0 + s * ln["hip_width"] / 2
        out[J[f"{side}_hip"]] = (hx, y0, hip_z)
        f = ln["thigh"] / leg
        out[J[f"{side}_knee"]] = (hx + s * stance * f, y0, hip_z - drop * f)
        out[J[f"{side}_ankle"]] = (hx + s * stance, y0, ankle_z)
        sx = x0 + s * ln["shoulder_width"] / 2
        out[J[f"{side}_shoulder"]] = (sx, y0, sh_z)
        out[J[f"{side}_elbow"]] = (sx + s * ln["upper_arm"], y0, sh_z)
        out[J[f"{side}_wrist"]] = (sx + s * (ln["upper_arm"] + ln["forearm"]), y0, sh_z)
    out[J["head"]] = (x0, y0, sh_z + ln["neck"])
    return out


def heading(joints: np.ndarray) -> float:
    """Yaw (rad) of the facing direction of (13, 3) joints; 0 = facing +Y."""
    x = joints[J["left_shoulder"]] - joints[J["right_shoulder"]]  # points to the subject's left
    # facing = z_up x left... for a T-pose facing +Y, left = -X, so facing = (left rotated -90 deg)
    fx, fy = x[1], -x[0]
    return float(np.arctan2(-fx, fy))


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def prepend_tpose(joints: np.ndarray, t: np.ndarray, fps: float, hold: float = 1.0,
                  transition: float = 0.6, stance: float = 0.12) -> tuple[np.ndarray, np.ndarray, int]:
    """Prepend ``hold`` s of T-pose and a ``transition`` s blend into the take.

    joints: (F, 13, 3) metres at times t (F,) (uniform at ``fps``). The T-pose uses the
    first frame's bone lengths, hip position and ankle height. The blend turns the body
    about the vertical axis (shortest way) while moving the joints from the T-pose to the
    first frame, so no marker jumps. Returns (joints (P+F, 13, 3), t (P+F,) from 0, P).
    """
    first = joints[0]
    lengths = bone_lengths(first[None])[0]
    hip = 0.5 * (first[J["left_hip"]] + first[J["right_hip"]])
    ankle_z = float(min(first[J["left_ankle"], 2], first[J["right_ankle"], 2]))
    tp = tpose(lengths, hip[:2], ankle_z, stance)
    n_hold = int(round(hold * fps))
    n_tr = int(round(transition * fps))
    yaw = heading(first)
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    tp_hip = 0.5 * (tp[J["left_hip"]] + tp[J["right_hip"]])
    local_tp = tp - tp_hip
    local_first = (first - hip) @ _rot_z(-yaw).T  # first frame turned to face +Y
    blend = []
    for k in range(1, n_tr + 1):
        w = k / (n_tr + 1)
        w = w * w * (3 - 2 * w)  # smoothstep
        local = (1 - w) * local_tp + w * local_first
        centre = (1 - w) * tp_hip + w * hip
        blend.append(local @ _rot_z(w * yaw).T + centre)
    pre = [np.repeat(tp[None], n_hold, axis=0)]
    if blend:
        pre.append(np.asarray(blend))
    pre_arr = np.concatenate(pre, axis=0)
    out = np.concatenate([pre_arr, joints], axis=0)
    t_out = np.arange(len(out)) / fps
    return out, t_out, len(pre_arr)
