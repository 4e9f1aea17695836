"""Feed the viewer from the server's own message types (one call per pose / packet).

``pose_to_viewer(viewer, pose)`` takes a :class:`samba_common.pose_wire.PoseMessage`,
``packet_to_viewer(viewer, packet)`` a :class:`samba_common.wire.MarkerPacket`; both are cheap
(the viewer coalesces to its max rate), so the server may call them for every message.
"""

from __future__ import annotations

import numpy as np

from .server import Viewer


def pose_to_viewer(viewer: Viewer, pose) -> None:
    """Publish a PoseMessage: joints, markers and its quality fields (t in seconds, Unix epoch)."""
    quality = {"residual_m": float(pose.residual_m), "n_markers": int(pose.n_markers),
               "n_views": int(pose.n_views), "latency_ms": float(pose.latency_ms), "solved": bool(pose.solved)}
    viewer.publish_pose(pose.t_ns / 1e9, np.asarray(pose.joints), pose.markers, quality)


def packet_to_viewer(viewer: Viewer, packet) -> None:
    """Publish the measured blobs of a MarkerPacket (predicted/lost records are left out)."""
    from samba_common.wire import FLAG_LOST, FLAG_PREDICTED

    keep = (np.asarray(packet.flags) & (FLAG_PREDICTED | FLAG_LOST)) == 0
    viewer.publish_blobs(packet.mote_id, np.asarray(packet.uv)[keep], np.asarray(packet.labels)[keep],
                         (int(packet.width), int(packet.height)))
