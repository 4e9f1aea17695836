"""The kinematic body model: 13 joints from a torso frame, bone directions and bone lengths.

This is the joint-angle representation used by the motion database, the pseudo-poses and the
solver. A pose is

- a **torso frame**: origin at the shoulder midpoint (world metres) and a rotation ``R`` (3, 3)
  whose columns are the torso axes in world coordinates: x from the right to the left
  shoulder, y up the spine (from the hip midpoint to the shoulder midpoint, made orthogonal to
  x), z = x × y (forward);
- 11 unit **bone directions** in that torso frame, in ``BONE_DIRS`` order;
- 8 **bone lengths** per subject, in ``BONE_TYPES`` order (both sides alike).

Because x and y are fixed by the shoulders and the spine, the spine direction has no z
component and the shoulder directions are ±x: they are not free parameters.
"""

from __future__ import annotations

import numpy as np

from .skeleton import BONE_TYPES, J, N_JOINTS

BONE_DIRS: tuple[str, ...] = (
    "neck",          # shoulder midpoint -> head
    "pelvis",        # right hip -> left hip
    "spine",         # shoulder midpoint -> hip midpoint
    "left_upper_arm", "right_upper_arm",
    "left_forearm", "right_forearm",
    "left_thigh", "right_thigh",
    "left_shin", "right_shin",
)
D = {name: i for i, name in enumerate(BONE_DIRS)}
L = {name: i for i, name in enumerate(BONE_TYPES)}

#: limb chains (side, upper bone, lower bone, root joint, middle joint, end joint, upper length, lower length)
LIMBS = (
    ("left", "left_upper_arm", "left_forearm", "left_shoulder", "left_elbow", "left_wrist", "upper_arm", "forearm"),
    ("right", "right_upper_arm", "right_forearm", "right_shoulder", "right_elbow", "right_wrist", "upper_arm", "forearm"),
    ("left", "left_thigh", "left_shin", "left_hip", "left_knee", "left_ankle", "thigh", "shin"),
    ("right", "right_thigh", "right_shin", "right_hip", "right_knee", "right_ankle", "thigh", "shin"),
)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def torso_frames(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Torso frames of (F, 13, 3) joints -> origin (F, 3) metres, R (F, 3, 3) (columns = axes)."""
    ls, rs = joints[:, J["left_shoulder"]], joints[:, J["right_shoulder"]]
    origin = 0.5 * (ls + rs)
    hipmid = 0.5 * (joints[:, J["left_hip"]] + joints[:, J["right_hip"]])
    x = _unit(ls - rs)
    up = origin - hipmid
    y = _unit(up - np.sum(up * x, axis=-1, keepdims=True) * x)
    z = np.cross(x, y)
    return origin, np.stack([x, y, z], axis=-1)


def bone_lengths(joints: np.ndarray) -> np.ndarray:
    """Per-frame bone lengths (F, 8) in metres, BONE_TYPES order, both sides averaged."""
    j = joints
    sm = 0.5 * (j[:, J["left_shoulder"]] + j[:, J["right_shoulder"]])
    hm = 0.5 * (j[:, J["left_hip"]] + j[:, J["right_hip"]])

    def dist(a, b):
        return np.linalg.norm(a - b, axis=-1)

    def pair(a, b):
        return 0.5 * (dist(j[:, J[f"left_{a}"]], j[:, J[f"left_{b}"]]) + dist(j[:, J[f"right_{a}"]], j[:, J[f"right_{b}"]]))

    return np.stack([
        dist(j[:, J["left_shoulder"]], j[:, J["right_shoulder"]]),
        dist(j[:, J["left_hip"]], j[:, J["right_hip"]]),
        dist(sm, hm),
        dist(sm, j[:, J["head"]]),
        pair("shoulder", "elbow"),
        pair("elbow", "wrist"),
        pair("hip", "knee"),
        pair("knee", "ankle"),
    ], axis=-1)


def decompose(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, 13, 3) joints -> origin (F, 3), R (F, 3, 3), dirs (F, 11, 3) unit vectors in the torso frame."""
    origin, R = torso_frames(joints)
    j = joints
    sm = origin
    hm = 0.5 * (j[:, J["left_hip"]] + j[:, J["right_hip"]])
    world = np.empty((len(j), len(BONE_DIRS), 3))
    world[:, D["neck"]] = j[:, J["head"]] - sm
    world[:, D["pelvis"]] = j[:, J["left_hip"]] - j[:, J["right_hip"]]
    world[:, D["spine"]] = hm - sm
    for _side, upper, lower, a, b, c, _lu, _ll in LIMBS:
        world[:, D[upper]] = j[:, J[b]] - j[:, J[a]]
        world[:, D[lower]] = j[:, J[c]] - j[:, J[b]]
    dirs = _unit(np.einsum("fbi,fij->fbj", world, R))
    return origin, R, dirs


def fk_body(dirs: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Joints in the torso frame: dirs (..., 11, 3), lengths (8,) or (..., 8) -> (..., 13, 3)."""
    lengths = np.asarray(lengths, dtype=float)
    shape = dirs.shape[:-2]
    lens = np.broadcast_to(lengths, shape + (len(BONE_TYPES),))
    out = np.zeros(shape + (N_JOINTS, 3))
    half_sw = 0.5 * lens[..., L["shoulder_width"]]
    out[..., J["left_shoulder"], 0] = half_sw
    out[..., J["right_shoulder"], 0] = -half_sw
    out[..., J["head"], :] = lens[..., L["neck"], None] * dirs[..., D["neck"], :]
    hm = lens[..., L["torso"], None] * dirs[..., D["spine"], :]
    half_pelvis = 0.5 * lens[..., L["hip_width"], None] * dirs[..., D["pelvis"], :]
    out[..., J["left_hip"], :] = hm + half_pelvis
    out[..., J["right_hip"], :] = hm - half_pelvis
    for _side, upper, lower, a, b, c, lu, ll in LIMBS:
        out[..., J[b], :] = out[..., J[a], :] + lens[..., L[lu], None] * dirs[..., D[upper], :]
        out[..., J[c], :] = out[..., J[b], :] + lens[..., L[ll], None] * dirs[..., D[lower], :]
    return out


def fk(origin: np.ndarray, R: np.ndarray, dirs: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """World joints (..., 13, 3) from origin (..., 3), R (..., 3, 3), dirs (..., 11, 3), lengths (8,)."""
    body = fk_body(dirs, lengths)
    return origin[..., None, :] + np.einsum("...ij,...pj->...pi", R, body)


def standard_dirs() -> np.ndarray:
    """Bone directions (11, 3) of the standard pose (T-pose) in the torso frame."""
    d = np.zeros((len(BONE_DIRS), 3))
    d[D["neck"]] = (0.0, 1.0, 0.0)
    d[D["pelvis"]] = (1.0, 0.0, 0.0)
    d[D["spine"]] = (0.0, -1.0, 0.0)
    for name in ("left_upper_arm", "left_forearm"):
        d[D[name]] = (1.0, 0.0, 0.0)
    for name in ("right_upper_arm", "right_forearm"):
        d[D[name]] = (-1.0, 0.0, 0.0)
    for name in ("left_thigh", "right_thigh", "left_shin", "right_shin"):
        d[D[name]] = (0.0, -1.0, 0.0)
    return d


#: torso axes of a subject facing world +Y, Z up (FORMATS.md): left = -X, up = +Z, forward = +Y
STANDARD_R = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]).T


#: m: the ankle joint's height above the floor, standing
ANKLE_HEIGHT = 0.08


def shoulder_height(lengths: np.ndarray, ankle_height: float = ANKLE_HEIGHT) -> float:
    """Height (m above the floor) of the shoulders standing straight, for bone lengths (8,)."""
    lengths = np.asarray(lengths, dtype=float)
    return float(ankle_height + lengths[L["shin"]] + lengths[L["thigh"]] + lengths[L["torso"]])


def standard_pose(lengths: np.ndarray, xy: tuple[float, float] = (0.0, 0.0),
                  ankle_height: float = ANKLE_HEIGHT) -> np.ndarray:
    """Joints (13, 3) of the standard pose (FORMATS.md) for bone lengths (8,), standing at ``xy``."""
    lengths = np.asarray(lengths, dtype=float)
    h = shoulder_height(lengths, ankle_height)
    return fk(np.array([xy[0], xy[1], h]), STANDARD_R, standard_dirs(), lengths)


def prepend_standard_pose(joints: np.ndarray, fps: float, seconds: float = 1.0, blend: float = 0.5,
                          lengths: np.ndarray | None = None) -> np.ndarray:
    """Put ``seconds`` of the standard pose, then a ``blend``-second transition, before a take.

    joints: (F, 13, 3) metres; lengths: bone lengths (8,) of the pose (default: the take's
    median). The take is re-posed with those lengths (directions and shoulder trajectory kept),
    so the whole result has one body. Returns (F + n_standard + n_blend, 13, 3).
    """
    lens = np.median(bone_lengths(joints), axis=0) if lengths is None else np.asarray(lengths, float)
    origin, R, dirs = decompose(joints)
    take = fk(origin, R, dirs, lens)
    floor = float(np.nanmin(take[..., 2]))
    stand = standard_pose(lens, (origin[0, 0], origin[0, 1]), ankle_height=floor if floor > 0 else ANKLE_HEIGHT)
    n_std, n_blend = int(round(seconds * fps)), int(round(blend * fps))
    s_origin, _s_R, s_dirs = decompose(stand[None])
    out = [np.repeat(stand[None], n_std, axis=0)]
    if n_blend:
        w = (np.arange(1, n_blend + 1) / (n_blend + 1))[:, None]
        w = 0.5 - 0.5 * np.cos(np.pi * w)  # smooth start and stop
        o = (1 - w) * s_origin + w * origin[:1]
        d = (1 - w[:, :, None]) * s_dirs + w[:, :, None] * dirs[:1]
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        rots = _slerp_rot(STANDARD_R, R[0], w[:, 0])
        out.append(fk(o, rots, d, lens))
    out.append(take)
    return np.concatenate(out, axis=0)


def _slerp_rot(Ra: np.ndarray, Rb: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotations (len(w), 3, 3) interpolated from Ra to Rb at fractions w (n,)."""
    Rrel = Ra.T @ Rb
    angle = np.arccos(np.clip((np.trace(Rrel) - 1) / 2, -1.0, 1.0))
    if angle < 1e-9:
        return np.repeat(Ra[None], len(w), axis=0)
    axis = np.array([Rrel[2, 1] - Rrel[1, 2], Rrel[0, 2] - Rrel[2, 0], Rrel[1, 0] - Rrel[0, 1]])
    n = np.linalg.norm(axis)
    if n < 1e-9:  # 180 degrees: axis from the symmetric part
        vals, vecs = np.linalg.eigh(Rrel + Rrel.T)
        axis = vecs[:, np.argmax(vals)]
    else:
        axis = axis / n
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    out = []
    for a in w * angle:
        out.append(Ra @ (np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)))
    return np.array(out)
