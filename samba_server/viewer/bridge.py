"""Feed the viewer from the server's own message types (one call per pose / packet).

``pose_to_viewer(viewer, pose)`` takes a :class:`samba_common.pose_wire.PoseMessage`,
``packet_to_viewer(viewer, packet)`` a :class:`samba_common.wire.MarkerPacket`; both are cheap
(the viewer coalesces to its max rate), so the server may call them for every message.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .server import Viewer


@dataclass(frozen=True)
class PoorPose:
    """When the page shows a pose as poor (amber skeleton, a warning sign with the reasons)."""

    min_markers: int = 6  #: fewer named markers than this (of 8): the unmarked joints are guessed
    max_residual_m: float = 0.02  #: solver residual (rms marker misfit) above this
    min_label_margin_m: float = 0.03  #: labelling's smallest cost gap to a runner-up below this


def pose_quality(pose, poor: PoorPose = PoorPose()) -> dict:
    """The quality dict the page shows for a PoseMessage: residual_m, n_markers, n_views,
    latency_ms, solved, label_mode (lost/tracking/identified), label_margin_m, flags (names),
    ``poor``: the list of reasons the pose is poor (empty = good), e.g. ["markers 5/8"], and
    ``unsure``: the names of the joints whose bound is 20 cm or more (drawn, but a guess)."""
    from samba_common.pose_wire import FLAG_MARKERS, FLAG_NAMES
    from samba_common.skeleton import JOINT_NAMES
    from samba_server.recon.bounds import CONFIDENT_M

    res, margin = float(pose.residual_m), float(pose.label_margin_m)
    reasons = []
    if not pose.solved:
        reasons.append("unsolved")
    if int(pose.n_markers) < poor.min_markers:
        reasons.append(f"markers {int(pose.n_markers)}/8")
    if np.isfinite(res) and res > poor.max_residual_m:
        reasons.append(f"residual {1000 * res:.0f} mm")
    if pose.label_mode == "lost":
        reasons.append("labels lost")
    elif np.isfinite(margin) and margin < poor.min_label_margin_m:
        reasons.append(f"ambiguous labels (margin {1000 * margin:.0f} mm)")
    unsure = []
    if pose.solved and pose.joint_bound is not None:
        unsure = [JOINT_NAMES[i] for i in np.flatnonzero(~(np.asarray(pose.joint_bound) < CONFIDENT_M))]
    return {"residual_m": res, "n_markers": int(pose.n_markers), "n_views": int(pose.n_views),
            "latency_ms": float(pose.latency_ms), "solved": bool(pose.solved), "label_mode": str(pose.label_mode),
            "label_margin_m": margin,
            "flags": [n for b, n in FLAG_NAMES.items() if pose.flags & b and b != FLAG_MARKERS],
            "poor": reasons, "unsure": unsure}


def pose_to_viewer(viewer: Viewer, pose) -> None:
    """Publish a PoseMessage: joints, markers and its quality (:func:`pose_quality`); t in
    seconds on the server's clock (the page shows it relative to the first pose)."""
    viewer.publish_pose(pose.t_ns / 1e9, np.asarray(pose.joints), pose.markers, pose_quality(pose))


def packet_to_viewer(viewer: Viewer, packet) -> None:
    """Publish the measured blobs of a MarkerPacket (predicted/lost records are left out)."""
    from samba_common.wire import FLAG_LOST, FLAG_PREDICTED

    keep = (np.asarray(packet.flags) & (FLAG_PREDICTED | FLAG_LOST)) == 0
    viewer.publish_blobs(packet.mote_id, np.asarray(packet.uv)[keep], np.asarray(packet.labels)[keep],
                         (int(packet.width), int(packet.height)))
