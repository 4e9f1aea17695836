"""BVH export: a 17-joint hierarchy over the 13 Samba joints, rotations derived from positions.

Axes and units (what Blender's BVH importer expects with its defaults, Forward -Z, Up Y):
the file is Y up, centimetres, and the subject's forward (+Y in the Samba world) is BVH -Z:

    bvh = 100 * (x, z, -y)          samba = (x_bvh, -z_bvh, y_bvh) / 100

Blender maps BVH (x, y, z) back to (x, -z, y), so an import at Scale 0.01 lands exactly on the
Samba world coordinates (Z up, metres, subject facing +Y).

Hierarchy (CMU / Mixamo-style names, so retargeting tools and ``samba_common.bvh`` recognise
it); every BVH joint sits on the Samba joint named in brackets:

    Hips [hip midpoint] -- LeftUpLeg [left_hip] -- LeftLeg [left_knee] -- LeftFoot [left_ankle]
                        -- RightUpLeg [right_hip] -- RightLeg -- RightFoot
                        -- Spine [hip midpoint] -- Chest [shoulder midpoint]
                              -- Neck [shoulder midpoint] -- Head [head]
                              -- LeftArm [left_shoulder] -- LeftForeArm [left_elbow] -- LeftHand [left_wrist]
                              -- RightArm [right_shoulder] -- RightForeArm -- RightHand

Rest pose: T-pose facing -Z, bone lengths = per-bone median over the take's complete frames.
Each segment's global rotation maps its rest bone direction exactly onto the observed one
(a swing), so forward kinematics reproduces every joint whose bones keep their length; the
twist about the bone comes from a neighbour: the hip axis and torso for the pelvis/chest, the
knee/elbow hinge (blended with the parent's axis when the limb is straight) for the limbs.
Frames with a missing joint hold the last complete pose (logged and counted).

Reading back: :func:`fk_positions` maps a Samba-exported BVH (parsed with
:func:`samba_common.bvh.read_bvh`) back to the 13 Samba joints in the Samba world frame; the
writer uses it to check that the file means what it says.
"""

from __future__ import annotations

import logging
import os
import sys
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from samba_common.bvh import BvhDocument, BvhError, forward_kinematics, read_bvh
from samba_common.skeleton import J, JOINT_NAMES

from .take import ExportTake, fill_invalid

log = logging.getLogger(__name__)

#: metres -> centimetres and Samba (Z up, facing +Y) -> BVH (Y up, facing -Z)
TO_BVH = 100.0 * np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

X, Y, Z = np.eye(3)

#: BVH joint name -> Samba joint it sits on (helpers sit on midpoints and have no entry)
BVH_TO_SAMBA: dict[str, str] = {
    "LeftUpLeg": "left_hip", "LeftLeg": "left_knee", "LeftFoot": "left_ankle",
    "RightUpLeg": "right_hip", "RightLeg": "right_knee", "RightFoot": "right_ankle",
    "Head": "head",
    "LeftArm": "left_shoulder", "LeftForeArm": "left_elbow", "LeftHand": "left_wrist",
    "RightArm": "right_shoulder", "RightForeArm": "right_elbow", "RightHand": "right_wrist",
}

#: (name, parent) in file order; parents come first
HIERARCHY: tuple[tuple[str, str | None], ...] = (
    ("Hips", None),
    ("LeftUpLeg", "Hips"), ("LeftLeg", "LeftUpLeg"), ("LeftFoot", "LeftLeg"),
    ("RightUpLeg", "Hips"), ("RightLeg", "RightUpLeg"), ("RightFoot", "RightLeg"),
    ("Spine", "Hips"), ("Chest", "Spine"), ("Neck", "Chest"), ("Head", "Neck"),
    ("LeftArm", "Chest"), ("LeftForeArm", "LeftArm"), ("LeftHand", "LeftForeArm"),
    ("RightArm", "Chest"), ("RightForeArm", "RightArm"), ("RightHand", "RightForeArm"),
)

#: End Site offsets (cm, rest frame): feet forward, hands along the arm, top of the head
END_SITES = {"LeftFoot": (0.0, 0.0, -12.0), "RightFoot": (0.0, 0.0, -12.0),
             "LeftHand": (-8.0, 0.0, 0.0), "RightHand": (8.0, 0.0, 0.0), "Head": (0.0, 12.0, 0.0)}

ROT_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")  # matrix Rz @ Rx @ Ry
EULER = "ZXY"  # scipy intrinsic sequence matching ROT_CHANNELS
HINGE_BLEND = 0.25  # weight of the parent's axis in a limb's twist reference (straight limbs)


@dataclass
class BvhExportReport:
    """What the export did: frames held over NaN, reproduction error of the written file
    against the input on complete frames (metres; > 0 only where bone lengths vary)."""

    n_frames: int
    n_held: int
    fps: float
    bone_lengths_cm: dict[str, float] = field(default_factory=dict)
    max_error_m: float = 0.0
    median_error_m: float = 0.0


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def _frames(d: np.ndarray, s: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Orthonormal frames (F, 3, 3), columns [d, s_perp, d x s_perp].

    d: (F, 3) primary direction (kept exactly); s: (F, 3) secondary hint; fallback: (F, 3) used
    where s is (nearly) parallel to d."""
    d = _unit(d)
    sp = s - np.sum(s * d, axis=-1, keepdims=True) * d
    bad = np.linalg.norm(sp, axis=-1) < 1e-6 * np.maximum(np.linalg.norm(s, axis=-1), 1e-12)
    if bad.any():
        fb = fallback[bad] - np.sum(fallback[bad] * d[bad], axis=-1, keepdims=True) * d[bad]
        still = np.linalg.norm(fb, axis=-1) < 1e-9
        if still.any():  # any perpendicular will do
            alt = np.where(np.abs(d[bad][still, 0:1]) < 0.9, X, Y)
            fb[still] = np.cross(d[bad][still], alt)
        sp[bad] = fb
    sp = _unit(sp)
    return np.stack([d, sp, np.cross(d, sp)], axis=-1)


def _rest_frame(d0: np.ndarray, s0: np.ndarray) -> np.ndarray:
    return _frames(d0[None], s0[None], s0[None])[0]


def _segment(d: np.ndarray, s: np.ndarray, fallback: np.ndarray, d0: np.ndarray, s0: np.ndarray) -> np.ndarray:
    """Global rotation (F, 3, 3) taking rest direction d0 onto d, rest s0 toward s."""
    return _frames(d, s, fallback) @ _rest_frame(d0, s0).T


def _median_len(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(b - a, axis=-1)))


def solve_bvh(joints: np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray, dict[str, float]]:
    """Offsets, root positions and local rotations for complete frames.

    joints: (F, 13, 3) Samba world metres, no NaN. Returns (offsets name -> (3,) cm rest offset,
    motion (F, 6 + 3 * 16) channel values in file order, bone lengths name -> cm).
    """
    P = joints @ TO_BVH.T  # (F, 13, 3) BVH cm
    p = {n: P[:, J[n]] for n in JOINT_NAMES}
    hipmid = 0.5 * (p["left_hip"] + p["right_hip"])
    shmid = 0.5 * (p["left_shoulder"] + p["right_shoulder"])
    L = {
        "hip_half": _median_len(p["left_hip"], p["right_hip"]) / 2,
        "sh_half": _median_len(p["left_shoulder"], p["right_shoulder"]) / 2,
        "torso": _median_len(hipmid, shmid), "neck": _median_len(shmid, p["head"]),
    }
    for side in ("left", "right"):
        L[f"{side}_thigh"] = _median_len(p[f"{side}_hip"], p[f"{side}_knee"])
        L[f"{side}_shin"] = _median_len(p[f"{side}_knee"], p[f"{side}_ankle"])
        L[f"{side}_upper_arm"] = _median_len(p[f"{side}_shoulder"], p[f"{side}_elbow"])
        L[f"{side}_forearm"] = _median_len(p[f"{side}_elbow"], p[f"{side}_wrist"])
    off = {
        "Hips": np.zeros(3),
        "LeftUpLeg": -L["hip_half"] * X, "LeftLeg": -L["left_thigh"] * Y, "LeftFoot": -L["left_shin"] * Y,
        "RightUpLeg": L["hip_half"] * X, "RightLeg": -L["right_thigh"] * Y, "RightFoot": -L["right_shin"] * Y,
        "Spine": np.zeros(3), "Chest": L["torso"] * Y, "Neck": np.zeros(3), "Head": L["neck"] * Y,
        "LeftArm": -L["sh_half"] * X, "LeftForeArm": -L["left_upper_arm"] * X, "LeftHand": -L["left_forearm"] * X,
        "RightArm": L["sh_half"] * X, "RightForeArm": L["right_upper_arm"] * X, "RightHand": L["right_forearm"] * X,
    }
    F = P.shape[0]
    ones = np.ones((F, 1))
    hip_axis = p["right_hip"] - p["left_hip"]
    sh_axis = p["right_shoulder"] - p["left_shoulder"]
    torso = shmid - hipmid
    G: dict[str, np.ndarray] = {}
    G["Hips"] = _segment(hip_axis, torso, ones * Y, X, Y)
    G["Spine"] = _segment(torso, sh_axis, G["Hips"] @ X, Y, X)
    G["Chest"] = _segment(sh_axis, torso, G["Spine"] @ Y, X, Y)
    G["Neck"] = _segment(p["head"] - shmid, sh_axis, G["Chest"] @ X, Y, X)
    G["Head"] = G["Neck"]
    for side, S in (("left", "Left"), ("right", "Right")):
        thigh = p[f"{side}_knee"] - p[f"{side}_hip"]
        shin = p[f"{side}_ankle"] - p[f"{side}_knee"]
        hint = G["Hips"] @ X
        hinge = np.cross(_unit(shin), _unit(thigh)) + HINGE_BLEND * hint
        G[f"{S}UpLeg"] = _segment(thigh, hinge, hint, -Y, X)
        G[f"{S}Leg"] = _segment(shin, hinge, hint, -Y, X)
        G[f"{S}Foot"] = G[f"{S}Leg"]
        sign = -1.0 if side == "left" else 1.0
        upper = p[f"{side}_elbow"] - p[f"{side}_shoulder"]
        fore = p[f"{side}_wrist"] - p[f"{side}_elbow"]
        s0 = sign * Y
        hint = G["Chest"] @ s0
        hinge = np.cross(_unit(upper), _unit(fore)) + HINGE_BLEND * hint
        G[f"{S}Arm"] = _segment(upper, hinge, hint, sign * X, s0)
        G[f"{S}ForeArm"] = _segment(fore, hinge, hint, sign * X, s0)
        G[f"{S}Hand"] = G[f"{S}ForeArm"]
    cols = [hipmid]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # gimbal-lock warning: the matrix is still reproduced
        for name, parent in HIERARCHY:
            local = G[name] if parent is None else np.swapaxes(G[parent], -1, -2) @ G[name]
            cols.append(Rotation.from_matrix(local).as_euler(EULER, degrees=True))
    lengths = {k: (2 * v if k.endswith("_half") else v) for k, v in L.items()}
    lengths = {k.replace("_half", "_width"): v for k, v in lengths.items()}
    return off, np.concatenate(cols, axis=1), lengths


def _hierarchy_text(off: dict[str, np.ndarray]) -> str:
    children: dict[str, list[str]] = {}
    for name, parent in HIERARCHY:
        if parent is not None:
            children.setdefault(parent, []).append(name)
    lines = ["HIERARCHY"]

    def emit(name: str, depth: int) -> None:
        ind = "  " * depth
        kind = "ROOT" if depth == 0 else "JOINT"
        lines.append(f"{ind}{kind} {name}")
        lines.append(f"{ind}{{")
        o = off[name]
        lines.append(f"{ind}  OFFSET {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}")
        chans = (("Xposition", "Yposition", "Zposition") if depth == 0 else ()) + ROT_CHANNELS
        lines.append(f"{ind}  CHANNELS {len(chans)} {' '.join(chans)}")
        for c in children.get(name, []):
            emit(c, depth + 1)
        if name in END_SITES:
            e = END_SITES[name]
            lines.extend([f"{ind}  End Site", f"{ind}  {{", f"{ind}    OFFSET {e[0]:.6f} {e[1]:.6f} {e[2]:.6f}",
                      f"{ind}  }}"])
        lines.append(f"{ind}}}")

    emit("Hips", 0)
    return "\n".join(lines) + "\n"


def fk_positions(bvh: BvhDocument) -> np.ndarray:
    """The 13 Samba joints (F, 13, 3) in world metres (Z up) from a Samba-exported BVH."""
    samba_to_bvh = {v: k for k, v in BVH_TO_SAMBA.items()}
    g = forward_kinematics(bvh)
    try:
        cols = [bvh.index(samba_to_bvh[n]) for n in JOINT_NAMES]
    except KeyError as exc:
        raise BvhError(f"not a Samba BVH: no joint {exc}") from None
    return g[:, cols] @ np.linalg.inv(TO_BVH).T


def write_bvh(path: str | os.PathLike, take: ExportTake) -> BvhExportReport:
    """Write ``take`` as BVH (Y up, cm, see module doc). One BVH frame per take frame; Frame
    Time = median time step. Frames with NaN joints hold the last complete pose."""
    filled, held = fill_invalid(take.joints)
    fps = take.rate()
    if take.n_frames > 2:
        dt = np.diff(take.t)
        jitter = float(np.max(np.abs(dt - 1.0 / fps)) * fps)
        if jitter > 0.5:
            log.warning("%s: time steps vary by up to %.0f%% of a frame; BVH assumes a fixed rate "
                        "of %.3f fps", take.source, 100 * jitter, fps)
    if held.any():
        log.warning("%s: %d of %d frames have missing joints; holding the last complete pose",
                    take.source, int(held.sum()), take.n_frames)
    good = filled[~held] if (~held).any() else filled
    off, motion, lengths = solve_bvh(filled)
    # the rest offsets come from complete frames only (held frames would bias the medians)
    if held.any():
        off, _, lengths = solve_bvh(good)
    text = _hierarchy_text(off)
    body = "\n".join(" ".join(f"{v:.6f}" for v in row) for row in motion)
    tmp = f"{os.fspath(path)}.part"
    with open(tmp, "w", encoding="ascii") as fh:
        fh.write(text)
        fh.write(f"MOTION\nFrames: {motion.shape[0]}\nFrame Time: {1.0 / fps:.8f}\n")
        fh.write(body + "\n")
    os.replace(tmp, path)
    report = BvhExportReport(take.n_frames, int(held.sum()), fps, lengths)
    back = fk_positions(read_bvh(path))  # (F, 13, 3) metres Samba world
    valid = ~held
    if valid.any():
        err = np.linalg.norm(back[valid] - take.joints[valid], axis=-1)
        report.max_error_m = float(err.max())
        report.median_error_m = float(np.median(err))
    log.info("%s: %d frames at %.2f fps, %d held, FK error max %.2f mm median %.2f mm", path,
             report.n_frames, fps, report.n_held, 1e3 * report.max_error_m, 1e3 * report.median_error_m)
    if report.max_error_m > 0.01:
        log.warning("%s: bone lengths vary in this take; the fixed-length skeleton is off by up to "
                    "%.1f mm", path, 1e3 * report.max_error_m)
    print(f"wrote {os.fspath(path)}: {report.n_frames} frames at {fps:g} fps", file=sys.stderr)
    return report
