"""The Samba skeleton: joint and marker names and order (FORMATS.md), bones and bone types.

All arrays indexed by joint follow ``JOINT_NAMES``; all arrays indexed by marker follow
``MARKER_NAMES``. Positions are world metres, Z up (FORMATS.md).
"""

from __future__ import annotations

JOINT_NAMES: tuple[str, ...] = (
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
    "left_hip",
    "right_hip",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
)
N_JOINTS = len(JOINT_NAMES)
J = {name: i for i, name in enumerate(JOINT_NAMES)}

MARKER_NAMES: tuple[str, ...] = (
    "left_shoulder",
    "right_shoulder",
    "left_wrist",
    "right_wrist",
    "left_knee",
    "right_knee",
    "left_ankle",
    "right_ankle",
)
N_MARKERS = len(MARKER_NAMES)
M = {name: i for i, name in enumerate(MARKER_NAMES)}

#: index into JOINT_NAMES of the joint each marker sits on, shape (8,)
MARKER_JOINT: tuple[int, ...] = tuple(J[name] for name in MARKER_NAMES)

#: joints that carry no marker (head, elbows, hips)
UNOBSERVED_JOINTS: tuple[int, ...] = tuple(i for i in range(N_JOINTS) if i not in MARKER_JOINT)

#: bones for drawing and export, as (parent joint, child joint) index pairs
BONES: tuple[tuple[int, int], ...] = (
    (J["left_shoulder"], J["right_shoulder"]),
    (J["left_shoulder"], J["left_elbow"]),
    (J["left_elbow"], J["left_wrist"]),
    (J["right_shoulder"], J["right_elbow"]),
    (J["right_elbow"], J["right_wrist"]),
    (J["left_hip"], J["right_hip"]),
    (J["left_hip"], J["left_knee"]),
    (J["left_knee"], J["left_ankle"]),
    (J["right_hip"], J["right_knee"]),
    (J["right_knee"], J["right_ankle"]),
)

#: bone types whose length is one number per subject (both sides alike).
#: "torso" runs from the shoulder midpoint to the hip midpoint, "neck" from the shoulder
#: midpoint to the head; the widths are the distances between the two joints.
BONE_TYPES: tuple[str, ...] = (
    "shoulder_width",
    "hip_width",
    "torso",
    "neck",
    "upper_arm",
    "forearm",
    "thigh",
    "shin",
)
