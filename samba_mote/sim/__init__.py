"""Camera simulator: renders marker frames for a rig from joint motion (BVH or joints.npz).

Main entry points: :func:`render_take` (frames per camera in memory) and :func:`make_take`
(a complete take directory: ``cam*.avi``, ``calibration.toml``, ``joints.npz``,
``markers.npz``, ``truth2d.npz``).
"""

from .motion import synthetic_motion
from .render import RenderedCamera, SimConfig, render_frame, render_take
from .take import SimTake, load_motion, make_take, prepare_motion
from .tpose import prepend_tpose, tpose

__all__ = ["RenderedCamera", "SimConfig", "SimTake", "load_motion", "make_take", "prepare_motion",
           "prepend_tpose", "render_frame", "render_take", "synthetic_motion", "tpose"]
