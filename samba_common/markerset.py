"""The marker model: each marker = its joint centre + an offset fixed in its segment's frame.

Real markers are taped to bony landmarks, not placed on the joint centres. Each of the 8
markers has an offset (3,) metres in the frame of the segment it is taped to; the columns of
every segment frame are (e1, e2, e3):

- shoulders (acromion): the **torso** frame; e1 lateral (outwards on that side), e2 up the
  spine, e3 forward;
- knees (lateral femoral epicondyle) and ankles (lateral malleolus): the **shank** frame; e2
  proximal (ankle -> knee), e1 lateral along the knee hinge axis, e3 anterior;
- wrists (back of the wrist): the **forearm** frame; e2 proximal (wrist -> elbow), e1 dorsal
  (from the elbow's hinge axis: up in a palms-down T-pose, outwards with the arm hanging),
  e3 = the radial side in the T-pose.

The hinge axis of a limb is ``upper x (lower + k * forward)`` (k = -:data:`HINGE_BLEND` for the
legs, +HINGE_BLEND for the arms, in torso coordinates), made orthogonal to the lower bone: the
true hinge when the limb is bent, the torso's sideways axis when it is straight, continuous in
between. The same definition is used by the solver (:mod:`samba_server.recon.kernels`), the
simulator and the subject calibration. Joint-centre markers are the special case of zero offsets.
"""

from __future__ import annotations

import numpy as np

from .body import D, decompose, fk_body
from .skeleton import MARKER_JOINT, N_MARKERS

#: how much of the torso's forward axis enters the hinge axis (a straight limb uses it alone)
HINGE_BLEND = 0.2
#: +1 for left markers, -1 for right markers (MARKER_NAMES order)
SIDE = np.array([1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0])
#: segment of each marker: 0 torso, 1 forearm, 2 shank
SEGMENT = np.array([0, 0, 1, 1, 2, 2, 2, 2])
#: (upper bone, lower bone) direction indices (samba_common.body.BONE_DIRS) per marker; -1 for the torso
LIMB_OF_MARKER = np.array([[-1, -1], [-1, -1],
                           [D["left_upper_arm"], D["left_forearm"]], [D["right_upper_arm"], D["right_forearm"]],
                           [D["left_thigh"], D["left_shin"]], [D["right_thigh"], D["right_shin"]],
                           [D["left_thigh"], D["left_shin"]], [D["right_thigh"], D["right_shin"]]])

#: typical landmark offsets (8, 3) metres in (e1, e2, e3) of each segment frame: acromion 4.5 cm
#: above the shoulder centre, lateral femoral epicondyle 5 cm lateral of the knee centre, lateral
#: malleolus 3.5 cm lateral and 1 cm below the ankle centre, back of the wrist 2.5 cm dorsal
TYPICAL_OFFSETS = np.array([
    [0.0, 0.045, 0.0], [0.0, 0.045, 0.0],
    [0.025, 0.0, 0.0], [0.025, 0.0, 0.0],
    [0.05, 0.0, 0.0], [0.05, 0.0, 0.0],
    [0.035, -0.01, 0.0], [0.035, -0.01, 0.0],
])
#: prior standard deviation (8, 3) metres of each offset component about TYPICAL_OFFSETS
OFFSET_SIGMA = np.array([
    [0.01, 0.01, 0.01], [0.01, 0.01, 0.01],
    [0.01, 0.01, 0.01], [0.01, 0.01, 0.01],
    [0.008, 0.008, 0.008], [0.008, 0.008, 0.008],
    [0.008, 0.008, 0.008], [0.008, 0.008, 0.008],
])

PLACEMENTS = ("skin", "joint_centres")


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def segment_frames_body(dirs: np.ndarray) -> np.ndarray:
    """Segment frames of the 8 markers in torso coordinates.

    dirs: (..., 11, 3) bone directions (samba_common.body). Returns (..., 8, 3, 3) whose columns
    are the frame axes e1, e2, e3 (module docstring).
    """
    dirs = np.asarray(dirs, dtype=float)
    shape = dirs.shape[:-2]
    out = np.zeros(shape + (N_MARKERS, 3, 3))
    fwd = np.array([0.0, 0.0, 1.0])
    for i in range(N_MARKERS):
        s = SIDE[i]
        if SEGMENT[i] == 0:
            e1 = np.broadcast_to(np.array([s, 0.0, 0.0]), shape + (3,))
            e2 = np.broadcast_to(np.array([0.0, 1.0, 0.0]), shape + (3,))
        else:
            u, low = dirs[..., LIMB_OF_MARKER[i, 0], :], dirs[..., LIMB_OF_MARKER[i, 1], :]
            k = HINGE_BLEND if SEGMENT[i] == 1 else -HINGE_BLEND
            h = np.cross(u, low + k * fwd)
            e2 = -low
            h = h - np.sum(h * e2, axis=-1, keepdims=True) * e2
            bad = np.linalg.norm(h, axis=-1) < 1e-9
            if np.any(bad):  # limb along the forward axis exactly: use the torso's sideways axis
                x = np.array([1.0, 0.0, 0.0])
                h = np.where(bad[..., None], x - np.sum(x * e2, axis=-1, keepdims=True) * e2, h)
            e1 = _unit(h) * (-s if SEGMENT[i] == 1 else s)
        e3 = s * np.cross(e1, e2)
        out[..., i, :, 0], out[..., i, :, 1], out[..., i, :, 2] = e1, e2, e3
    return out


def body_markers(dirs: np.ndarray, lengths: np.ndarray, offsets: np.ndarray | None) -> np.ndarray:
    """Markers in torso coordinates (..., 8, 3) of directions (..., 11, 3), lengths (8,) and
    offsets (8, 3) metres in segment frames (None = joint centres)."""
    body = fk_body(dirs, lengths)[..., list(MARKER_JOINT), :]
    if offsets is None:
        return body
    return body + np.einsum("...mij,mj->...mi", segment_frames_body(dirs), np.asarray(offsets, float))


def markers_from_joints(joints: np.ndarray, offsets: np.ndarray | None) -> np.ndarray:
    """World markers (F, 8, 3) of world joints (F, 13, 3) metres and offsets (8, 3) (None = the
    joint centres). Frames with NaN joints give NaN markers."""
    joints = np.asarray(joints, dtype=float)
    centres = joints[:, list(MARKER_JOINT)]
    if offsets is None or not np.any(offsets):
        return centres.copy()
    ok = np.all(np.isfinite(joints), axis=(1, 2))
    out = np.full(centres.shape, np.nan)
    if np.any(ok):
        _origin, R, dirs = decompose(joints[ok])
        w = np.einsum("fmij,mj->fmi", segment_frames_body(dirs), np.asarray(offsets, float))
        out[ok] = centres[ok] + np.einsum("fij,fmj->fmi", R, w)
    return out


def joint_markers_predictor(offsets: np.ndarray | None):
    """A function joints (13, 3) or (F, 13, 3) -> markers (8, 3) / (F, 8, 3) for ``offsets``
    (what the labelling predicts the markers from)."""
    def predict(joints: np.ndarray) -> np.ndarray:
        j = np.asarray(joints, dtype=float)
        single = j.ndim == 2
        m = markers_from_joints(j[None] if single else j, offsets)
        return m[0] if single else m
    return predict


def vary_offsets(rng: np.random.Generator, scale: float = 0.15, jitter: float = 0.003,
                 asymmetry: float = 0.002) -> np.ndarray:
    """One subject's landmark offsets (8, 3): TYPICAL_OFFSETS x U(1 - scale, 1 + scale) per
    landmark (both sides alike), plus N(0, jitter) per component and N(0, asymmetry) per side."""
    base = TYPICAL_OFFSETS.copy()
    for a in range(0, N_MARKERS, 2):
        f = rng.uniform(1 - scale, 1 + scale)
        jit = rng.normal(0.0, jitter, 3)
        for i in (a, a + 1):
            base[i] = base[i] * f + jit + rng.normal(0.0, asymmetry, 3)
    return base


def soft_tissue(markers: np.ndarray, rng: np.random.Generator, sigma: float = 0.005, seconds: float = 0.3,
                fps: float = 60.0) -> np.ndarray:
    """Markers (F, 8, 3) plus smooth soft-tissue wobble: per marker and axis, Gaussian noise
    low-passed over about ``seconds`` and scaled to standard deviation ``sigma`` metres."""
    F = len(markers)
    n = max(int(round(seconds * fps)), 1)
    kernel = np.hanning(2 * n + 1)
    kernel /= np.sqrt(np.sum(kernel ** 2))
    raw = rng.standard_normal((F + 2 * n, N_MARKERS, 3))
    smooth = np.apply_along_axis(lambda v: np.convolve(v, kernel, mode="valid"), 0, raw)[:F]
    return markers + sigma * smooth
