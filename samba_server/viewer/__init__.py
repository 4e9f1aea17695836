"""Live browser viewer (HTTP + WebSocket) for ``samba-server --http`` and ``samba-demo``."""

from .bridge import packet_to_viewer, pose_to_viewer
from .server import Viewer, ViewerError, ViewerStats

__all__ = ["Viewer", "ViewerError", "ViewerStats", "packet_to_viewer", "pose_to_viewer"]
