"""The standard pose (T-pose, FORMATS.md) built from a take's own bone lengths, and the
smooth lead-in from it to the first frame of the take.

A T-pose stands upright, arms straight out sideways, facing world +Y, so the subject's right
hand points to +X. Joints are world metres, Z up, JOINT_NAMES order.
"""

from __future__ import annotations

import numpy as np

from samba_common.body import ANKLE_HEIGHT, bone_lengths
from samba_common.bvh import floor_ankle_height
from samba_common.skeleton import BONE_TYPES, J, N_JOINTS

_L = {name: i for i, name in enumerate(BONE_TYPES)}

#: named stances of the standard pose: how far (m) each ankle stands outside its hip.
#: "together" depends on the hip width (the ankles ~6 cm either side of the midline).
STANCES = ("hip", "apart", "together")
_FEET_TOGETHER_HALF = 0.06  #: m, ankle to midline with the feet touching
_STANCE_APART = 0.12


def stance_offset(stance: float | str, hip_width: float) -> float:
    """The ankle-outside-hip offset (m) of ``stance``: a number (m, negative = legs converging)
    or one of :data:`STANCES` -- ``hip`` 0.0 (ankles straight below the hips), ``apart`` 0.12,
    ``together`` -(hip_width / 2 - 0.06) (feet touching, ankles ~6 cm from the midline)."""
    if isinstance(stance, str):
        key = stance.strip().lower()
        if key == "hip":
            return 0.0
        if key == "apart":
            return _STANCE_APART
        if key == "together":
            return -(hip_width / 2 - _FEET_TOGETHER_HALF)
        try:
            return float(key)
        except ValueError:
            raise ValueError(f"stance must be {'|'.join(STANCES)} or metres, not {stance!r}") from None
    return float(stance)


def tpose(lengths: np.ndarray, hip_xy: np.ndarray = (0.0, 0.0), ankle_z: float = ANKLE_HEIGHT,
          stance: float | str = 0.12) -> np.ndarray:
    """T-pose joints (13, 3): lengths (8,) in BONE_TYPES order (metres), hip midpoint at
    ``hip_xy`` (2,), ankles at height ``ankle_z``; facing +Y, right hand toward +X.

    The straight legs lean so that each ankle is ``stance`` m further out than its hip
    (:func:`stance_offset`: a number or hip / apart / together). 0 = legs straight down,
    ankles at hip width; negative = legs converging (down to the feet touching at the
    midline, ``-hip_width / 2``; closer would cross the legs: ValueError)."""
    ln = {k: float(lengths[i]) for k, i in _L.items()}
    stance = stance_offset(stance, ln["hip_width"])
    x0, y0 = float(hip_xy[0]), float(hip_xy[1])
    leg = ln["shin"] + ln["thigh"]
    if stance < -ln["hip_width"] / 2 - 1e-9:
        raise ValueError(f"stance {stance:+.3f} m crosses the legs (hip width {ln['hip_width']:.3f} m)")
    if abs(stance) >= 0.9 * leg:
        raise ValueError(f"stance {stance:+.3f} m is too wide for legs of {leg:.2f} m")
    drop = float(np.sqrt(leg ** 2 - stance ** 2))
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


#: the blend's kinematic tree, parent before child: (parent, child); -1 = the hip midpoint,
#: -2 = the shoulder midpoint. The hips and the shoulders hang from their midpoints.
_TREE: tuple[tuple[int, int], ...] = (
    (-1, J["left_hip"]), (-1, J["right_hip"]), (-1, -2),
    (-2, J["left_shoulder"]), (-2, J["right_shoulder"]), (-2, J["head"]),
    (J["left_shoulder"], J["left_elbow"]), (J["left_elbow"], J["left_wrist"]),
    (J["right_shoulder"], J["right_elbow"]), (J["right_elbow"], J["right_wrist"]),
    (J["left_hip"], J["left_knee"]), (J["left_knee"], J["left_ankle"]),
    (J["right_hip"], J["right_knee"]), (J["right_knee"], J["right_ankle"]),
)


def _slerp(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Unit vector (3,) a fraction w of the way along the great circle from unit a to unit b (3,);
    opposite vectors turn about a horizontal axis across a (the path is then not unique)."""
    theta = float(np.arccos(np.clip(a @ b, -1.0, 1.0)))
    if theta < 1e-9:
        return a.copy()
    if np.pi - theta < 1e-6:
        axis = np.cross(a, (0.0, 0.0, 1.0) if abs(a[2]) < 0.9 else (1.0, 0.0, 0.0))
        across = np.cross(axis / np.linalg.norm(axis), a)
        return np.cos(w * np.pi) * a + np.sin(w * np.pi) * across
    return (np.sin((1.0 - w) * theta) * a + np.sin(w * theta) * b) / np.sin(theta)


def _rigid_blend(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """Joints (13, 3) a fraction w (0..1) of the way from pose a to pose b (13, 3, metres): the
    hip midpoint moves on the straight line, every bone of :data:`_TREE` turns along the great
    circle between its two directions and changes length linearly, so a body stays a body
    (blending the positions instead shortened an arm going from straight out to hanging by 25 %)."""
    def point(j: np.ndarray, k: int) -> np.ndarray:
        if k == -1:
            return 0.5 * (j[J["left_hip"]] + j[J["right_hip"]])
        if k == -2:
            return 0.5 * (j[J["left_shoulder"]] + j[J["right_shoulder"]])
        return j[k]

    out = np.zeros_like(a)
    placed = {-1: (1 - w) * point(a, -1) + w * point(b, -1)}
    for parent, child in _TREE:
        va, vb = point(a, child) - point(a, parent), point(b, child) - point(b, parent)
        la, lb = float(np.linalg.norm(va)), float(np.linalg.norm(vb))
        if la < 1e-12 or lb < 1e-12:
            v = (1 - w) * va + w * vb
        else:
            v = ((1 - w) * la + w * lb) * _slerp(va / la, vb / lb, w)
        placed[child] = placed[parent] + v
        if child >= 0:
            out[child] = placed[child]
    return out


#: m: a take starting higher than this above its floor gets its T-pose on the floor
FLOOR_SLACK_M = 0.05


def prepend_tpose(joints: np.ndarray, t: np.ndarray, fps: float, hold: float = 1.0,
                  transition: float = 0.6, stance: float | str = 0.12, *,
                  pose_at: tuple[float, float] | np.ndarray | None = None, walk_speed: float = 1.0,
                  max_speed: float = 2.5) -> tuple[np.ndarray, np.ndarray, int]:
    """Prepend ``hold`` s of T-pose and a blend into the take.

    joints: (F, 13, 3) metres at times t (F,) (uniform at ``fps``). The T-pose uses the
    first frame's bone lengths and ankle height, and ``stance`` (:func:`stance_offset`). A take
    whose first frame is more than ``FLOOR_SLACK_M`` off the ground (a climb starting on a
    structure, a jump) has its T-pose on the take's floor
    (:func:`~samba_common.bvh.floor_ankle_height`): people stand on the floor for the standard
    pose, and one 1.7 m up in the air had the upper body out of every camera's view. It stands
    at ``pose_at`` (x, y) m, or where the take starts if None.

    The blend moves the hips along the straight line from the pose to the first frame's
    position, turns the body about the vertical axis (shortest way) and turns every bone from
    its T-pose direction to its first-frame direction (:func:`_rigid_blend`: bones keep their
    lengths), all with one smoothstep weight, so nothing jumps.
    It lasts max(``transition``, distance / ``walk_speed``, long enough that no joint moves
    faster than ``max_speed`` m/s). Returns (joints (P+F, 13, 3), t (P+F,) from 0, P).
    """
    first = joints[0]
    lengths = bone_lengths(first[None])[0]
    hip = 0.5 * (first[J["left_hip"]] + first[J["right_hip"]])
    ankle_z = float(min(first[J["left_ankle"], 2], first[J["right_ankle"], 2]))
    floor = floor_ankle_height(joints)
    if ankle_z > floor + FLOOR_SLACK_M:
        ankle_z = floor
    place = hip[:2] if pose_at is None else np.asarray(pose_at, float).reshape(2)
    tp = tpose(lengths, place, ankle_z, stance)
    n_hold = int(round(hold * fps))
    yaw = heading(first)
    yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
    tp_hip = 0.5 * (tp[J["left_hip"]] + tp[J["right_hip"]])
    local_tp = tp - tp_hip
    local_first = (first - hip) @ _rot_z(-yaw).T  # first frame turned to face +Y

    def at(w: float) -> np.ndarray:
        local = _rigid_blend(local_tp, local_first, w)
        centre = (1 - w) * tp_hip + w * hip
        return local @ _rot_z(w * yaw).T + centre

    # duration: walking pace along the path, and no joint faster than max_speed (the
    # smoothstep's peak rate is 1.5 / duration)
    ws = np.linspace(0.0, 1.0, 201)
    path = np.stack([at(w) for w in ws])
    dp_dw = float(np.linalg.norm(np.diff(path, axis=0), axis=2).max()) * (len(ws) - 1)
    dist = float(np.linalg.norm(hip[:2] - tp_hip[:2]))
    duration = max(transition, dist / walk_speed if walk_speed > 0 else 0.0,
                   1.5 * dp_dw / max_speed if max_speed > 0 else 0.0)
    n_tr = int(round(duration * fps))
    blend = []
    for k in range(1, n_tr + 1):
        w = k / (n_tr + 1)
        blend.append(at(w * w * (3 - 2 * w)))  # smoothstep
    pre = [np.repeat(tp[None], n_hold, axis=0)]
    if blend:
        pre.append(np.asarray(blend))
    pre_arr = np.concatenate(pre, axis=0)
    out = np.concatenate([pre_arr, joints], axis=0)
    t_out = np.arange(len(out)) / fps
    return out, t_out, len(pre_arr)
